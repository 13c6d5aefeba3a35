"""A Model Exchange FMU integrated between communication points.

A Model Exchange FMU gives its state derivatives and event indicators; the
importer integrates it (FMI 2.0 §3.1, FMI 3.0 §3.1). Between two
communication points ``t_n`` and ``t_{n+1}`` the master holds the inputs
(set at ``t_n``) and :meth:`Integrator.advance` integrates the FMU with:

* **CVODE** (BDF with root finding on the event indicators, the SUNDIALS
  build fmpy ships and drives in ``simulate_fmu``: :class:`fmpy.sundials.CVodeSolver`),
  told to stop exactly at ``t_{n+1}`` and at every time event
  (``CVodeSetStopTime``), so the outputs read at ``t_{n+1}`` are values of
  the solution there, not an interpolation a step behind; or
* **forward Euler** at a fixed step (``step``, a whole fraction of the
  communication step), the integrator the Reference FMUs' own Co-Simulation
  uses, so their published results are reproduced to rounding.

Events, as fmpy's ``simulateME`` handles them (the reference this follows):
time events at ``nextEventTime`` (the integration stops there), state
events where an event indicator changes sign (CVODE locates the root; Euler
sees it at the end of the step), step events when
``completedIntegratorStep`` asks for one; each is handled in Event Mode by
the event iteration (FMI 2.0 ``fmi2NewDiscreteStates``, FMI 3.0
``fmi3UpdateDiscreteStates``, until no new discrete states are needed), then
the solver restarts from the states the event left. The solver also
restarts at a communication point where an input changed (the right-hand
side may jump there): :meth:`Integrator.restart`.

What cannot be passed is an :class:`IntegrationError` naming the time: the
solver's own failure (CVODE's message), an event iteration that does not
settle, more events in one communication step than ``max_events`` (a
chattering or Zeno model), the FMU asking to terminate.
"""
from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["SolverSettings", "Integrator", "IntegrationError", "METHODS"]

METHODS = ("cvode", "euler")
DEFAULT_TOLERANCE = 1e-5  # fmpy's, for an FMU whose default experiment gives none
MAX_EVENT_ITERATIONS = 1000  # newDiscreteStates calls at one event instant


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
    """

    method: str = "cvode"
    relative_tolerance: float | None = None
    step: float | None = None
    max_events: int = 1000

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"solver method {self.method!r}: expected one of {', '.join(METHODS)}")
        if self.relative_tolerance is not None and not (0 < self.relative_tolerance < 1):
            raise ValueError(f"relative_tolerance = {self.relative_tolerance!r}: expected a number in (0, 1)")
        if self.step is not None and not (math.isfinite(self.step) and self.step > 0):
            raise ValueError(f"step = {self.step!r} s: expected a positive number")
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


class _HeldInputs:
    """fmpy's solver asks its input object to apply the inputs at every root
    evaluation; the master sets them at the communication point and holds them."""

    @staticmethod
    def apply(time, continuous=True, discrete=True, after_event=False):
        pass


def _set_stop_time():
    """``CVodeSetStopTime`` from fmpy's SUNDIALS build (fmpy does not wrap it)."""
    from fmpy.sundials.libraries import sundials_cvode
    from fmpy.sundials.sundials_types import sunrealtype

    function = sundials_cvode.CVodeSetStopTime
    function.argtypes, function.restype = [ctypes.c_void_p, sunrealtype], ctypes.c_int
    return function


class Integrator:
    """One Model Exchange instance's time between communication points.

    ``model`` is fmpy's ``FMU2Model`` or ``FMU3Model`` (instantiated, out of
    Initialization Mode); :meth:`start` runs the initial event iteration and
    enters Continuous-Time Mode; :meth:`advance` integrates from ``t`` to
    ``t_end``, handling every event on the way.
    """

    def __init__(self, model, version: int, n_states: int, n_indicators: int, needs_completed_step: bool,
                 settings: SolverSettings):
        self.model, self.version, self.settings = model, version, settings
        self.nx, self.nz = n_states, n_indicators
        self.needs_completed_step = needs_completed_step
        self.next_event_time: float | None = None
        self.events = 0  # handled since start (time, state and step events)
        self._solver = None
        self._restart = False
        if settings.method == "euler":
            self.x, self.dx = np.zeros(n_states), np.zeros(n_states)
            self.z, self.z_before = np.zeros(n_indicators), np.zeros(n_indicators)
            ptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
            self._px, self._pdx, self._pz = ptr(self.x), ptr(self.dx), ptr(self.z)

    # ---- events ------------------------------------------------------------

    def _derivatives(self, pointer, n):
        m = self.model
        return m.getDerivatives(pointer, n) if self.version == 2 else m.getContinuousStateDerivatives(pointer, n)

    def event_iteration(self, t: float) -> None:
        """In Event Mode: update the discrete states until none is needed
        (FMI 2.0 §3.2.2 ``fmi2NewDiscreteStates``, FMI 3.0 §3.2.2
        ``fmi3UpdateDiscreteStates``); the next time event is kept."""
        update = self.model.newDiscreteStates if self.version == 2 else self.model.updateDiscreteStates
        for _ in range(MAX_EVENT_ITERATIONS):
            needed, terminate, _, _, defined, next_time = update()
            if terminate:
                raise IntegrationError(t, "the FMU asked to terminate the simulation at an event", terminate=True)
            if not needed:
                self.next_event_time = float(next_time) if defined else None
                return
        raise IntegrationError(t, f"the event iteration did not settle in {MAX_EVENT_ITERATIONS} updates "
                                  f"of the discrete states")

    def handle_event(self, t: float, in_event_mode=None) -> None:
        """An event at ``t``, from Continuous-Time Mode: Event Mode (where
        ``in_event_mode()`` is called, e.g. to set discrete inputs), the event
        iteration, back to Continuous-Time Mode; the solver restarts."""
        self.model.enterEventMode()
        if in_event_mode is not None:
            in_event_mode()
        self.event_iteration(t)
        self.model.enterContinuousTimeMode()
        self.events += 1
        self._restart = True

    def start(self, t0: float) -> None:
        """After ``exitInitializationMode``: the initial event iteration
        (the FMU is in Event Mode), Continuous-Time Mode, the solver at ``t0``."""
        self.event_iteration(t0)
        self.model.enterContinuousTimeMode()
        self.events = 0
        self._solver = None
        self._restart = True

    def restart(self) -> None:
        """The states or the inputs changed outside the solver (an input set
        at a communication point, a state restored): start it afresh there."""
        self._restart = True

    # ---- integration ---------------------------------------------------------

    def _cvode(self, t: float):
        if self._solver is None:
            from fmpy.sundials import CVodeSolver

            m, s = self.model, self.settings
            self._solver = CVodeSolver(
                nx=self.nx, nz=self.nz, get_x=m.getContinuousStates, set_x=m.setContinuousStates,
                get_dx=self._derivatives, get_z=m.getEventIndicators, get_nominals=m.getNominalsOfContinuousStates,
                set_time=m.setTime, input=_HeldInputs(), startTime=t,
                maxStep=s.step if s.step is not None else float("inf"), relativeTolerance=s.relative_tolerance,
                maxNumSteps=100_000)
            self._stop_at = _set_stop_time()
        elif self._restart:
            self._solver.reset(t)
        self._restart = False
        return self._solver

    def advance(self, t: float, t_end: float) -> None:
        """Integrate from ``t`` to ``t_end`` with the inputs held, handling the
        time, state and step events on the way; the FMU is left at ``t_end``
        in Continuous-Time Mode (an event at ``t_end`` handled)."""
        h = t_end - t
        close = 1e-9 * max(h, 1e-300)  # a time event this near t_end is at t_end (its time is a sum of steps)
        events_before = self.events
        euler = self.settings.method == "euler"
        substep = (self.settings.step or h) if euler else None
        if euler:
            self.settings.substeps(h)  # the step divides the communication step
        while t_end - t > close:
            target, time_event = t_end, False
            if self.next_event_time is not None and self.next_event_time <= t_end + close:
                if self.next_event_time < t - close:
                    raise IntegrationError(t, f"the FMU's next time event {self.next_event_time!r} s lies in "
                                              f"the past")
                target, time_event = (t_end if abs(self.next_event_time - t_end) <= close else
                                      max(self.next_event_time, t)), True
            if euler:  # whole steps of the given size (the step the Reference FMUs' own Euler takes), cut at events
                whole = target - (t + substep) > -close  # a whole step fits (to rounding)
                dt = substep if whole else target - t
                reached = t + substep if target - (t + substep) > close else target
                state_event = self._euler_step(t, reached, dt)
                time_event = time_event and reached == target
            else:
                state_event, reached = self._cvode_step(t, target)
                time_event = time_event and not state_event
            self.model.setTime(reached)
            step_event = False
            if self.needs_completed_step:
                step_event, terminate = self.model.completedIntegratorStep()
                if terminate:
                    raise IntegrationError(reached, "the FMU asked to terminate the simulation", terminate=True)
            t = reached
            if time_event or state_event or step_event:
                if self.events - events_before >= self.settings.max_events:
                    raise IntegrationError(t, f"more than {self.settings.max_events} events in one communication "
                                              f"step: the model chatters (a discontinuity the solver cannot pass)")
                self.handle_event(t)

    def _cvode_step(self, t: float, target: float) -> tuple[bool, float]:
        solver = self._cvode(t)
        self._stop_at(solver.cvode_mem, target)
        try:
            _, roots, reached = solver.step(t, target)  # its flag is also > 0 at the stop time: ask the roots
        except RuntimeError as exc:  # CVODE's own message (too much work, error test failures, ...)
            raise IntegrationError(t, str(exc)) from None
        state_event = bool(np.any(roots))
        return state_event, float(reached) if state_event else target

    def _euler_step(self, t: float, t_next: float, dt: float) -> bool:
        """One forward Euler step; a state event where an indicator changed
        sign over it (fmpy's ``ForwardEuler``: seen at the end of the step)."""
        m, nx, nz = self.model, self.nx, self.nz
        if self._restart or self._solver is None:
            if nz:
                m.getEventIndicators(self._pz, nz)
            self._solver, self._restart = "euler", False
        if nx:
            m.getContinuousStates(self._px, nx)
            self._derivatives(self._pdx, nx)
            self.x += dt * self.dx
            m.setTime(t_next)
            m.setContinuousStates(self._px, nx)
        if not nz:
            return False
        self.z_before[:] = self.z
        m.getEventIndicators(self._pz, nz)
        before, after = self.z_before, self.z
        return bool(np.any((before < 0) & (after >= 0) | (before > 0) & (after <= 0)))
