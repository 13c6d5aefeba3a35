"""What a calibration warns about: the checks that say when the model does
not fit the log (docs/calibration.md, "Warnings").

Each check gives a :class:`Diagnostic`; ``report.md`` opens with them, the
command prints them on stderr, and ``--strict`` turns any into exit status 1.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Diagnostic"]


@dataclass(frozen=True)
class Diagnostic:
    """One warning: ``kind`` (a short fixed identifier, e.g.
    ``"residuals-not-white"``, for the JSON and tests), ``subject`` (the
    output, parameter or column it names, or ``None``) and ``message`` (one
    line for a user, with the numbers that made it)."""

    kind: str
    message: str
    subject: str | None = None
