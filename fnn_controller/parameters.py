"""Parameters with their unit, description and admissible range, on the
dataclass fields themselves, so that the checks, the documentation, the
scenario errors and the controller FMU's modelDescription all read one place.

    kp: float = param(2.5, "1/s", "proportional gain of eq. 19", min=0.0)

A tuple field (one value per axis) is checked element by element.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Iterator

__all__ = ["param", "ParameterInfo", "parameter_info", "check_ranges"]


def param(default: Any, unit: str, description: str, min: float = -math.inf, max: float = math.inf):
    """A dataclass field carrying its unit, description and range (inclusive)."""
    return dataclasses.field(default=default, metadata={"unit": unit, "description": description,
                                                        "min": min, "max": max})


@dataclass(frozen=True)
class ParameterInfo:
    name: str
    default: Any
    unit: str
    description: str
    min: float
    max: float


def parameter_info(cls) -> Iterator[ParameterInfo]:
    """The documented fields of a parameter dataclass (those made by :func:`param`)."""
    for f in dataclasses.fields(cls):
        if "unit" in f.metadata:
            m = f.metadata
            yield ParameterInfo(f.name, f.default, m["unit"], m["description"], m["min"], m["max"])


def check_ranges(obj) -> None:
    """Raise ``ValueError`` naming the first field of ``obj`` outside its range."""
    for info in parameter_info(type(obj)):
        value = getattr(obj, info.name)
        for i, v in enumerate(value if isinstance(value, tuple) else (value,)):
            where = f"{info.name}[{i}]" if isinstance(value, tuple) else info.name
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{type(obj).__name__}.{where} = {v!r} is not a finite number")
            if not info.min <= v <= info.max:
                raise ValueError(f"{type(obj).__name__}.{where} = {v!r} {info.unit} is outside its range "
                                 f"[{info.min:g}, {info.max:g}]")
