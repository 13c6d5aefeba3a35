"""A parameter dataclass with the values a table gives: the one rule a
validated table (:class:`cosim.scenario.schema.ParameterTable`) and the values a
scenario holds for it (:class:`Given`) share, importing no pydantic.

A scenario's component parameters are its tables' values as validated (the
keys the document gave): a component built from them reads them through
:class:`Given`, as it would read the validated table, instead of validating
them again (a scenario served from the cache, :func:`cosim.scenario.definition.load_scenario`,
then starts with no pydantic at all).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

__all__ = ["replaced", "Given"]


def replaced(base: Any, values: Mapping[str, Any]) -> Any:
    """The frozen dataclass ``base`` with its fields named in ``values``
    replaced (the others ignored): a nested table's values applied to the
    nested dataclass, a list as a tuple. The dataclass checks the result
    (its ``__post_init__``, in its own words)."""
    names = {f.name for f in dataclasses.fields(base)}
    changes = {}
    for name, value in values.items():
        if name not in names:
            continue
        if hasattr(value, "applied"):  # a validated table (ParameterTable, Given)
            changes[name] = value.applied(getattr(base, name))
        elif isinstance(value, Mapping):
            changes[name] = replaced(getattr(base, name), value)
        elif isinstance(value, list):
            changes[name] = tuple(value)
        else:
            changes[name] = value
    return dataclasses.replace(base, **changes)


class Given:
    """A table's values validated before, read as the validated table is:
    each key (``defaults`` for a key not given; a nested table a
    :class:`Given` too), ``model_fields_set`` (the keys given) and
    :meth:`applied`."""

    __slots__ = ("_values", "_defaults", "model_fields_set")

    def __init__(self, values: Mapping[str, Any], defaults: Mapping[str, Any] | None = None):
        self._values = dict(values)
        self._defaults = dict(defaults or {})
        self.model_fields_set = set(self._values)

    def __getattr__(self, key: str) -> Any:
        if key in self._values:
            value = self._values[key]
            return Given(value) if isinstance(value, Mapping) else value
        if key in self._defaults:
            return self._defaults[key]
        raise AttributeError(key)

    def applied(self, base: Any) -> Any:
        """``base`` with the given keys replaced (:func:`replaced`)."""
        return replaced(base, self._values)
