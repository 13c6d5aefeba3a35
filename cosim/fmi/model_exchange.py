"""How a Model Exchange FMU is integrated: the solver's settings and its errors.

A Model Exchange FMU gives its state derivatives and event indicators; the
importer integrates it (FMI 2.0 §3.1, FMI 3.0 §3.1). The integration itself,
of one FMU or of several connected ones as one system, is
:mod:`cosim.fmi.me_system` (its calls in C); this module holds what a scenario's
``[fmus.X.solver]`` sets (:class:`SolverSettings`) and what cannot be passed
(:class:`IntegrationError`: the solver's own failure, an event iteration that
does not settle, more events in one communication step than ``max_events``,
the FMU asking to terminate), kept apart so a Co-Simulation run loads neither.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

__all__ = ["SolverSettings", "IntegrationError", "METHODS", "JACOBIANS", "COUPLINGS"]

METHODS = ("cvode", "euler")
JACOBIANS = ("difference", "directional")  # CVODE's: difference quotients, or the FMUs' directional derivatives
# connected Model Exchange FMUs: one solver over all their states, or each alone (cosim.fmi.me_system)
COUPLINGS = ("tight", "loose")
DEFAULT_TOLERANCE = 1e-5  # fmpy's, for an FMU whose default experiment gives none


class IntegrationError(RuntimeError):
    """The integration of a Model Exchange FMU cannot go on at ``time``."""

    def __init__(self, time: float, reason: str, terminate: bool = False):
        super().__init__(f"at t = {time!r} s: {reason}")
        self.time, self.reason, self.terminate = time, reason, terminate


@dataclass(frozen=True)
class SolverSettings:
    """How a Model Exchange FMU is integrated (a scenario's ``[fmus.X.solver]``).

    ``method``: ``"cvode"`` (variable step, BDF, root finding) or
    ``"euler"`` (fixed step). ``relative_tolerance``: CVODE's (``None``:
    the tolerance of the FMU's default experiment, else 1e-5, as fmpy's
    ``simulate_fmu`` chooses); the absolute tolerance of each state is it
    times the state's nominal value, as fmpy sets it. ``step``: Euler's step (s; default: the communication step),
    or CVODE's largest step (default: unbounded but for the stop at every
    communication point). ``max_events``: events allowed in one
    communication step before the model is taken to chatter.
    ``jacobian``: CVODE's Newton matrix by its own difference quotients
    (``"difference"``, the default) or from the FMUs' directional
    derivatives through the connections (``"directional"``; every member
    with states or inputs from other members must provide them).
    """

    method: str = "cvode"
    relative_tolerance: float | None = None
    step: float | None = None
    max_events: int = 1000
    jacobian: str = "difference"

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"solver method {self.method!r}: expected one of {', '.join(METHODS)}")
        if self.relative_tolerance is not None and not (0 < self.relative_tolerance < 1):
            raise ValueError(f"relative_tolerance = {self.relative_tolerance!r}: expected a number in (0, 1)")
        if self.step is not None and not (math.isfinite(self.step) and self.step > 0):
            raise ValueError(f"step = {self.step!r} s: expected a positive number")
        if self.jacobian not in JACOBIANS:
            raise ValueError(f"jacobian {self.jacobian!r}: expected one of {', '.join(JACOBIANS)}")
        if self.max_events < 1:
            raise ValueError(f"max_events = {self.max_events!r}: expected a positive integer")

    def for_fmu(self, model_description) -> "SolverSettings":
        """These settings with the relative tolerance resolved for an FMU."""
        if self.relative_tolerance is not None:
            return self
        experiment = model_description.defaultExperiment
        tolerance = experiment.tolerance if experiment is not None and experiment.tolerance is not None else None
        return replace(self, relative_tolerance=float(tolerance) if tolerance is not None else DEFAULT_TOLERANCE)

    def substeps(self, h: float) -> int:
        """Euler steps in one communication step ``h``; the step must divide it."""
        step = self.step if self.step is not None else h
        n = max(1, round(h / step))
        if abs(n * step - h) > 1e-9 * h:
            raise ValueError(f"the Euler step {step!r} s does not divide the communication step {h!r} s")
        return n
