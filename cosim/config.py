"""Frozen parameter dataclasses from plain mappings (TOML tables), with errors
naming the full key, the value and what was expected.

Types are taken from each field's default value: a float field takes a
float or an int, a tuple field a list of the same length and element type, a
str field a string, a nested dataclass field a table. Unknown keys are
refused with the list of known ones.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

from .errors import ScenarioError

__all__ = ["dataclass_from_mapping", "check_number"]


def check_number(where: str, value: Any, *, positive: bool = False, nonnegative: bool = False,
                 integer: bool = False) -> float:
    """``value`` as a finite number, or a :class:`ScenarioError` naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(f"{where} = {value!r}: expected a number")
    if integer and not isinstance(value, int):
        raise ScenarioError(f"{where} = {value!r}: expected an integer")
    if not math.isfinite(value):
        raise ScenarioError(f"{where} = {value!r}: expected a finite number")
    if positive and not value > 0:
        raise ScenarioError(f"{where} = {value!r}: must be positive")
    if nonnegative and not value >= 0:
        raise ScenarioError(f"{where} = {value!r}: must not be negative")
    return value


def _convert(where: str, value: Any, default: Any) -> Any:
    if dataclasses.is_dataclass(default):
        if not isinstance(value, Mapping):
            raise ScenarioError(f"{where} = {value!r}: expected a table of {type(default).__name__} fields")
        return dataclass_from_mapping(type(default), value, where, base=default)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ScenarioError(f"{where} = {value!r}: expected true or false")
        return value
    if isinstance(default, (int, float)):
        return float(check_number(where, value)) if isinstance(default, float) else check_number(where, value, integer=True)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ScenarioError(f"{where} = {value!r}: expected a string")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, (list, tuple)) or len(value) != len(default):
            raise ScenarioError(f"{where} = {value!r}: expected a list of {len(default)} values")
        return tuple(_convert(f"{where}[{i}]", v, d) for i, (v, d) in enumerate(zip(value, default)))
    raise ScenarioError(f"{where}: fields of type {type(default).__name__} cannot be set from a scenario")


def dataclass_from_mapping(cls, values: Mapping[str, Any], where: str, base: Any = None):
    """An instance of the frozen dataclass ``cls``: ``base`` (or the defaults)
    with the entries of ``values`` replaced; ``where`` prefixes error keys."""
    base = base if base is not None else cls()
    known = {f.name: f for f in dataclasses.fields(cls)}
    changes = {}
    for key, value in values.items():
        if key not in known:
            raise ScenarioError(f"{where}.{key}: unknown key; known keys: {', '.join(known)}")
        changes[key] = _convert(f"{where}.{key}", value, getattr(base, key))
    try:
        return dataclasses.replace(base, **changes)
    except (ValueError, TypeError) as exc:
        raise ScenarioError(f"{where}: {exc}") from None
