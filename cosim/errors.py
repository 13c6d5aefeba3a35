"""The exceptions of the co-simulation master, each naming what went wrong.

All derive from :class:`CosimError`, so a caller (the CLI) can catch one type
and print the message; the messages name the connection, key, signal or FMI
call concerned, never just a status code.
"""
from __future__ import annotations

import math

__all__ = ["CosimError", "ConnectionCheckError", "ScenarioError", "DivergenceError", "FmuCallError"]


class CosimError(Exception):
    """Base class of every error the master raises on purpose."""


class ConnectionCheckError(CosimError):
    """A declared connection is wrong (unknown variable, causality, type, unit)."""


class ScenarioError(CosimError):
    """A scenario file is invalid: names the key, the value and what was expected."""


class DivergenceError(CosimError):
    """The run left its declared envelope or produced a non-finite value.

    Attributes ``time`` (s), ``signal`` and ``value`` name the first violation.
    """

    def __init__(self, time: float, signal: str, value: float, bounds: tuple[float, float] | None):
        self.time, self.signal, self.value, self.bounds = time, signal, value, bounds
        if bounds is None or not math.isfinite(value):
            what = "is not a finite number"
        else:
            what = f"is outside its envelope [{bounds[0]:g}, {bounds[1]:g}]"
        super().__init__(f"diverged at t = {time:.4f} s: {signal} = {value!r} {what}")


class FmuCallError(CosimError):
    """An FMI call returned an error status; carries the FMU's own log messages."""
