"""The FMU driven by the log: trajectories of segments (Co-Simulation, or
Model Exchange through the master's solver) and the Jacobians of its
right-hand side along them (Model Exchange).

* **Trajectory** of a segment: the instance is started at the segment's
  first instant with the fixed and fitted parameters, then stepped from row
  to row with the log's inputs held over each step (zero-order hold, as the
  master's communication does), reading the compared outputs and the states
  at every row. Its initial state: in Co-Simulation, each state's start
  value, or the parameter that sets it (``<state>_0`` or the settings'
  ``initial_parameters``), set before initialization; in Model Exchange,
  the continuous states set by ``fmiXSetContinuousStates`` in
  Continuous-Time Mode after initialization (FMI 2.0 section 3.2.1, FMI 3.0
  section 3.2.1: the importer owns the states there; the solver restarts),
  whatever the start values' rules. In Co-Simulation the FMU's own
  integrator makes the trajectory (a model fitted to a log it produced
  itself meets it to round-off); in Model Exchange the master's
  (:mod:`cosim.fmi.model_exchange`, through the FMU component's ``do_step``),
  at the settings' tolerance.
* **Right-hand side Jacobians** at each row, on Model Exchange instances of
  the same FMU set to the row's states and inputs: ``A = d der(x)/dx``,
  ``C = dy/dx`` and the columns of fitted inputs from the FMU's directional
  derivatives (FMI 2.0 section 3.2.2, FMI 3.0 section 3.2.2: knowns are
  states and inputs); the columns of fitted parameters by forward
  differences, each on an instance started with the parameter moved by
  ``h`` (``fixed`` parameters are set before initialization and nothing else
  may change them), with the error estimate of ``h`` against ``2 h`` (at
  every :data:`ERROR_EVERY`-th row). :mod:`cosim.calibration.sensitivity` integrates them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..errors import FmuCallError, ScenarioError
from ..fmi.fmu import FmuComponent
from ..fmi.description import start_value_rule
from ..fmi.model_exchange import SolverSettings
from .problem import Problem
from .segments import Segment

__all__ = ["Trajectory", "LogModel", "REL_STEP"]

ERROR_EVERY = 20  # rows: the parameter columns' error estimate (h against 2 h) is made at every 20th row
REL_STEP = np.finfo(float).eps ** (1.0 / 3.0)  # differences: 6e-6 relative, the Jacobian's error about 1e-10


@dataclass
class Trajectory:
    """A segment simulated: ``states`` at rows first..last (one more row
    than ``outputs`` where the log goes on), ``outputs`` at rows
    first..last-1, in the problem's order."""

    states: np.ndarray
    outputs: np.ndarray


class _Fast:
    """One started Model Exchange instance's evaluation calls, bare, at many
    points in one call into C
    (:meth:`cosim.fmi.me_system.ModelExchangeSystem.evaluate_rows`; the value
    references made once): the right-hand side and outputs, and directional
    derivatives. A status above warning is the instance's
    :class:`~cosim.errors.FmuCallError`."""

    def __init__(self, comp: FmuComponent, drive: Sequence[str], outputs: Sequence[str], states: Sequence[str],
                 known_inputs: Sequence[str] = ()):
        import ctypes

        self.comp = comp
        self._dd = comp.bare_call("fmi2GetDirectionalDerivative" if comp.fmi_version == 2 else
                                  "fmi3GetDirectionalDerivative") if comp.provides_directional_derivatives else None
        vr = lambda names: (ctypes.c_uint32 * max(len(names), 1))(*[comp.variables[n].valueReference  # noqa: E731
                                                                     for n in names])
        self.nx, self.ny = len(states), len(outputs)
        self.vu, self.vy = vr(drive), vr(outputs)
        self.unknowns = vr(comp.derivative_names + list(outputs))
        self.knowns = vr(list(states) + list(known_inputs))
        self.n_known = len(states) + len(known_inputs)

    def evaluate_rows(self, t: np.ndarray, x: np.ndarray, u: np.ndarray, derivatives: bool = False):
        """``[der(x); y]`` at each row of ``t`` (s), states ``x``, inputs
        ``u`` (``F``: rows x (nx + ny)), and with ``derivatives`` its
        directional derivatives along the states, then the known inputs
        (``J``: rows x (nx + ny) x knowns; else None)."""
        comp, n = self.comp, t.size
        F = np.empty((n, self.nx + self.ny))
        jac = np.empty((n, self.n_known, self.nx + self.ny)) if derivatives else None
        comp.system.evaluate_rows(comp, np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(x, dtype=float),
                                  np.ascontiguousarray(u, dtype=float), self.vu, self.vy, F,
                                  self._dd if derivatives else None, self.unknowns, self.knowns, jac)
        return F, (jac.transpose(0, 2, 1) if derivatives else None)


class LogModel:
    """The problem's FMU: one instance for trajectories (Co-Simulation or
    Model Exchange: the problem's), Model Exchange instances for Jacobians
    (when the FMU has that interface)."""

    def __init__(self, problem: Problem, initial_parameters: Mapping[str, str] | None = None):
        self.problem = p = problem
        self.cs: FmuComponent = p.fmu  # the trajectories' instance, in either interface
        self.model_exchange = self.cs.interface == "ModelExchange"
        self.drive = p.inputs + p.fit_inputs  # inputs set each step: the log's, then the fitted constants
        self.states = list(p.states)
        self.read = list(dict.fromkeys(p.outputs + self.states))
        self.cs.bind(self.drive, self.read)
        self._out_idx = np.array([self.read.index(o) for o in p.outputs], dtype=int)
        self._x_idx = np.array([self.read.index(s) for s in self.states], dtype=int)
        self.n_params = len(p.fit) - len(p.fit_inputs)
        # Model Exchange sets the states themselves (simulate): no start value needed
        self.setters = {} if self.model_exchange else self._initial_setters(dict(initial_parameters or {}))
        self.times = p.log.times
        self._me: FmuComponent | None = None
        self._pairs: list[tuple[FmuComponent, FmuComponent, float]] = []
        self._started_for: np.ndarray | None = None
        self.derivative_error = 0.0
        self._rows_seen = 0  # the largest difference of a parameter column at h against 2 h (last Jacobian)

    # ---- parameters and initial states ------------------------------------------------------------

    def _initial_setters(self, given: dict[str, str]) -> dict[str, str]:
        """state -> the variable whose start value sets it."""
        variables, name = self.cs.variables, self.cs.path.name
        out = {}
        for s in self.states:
            if s in given:
                target = given[s]
                v = variables.get(target)
                if v is None or start_value_rule(v):
                    raise ScenarioError(f"initial_parameters.{s} = {target!r}: not a variable of {name} whose start "
                                        f"value may be set")
            elif not start_value_rule(variables.get(s)):
                target = s
            elif f"{s}_0" in variables and not start_value_rule(variables[f"{s}_0"]):
                target = f"{s}_0"
            else:
                raise ScenarioError(f"{name}: cannot start a segment at a state {s}: its start value cannot be set "
                                    f"and there is no parameter {s}_0 (name one in the settings' "
                                    f"initial_parameters)")
            out[s] = target
        return out

    def parameters(self, theta: np.ndarray) -> dict[str, float]:
        p = self.problem
        values = dict(p.fixed)
        values.update(zip(p.fit[:self.n_params], map(float, theta[:self.n_params])))
        return values

    def initial_guess(self) -> np.ndarray:
        """Each state's start: its setter's start value (the FMU's default);
        in Model Exchange, the states the FMU's initialization gives at the
        first guess."""
        from .problem import _float

        if self.model_exchange:
            self.cs.start(float(self.times[0]), self.parameters(np.asarray(self.problem.guess, dtype=float)))
            return self.cs.continuous_states()
        return np.array([_float(self.cs.variables[self.setters[s]].start, 0.0) for s in self.states])

    # ---- trajectories -----------------------------------------------------------------------------

    def simulate(self, theta: np.ndarray, seg: Segment, x0: np.ndarray) -> Trajectory:
        """The segment from state ``x0`` under ``theta`` (module docstring)."""
        p, cs, t = self.problem, self.cs, self.times
        n_rows = seg.last - seg.first
        steps = n_rows if seg.last < t.size else n_rows - 1
        parameters = self.parameters(theta) | {self.setters[s]: float(v) for s, v in zip(self.states, x0)
                                               if s in self.setters}
        fitted_u = theta[self.n_params:]
        n_in = len(p.inputs)
        cs.u[n_in:n_in + fitted_u.size] = fitted_u
        cs.u[:n_in] = p.input_values[seg.first]
        cs.enter_initialization(float(t[seg.first]), parameters)
        if self.drive:
            cs.set_inputs(dict(zip(self.drive, cs.u[:len(self.drive)])), float(t[seg.first]))
        cs.exit_initialization(float(t[seg.first]))
        if self.model_exchange:
            cs.set_continuous_states(x0)
            if cs.system is not None and not cs.typed_calls:  # the same calls row by row, in C
                u = np.empty((steps + 1, len(self.drive)))
                u[:, :n_in] = p.input_values[seg.first:seg.first + steps + 1]
                u[:, n_in:] = fitted_u
                y = np.empty((steps + 1, len(self.read)))
                cs.system.rows(cs, np.ascontiguousarray(t[seg.first:seg.first + steps + 1], dtype=float), u, y)
                return Trajectory(y[:, self._x_idx], y[:n_rows, self._out_idx])
        outputs = np.empty((n_rows, len(p.outputs)))
        states = np.empty((steps + 1, len(self.states)))
        y = cs.y
        for i in range(steps + 1):
            k = seg.first + i
            if i:
                if n_in:
                    cs.u[:n_in] = p.input_values[k]
            if self.drive:
                cs.write_inputs(float(t[k]))
            cs.read_outputs(float(t[k]))
            if i < n_rows:
                outputs[i] = y[self._out_idx]
            states[i] = y[self._x_idx]
            if i < steps:
                cs.do_step(float(t[k]), float(t[k + 1] - t[k]))
        return Trajectory(states, outputs)

    @property
    def difference_step(self) -> float:
        """The relative step of differences of whole simulations
        (:mod:`cosim.calibration.solve`): ``eps^(1/3)`` where a trajectory is
        a deterministic function to round-off (Co-Simulation, Euler), the
        integration's relative tolerance to the 1/3 in Model Exchange with
        CVODE (2e-3 at 1e-8: central differences' error balances the
        truncation ``h^2`` against the solver's error over ``h``; the
        round-off step meets only that error)."""
        if self.model_exchange and self.cs.solver.method == "cvode":
            return max(REL_STEP, self.cs.solver.relative_tolerance ** (1.0 / 3.0))
        return REL_STEP

    # ---- Jacobians of the right-hand side -------------------------------------------------------

    @property
    def has_derivatives(self) -> bool:
        md = self.cs.model_description
        if md.modelExchange is None or not self.states:
            return False
        return self._model_exchange().provides_directional_derivatives

    def _model_exchange(self, name: str = "jacobian") -> FmuComponent:
        comp = FmuComponent(name, self.cs.path, interface="ModelExchange", solver=SolverSettings(method="euler"))
        comp.bind(self.drive, [o for o in self.problem.outputs if o not in self.states])
        return comp

    def start_probes(self, theta: np.ndarray, t0: float) -> None:
        """The Model Exchange instances at ``theta``: one at it, and per fitted
        parameter one at ``theta_j + h`` and one at ``theta_j + 2 h`` (the
        error estimate; ``-h`` and ``-2 h`` where ``+2 h`` passes the bound)."""
        if self._started_for is not None and np.array_equal(theta, self._started_for):
            return
        if self._me is None:
            self._me = self._model_exchange()
            self._pairs = [(self._model_exchange(f"h{j}"), self._model_exchange(f"2h{j}"), 0.0)
                           for j in range(self.n_params)]
        base = self.parameters(theta)
        self._me.start(t0, base)
        self._fast = {id(self._me): self._fastof(self._me)}
        p = self.problem
        for j, (one, two, _) in enumerate(self._pairs):
            name = p.fit[j]
            h = REL_STEP * max(abs(float(theta[j])), abs(p.defaults.get(name, 0.0)), 1e-300)
            if float(theta[j]) + 2 * h > p.upper[j]:
                h = -h
            one.start(t0, base | {name: float(theta[j]) + h})
            two.start(t0, base | {name: float(theta[j]) + 2 * h})
            self._fast[id(one)], self._fast[id(two)] = self._fastof(one), self._fastof(two)
            self._pairs[j] = (one, two, (float(theta[j]) + h) - float(theta[j]))
        self._started_for = theta.copy()
        nx = len(self.states)
        others = list(self._me.output_names)
        self._state_rows = [(i, self.states.index(o)) for i, o in enumerate(p.outputs) if o in self.states]
        self._other_rows = [(i, nx + others.index(o)) for i, o in enumerate(p.outputs) if o not in self.states]

    def _fastof(self, comp: FmuComponent) -> _Fast:
        return _Fast(comp, self.drive, comp.output_names, self.states, self.problem.fit_inputs)

    def jacobians_at(self, theta: np.ndarray, t: np.ndarray, X: np.ndarray, U_log: np.ndarray):
        """At the rows given (times ``t``, states ``X``, the log's inputs
        ``U_log``, one row each), stacked on a leading axis of rows:
        ``(A, G, C, D)``: ``A = d der(x)/dx`` (nx x nx), ``G = d der(x)/d
        theta`` (nx x fitted), ``C = dy/dx``, ``D = dy/d theta`` over the
        compared outputs (a compared state: a row of the identity). A
        parameter's column by forward differences at ``h = eps^(1/3)
        max(|theta_j|, |default_j|)`` (about 1e-10 relative here, as the
        Jacobian needs), its error estimate against ``2 h`` at every
        :data:`ERROR_EVERY`-th row. Each instance's calls for all the rows
        in one call into C."""
        p, fast = self.problem, self._fast
        m = t.size
        U = np.hstack([U_log.reshape(m, -1), np.tile(theta[self.n_params:], (m, 1))]) if self.drive else \
            np.zeros((m, 0))
        me = fast[id(self._me)]
        F0, J = me.evaluate_rows(t, X, U, derivatives=True)  # rows x (nx + ny) x (states, then fitted inputs)
        nx, npar = len(self.states), self.n_params
        Jt = np.empty((m, J.shape[1], len(p.fit)))
        Jt[:, :, npar:] = J[:, :, nx:]
        check = (self._rows_seen + np.arange(m)) % ERROR_EVERY == 0
        self._rows_seen += m
        for j, (one, two, h) in enumerate(self._pairs):
            col = (fast[id(one)].evaluate_rows(t, X, U)[0] - F0) / h
            if check.any():
                col2 = (fast[id(two)].evaluate_rows(t[check], X[check], U[check])[0] - F0[check]) / (2 * h)
                self.derivative_error = max(self.derivative_error,
                                            float(np.max(np.abs(col[check] - col2), initial=0.0)))
            Jt[:, :, j] = col
        ny = len(p.outputs)
        C, D = np.zeros((m, ny, nx)), np.zeros((m, ny, len(p.fit)))
        for i, k in self._state_rows:
            C[:, i, k] = 1.0
        for i, r in self._other_rows:
            C[:, i] = J[:, r, :nx]
            D[:, i] = Jt[:, r]
        return J[:, :nx, :nx], Jt[:, :nx], C, D

    def close(self) -> None:
        for comp in [self._me] + [c for pair in self._pairs for c in pair[:2]]:
            if comp is not None:
                comp.close()
