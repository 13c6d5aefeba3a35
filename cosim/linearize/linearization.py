"""Linearization of an FMU (FMI 2.0 or 3.0) at an operating point.

The engine's one way to linearize an FMU; it knows no model. It returns a
:class:`Linearization`: a ``control.StateSpace`` whose states, inputs and
outputs carry the FMU's variable names (their units in :attr:`Linearization.units`),
the method used and an estimate of its error.

* **Model Exchange** (continuous time): ``A, B, C, D`` of
  ``der(x) = f(x, u)``, ``y = g(x, u)`` at the state and inputs given.
  With ``providesDirectionalDerivative(s)`` each column is one directional
  derivative (``fmiXGetDirectionalDerivative``, seed 1 on one known): exact
  to round-off. Otherwise (or with ``method="differences"``) central
  differences, the step of variable ``j`` being ``h_j = eps^(1/3) *
  max(|v_j|, nominal_j)`` (the step that balances the O(h^2) truncation
  against round-off; a Model Exchange evaluation integrates nothing, so
  the FMU's tolerance does not enter); the error estimate is the largest
  difference between the Jacobians at ``h`` and ``2 h``.
* **Co-Simulation, sampled data** (an FMU declaring its period,
  :data:`cosim.fmi.description.PERIOD_ANNOTATION`): the discrete-time map over
  one period, ``z+ = A z + B u``, ``y = C z + D u``, ``dt`` the period. The
  discrete states ``z`` are the FMU's local Real variables of variability
  ``discrete``; they must be readable and settable between communication
  steps (this project's exporter allows it, docs/stability.md "Discrete
  states"), and the FMU must be able to get and set its state, which is
  restored before every evaluation. Central differences as above; the map
  is evaluated by one ``doStep``.
* Anything else (a Co-Simulation FMU with no Model Exchange interface, no
  declared period, or discrete states it refuses to set) is refused with a
  :class:`LinearizationError` saying why, in one line.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from ..errors import FmuCallError, FmuLoadError
from ..fmi.fmu import FmuComponent
from ..names import nearest_told

if TYPE_CHECKING:
    import control

__all__ = ["Linearization", "LinearizationError", "linearize_fmu", "save_linearization", "operating_point_of_run",
           "METHODS"]

METHODS = ("auto", "derivatives", "differences")
_REL_STEP = np.finfo(float).eps ** (1.0 / 3.0)  # central differences: truncation h^2 vs round-off eps / h


class LinearizationError(ValueError):
    """An FMU, or an operating point, this module cannot linearize; one line."""


@dataclass(frozen=True, eq=False)
class Linearization:
    """The linear system and how it was obtained.

    ``system``: ``control.StateSpace`` (``dt`` = 0 for Model Exchange, the
    period for a sampled-data FMU), its ``state_labels``, ``input_labels``
    and ``output_labels`` the FMU's variable names. ``method``:
    ``"directional derivatives"`` or ``"central differences"``.
    ``error_estimate``: for differences, the largest absolute difference of
    any entry of ``[A B; C D]`` between steps ``h`` and ``2 h``; 0.0 for
    directional derivatives (exact to round-off). ``units``: variable name
    -> unit (``""`` when the FMU declares none). ``operating_point``: the
    states, inputs and parameters linearized at; ``outputs``: the outputs
    there (for a sampled-data FMU, those of its step at the point).
    """

    system: control.StateSpace
    method: str
    error_estimate: float
    units: dict[str, str] = field(default_factory=dict)
    operating_point: dict[str, float] = field(default_factory=dict)
    outputs: dict[str, float] = field(default_factory=dict)

    @property
    def A(self) -> np.ndarray:
        return np.asarray(self.system.A)

    @property
    def B(self) -> np.ndarray:
        return np.asarray(self.system.B)

    @property
    def C(self) -> np.ndarray:
        return np.asarray(self.system.C)

    @property
    def D(self) -> np.ndarray:
        return np.asarray(self.system.D)

    @cached_property
    def poles(self) -> np.ndarray:
        """The eigenvalues of ``A`` (none for a system without states)."""
        return np.linalg.eigvals(self.A) if self.system.nstates else np.zeros(0, dtype=complex)

    def stability_measure(self) -> tuple[str, float] | None:
        """What decides the system's stability, named: a sampled-data
        system's spectral radius (stable below 1), a continuous one's largest
        real part of a pole (stable below 0); ``None`` without states."""
        if not self.system.nstates:
            return None
        if self.system.dt:
            return "spectral radius", float(np.max(np.abs(self.poles)))
        return "largest real part", float(np.max(self.poles.real))


def _check_values(what: str, values: Mapping[str, float], variables: Mapping, allowed: Sequence[str]) -> None:
    for name, value in values.items():
        var = variables.get(name)
        if var is None:
            raise LinearizationError(f"{what} {name!r}: the FMU has no such variable{nearest_told(name, variables)}")
        if var.causality not in allowed:
            raise LinearizationError(f"{what} {name!r}: it is a {var.causality}, not a {' or '.join(allowed)}")
        if not np.isfinite(float(value)):
            raise LinearizationError(f"{what} {name} = {value!r}: not a finite number")


def _check_states(start: Mapping[str, float], variables: Mapping, states: Sequence[str], kind: str) -> None:
    for name, value in start.items():
        if name not in variables:
            raise LinearizationError(f"start value {name!r}: the FMU has no such variable{nearest_told(name, variables)}")
        if name not in states:
            raise LinearizationError(f"start value {name!r}: not a {kind} state of the FMU "
                                     f"(its {kind} states: {', '.join(states) or 'none'})")
        if not np.isfinite(float(value)):
            raise LinearizationError(f"start value {name} = {value!r}: not a finite number")


def _scale(var, value: float) -> float:
    nominal = getattr(var, "nominal", None)
    try:
        nominal = abs(float(nominal)) if nominal is not None else 1.0
    except (TypeError, ValueError):
        nominal = 1.0
    return max(abs(value), nominal if nominal > 0 else 1.0)


def _central(evaluate, base: np.ndarray, scales: np.ndarray) -> tuple[np.ndarray, float]:
    """Jacobian of ``evaluate(v)`` at ``base`` by central differences, with the
    estimate ``max |J(h) - J(2 h)|``."""
    def jac(factor):
        columns = []
        for j in range(base.size):
            h = factor * _REL_STEP * scales[j]
            plus, minus = base.copy(), base.copy()
            plus[j] += h
            minus[j] -= h
            columns.append((evaluate(plus) - evaluate(minus)) / (2.0 * h))
        return np.array(columns).T
    J = jac(1.0)
    return J, float(np.max(np.abs(J - jac(2.0)), initial=0.0))


def linearize_fmu(path: str | Path, *, start: Mapping[str, float] | None = None,
                  inputs: Mapping[str, float] | None = None, parameters: Mapping[str, float] | None = None,
                  fmu_state: bytes | None = None, t: float = 0.0, method: str = "auto",
                  interface: str = "auto", instance: FmuComponent | None = None) -> Linearization:
    """Linearize the FMU at ``path`` at an operating point.

    ``parameters`` are set before initialization; ``start`` sets continuous
    states (Model Exchange, after initialization) or discrete states
    (sampled-data Co-Simulation, after initialization or after restoring
    ``fmu_state``); ``inputs`` the inputs. ``fmu_state`` is a serialized
    Co-Simulation FMU state, e.g. ``FmuComponent.serialize_state()`` or a
    :class:`~cosim.loop.master.Snapshot`'s during a run at time ``t``: the
    operating point is then the run's. For a sampled-data FMU it is restored
    and stepped; for Model Exchange a Co-Simulation instance restores it and
    its continuous states' values are read from it (``start`` may still
    override some). ``instance``: a live, started Co-Simulation instance of
    the same FMU (e.g. a master's, :class:`~cosim.fmi.fmu.FmuComponent`)
    that restores ``fmu_state`` instead of a new one, and is left in its own
    state. ``method``:
    ``"auto"`` (directional derivatives where the FMU provides them),
    ``"derivatives"`` or ``"differences"``. ``interface``: ``"auto"`` (Model
    Exchange if the FMU has it and has continuous states, else
    Co-Simulation: a clocked sampled-data FMI 3.0 FMU also
    declares Model Exchange, where its ticks are time events and it has no
    continuous state to linearize), ``"me"`` or ``"cs"``.

    Every instance is an :class:`~cosim.fmi.fmu.FmuComponent`: the FMU
    is extracted within the limits of :mod:`cosim.files` (an archive beyond
    them is refused in one line, an :class:`~cosim.errors.FmuLoadError`),
    and a refused call quotes the FMU's own log.
    """
    path = Path(path)
    if method not in METHODS:
        raise LinearizationError(f"method {method!r}: not one of {', '.join(METHODS)}")
    if not np.isfinite(t):
        raise LinearizationError(f"time t = {t!r}: not a finite number")
    if interface not in ("auto", "me", "cs"):
        raise LinearizationError(f"interface {interface!r}: not one of auto, me, cs")
    comp = _component(path, interface)
    try:
        variables = comp.variables
        start, inputs, parameters = dict(start or {}), dict(inputs or {}), dict(parameters or {})
        _check_values("input", inputs, variables, ("input",))
        _check_values("parameter", parameters, variables, ("parameter",))
        if comp.interface == "ModelExchange":
            if fmu_state is not None:
                start = _values_in_state(path, parameters, fmu_state, t, comp.state_names, instance) | start
            return _linearize_me(path, comp, start, inputs, parameters, t, method)
        if instance is not None and fmu_state is not None:  # the lent instance, left in its own state after
            return instance.in_state(fmu_state, lambda: _linearize_sampled(path, instance, start, inputs, parameters,
                                                                           None, t, method))
        return _linearize_sampled(path, comp, start, inputs, parameters, fmu_state, t, method)
    except FmuCallError as exc:
        raise LinearizationError(f"{path.name}: an FMU call failed while linearizing ({exc})") from None
    finally:
        comp.close()


def _component(path: Path, interface: str) -> FmuComponent:
    """The instance to linearize with: Model Exchange (an instance evaluated,
    never stepped) where asked, or, for ``auto``, where the FMU has it and has
    continuous states; else Co-Simulation."""
    def make(which):
        try:
            return FmuComponent("linearize", path, interface=which)
        except FmuLoadError as exc:
            if exc.setting != ("interface", which):  # a file that is no usable FMU: the master's one line
                raise
            return None

    if interface != "cs":
        comp = make("ModelExchange")
        if comp is None and interface == "me":
            raise LinearizationError(f"{path.name}: no Model Exchange interface")
        if comp is not None and (interface == "me" or comp.state_names):
            return comp
        # no Model Exchange, or a clocked FMI 3.0 FMU's: no continuous state to linearize
    comp = make("CoSimulation")
    if comp is None:
        raise LinearizationError(f"{path.name}: no Co-Simulation interface")
    return comp


def _refused(path: Path, exc: FmuCallError) -> LinearizationError:
    """The FMU's refusal of the operating point, naming the value it refused
    first (``m = -1.0``) where the failing call set one."""
    if exc.variable is not None:
        return LinearizationError(f"{path.name}: {exc.variable} = {exc.value!r}: the FMU refuses it "
                                  f"({exc.log or exc.reason})")
    return LinearizationError(f"{path.name}: the FMU refused the operating point ({exc})")


def _values_in_state(path: Path, parameters, fmu_state: bytes, t: float, names,
                     instance: FmuComponent | None) -> dict[str, float]:
    """``names``' values in a serialized Co-Simulation FMU state, read on
    ``instance`` or on a Co-Simulation instance started with ``parameters``."""
    cs = instance or FmuComponent("state", path)
    if not cs.model_description.coSimulation or not cs.model_description.coSimulation.canGetAndSetFMUstate:
        raise LinearizationError(f"{path.name}: an FMU state is read through Co-Simulation, and this FMU cannot "
                                 "set its FMU state there")
    try:
        if instance is None:
            cs.start(t, parameters)
        return cs.state_values(fmu_state, names, t)
    except FmuCallError as exc:
        raise _refused(path, exc) from None
    finally:
        if instance is None:
            cs.close()


def _units(names, variables) -> dict[str, str]:
    return {n: variables[n].unit or "" for n in names}


def _system(A, B, C, D, states, ins, outs, dt=0) -> control.StateSpace:
    # python-control imported here, when a system is made: with the SciPy and matplotlib it imports about
    # 3 s of CPU, which a command refusing its input (or a process importing this module) need not pay
    import control

    return control.ss(A, B, C, D, dt, states=list(states), inputs=list(ins), outputs=list(outs))


def _reals(md, causality: str) -> list[str]:
    return [v.name for v in md.modelVariables if v.causality == causality and v.type in ("Real", "Float64")]


# ---- Model Exchange ---------------------------------------------------------------------------

def _linearize_me(path, comp: FmuComponent, start, inputs, parameters, t, method) -> Linearization:
    md, variables = comp.model_description, comp.variables
    provides = comp.provides_directional_derivatives
    if method == "derivatives" and not provides:
        raise LinearizationError(f"{path.name}: provides no directional derivatives (use differences)")
    use_dd = provides and method != "differences"
    state_names = comp.state_names
    _check_states(start, variables, state_names, "continuous")
    in_names, out_names = _reals(md, "input"), _reals(md, "output")
    nx = len(state_names)
    try:  # the inputs given are set in Initialization Mode; start() ends in Continuous-Time Mode
        comp.start(t, parameters, inputs)
    except FmuCallError as exc:
        raise _refused(path, exc) from None
    x = comp.continuous_states()
    for i, n in enumerate(state_names):
        if n in start:
            x[i] = float(start[n])
    held = comp.get_reals([n for n in in_names if n not in inputs])
    u = np.array([float(inputs[n]) if n in inputs else held[n] for n in in_names])

    def put(xv, uv):
        comp.set_continuous_states(xv)
        comp.set_reals(dict(zip(in_names, uv)))

    put(x, u)
    point = dict(zip(state_names, x)) | dict(zip(in_names, u)) | parameters
    y0 = comp.get_reals(out_names)
    if use_dd:
        J = comp.directional_derivatives(comp.derivative_names + out_names, state_names + in_names)
        error, how = 0.0, "directional derivatives"
    else:
        def evaluate(v):
            put(v[:nx], v[nx:])
            return np.concatenate([comp.derivatives(), np.fromiter(comp.get_reals(out_names).values(), float)])
        base = np.concatenate([x, u])
        scales = np.array([_scale(variables[n], b) for n, b in zip(state_names + in_names, base)])
        J, error = _central(evaluate, base, scales)
        put(x, u)
        how = "central differences"
    A, B = J[:nx, :nx], J[:nx, nx:]
    C, D = J[nx:, :nx], J[nx:, nx:]
    system = _system(A, B, C, D, state_names, in_names, out_names)
    return Linearization(system, how, error, _units(state_names + in_names + out_names, variables), point, y0)


# ---- Co-Simulation, sampled data ---------------------------------------------------------------

def _linearize_sampled(path, comp: FmuComponent, start, inputs, parameters, fmu_state, t,
                       method) -> Linearization:
    """The one-period map on ``comp``: started here with ``parameters`` (and
    ``fmu_state`` restored) unless it is a live instance already in the
    state to linearize at (``fmu_state`` None and ``comp`` started)."""
    if method == "derivatives":
        raise LinearizationError(f"{path.name}: a Co-Simulation step has no directional derivatives here "
                                 "(use differences)")
    md, variables = comp.model_description, comp.variables
    if not md.coSimulation.canGetAndSetFMUstate:
        raise LinearizationError(f"{path.name}: cannot linearize its Co-Simulation step: it cannot get and "
                                 "set its FMU state")
    if comp.sample_period is None:
        if md.modelExchange is not None:  # auto chose Co-Simulation: its Model Exchange has no continuous state
            raise LinearizationError(f"{path.name}: cannot linearize its Co-Simulation step: it declares no sample "
                                     f"period; its Model Exchange interface has no continuous state: linearize that "
                                     f"(interface me, --interface me) for the static map of its inputs to its outputs")
        raise LinearizationError(f"{path.name}: cannot linearize its Co-Simulation step: it declares no "
                                 "sample period (a black-box Co-Simulation FMU, and no Model Exchange)")
    z_names = [v.name for v in md.modelVariables if v.causality == "local" and v.variability == "discrete"
               and v.type in ("Real", "Float64")]
    _check_states(start, variables, z_names, "discrete")
    in_names, out_names = _reals(md, "input"), _reals(md, "output")
    if comp._slave is None:  # a new instance (not a live one lent by the caller)
        try:
            comp.start(t, parameters)
            if fmu_state is not None:
                comp.restore_state(fmu_state)
        except FmuCallError as exc:
            raise _refused(path, exc) from None
    period = float(parameters.get(comp.sample_period, comp.get_reals([comp.sample_period])[comp.sample_period]))
    z = np.fromiter(comp.get_reals(z_names).values(), float, len(z_names))
    for i, n in enumerate(z_names):
        if n in start:
            z[i] = float(start[n])
    held = comp.get_reals([n for n in in_names if n not in inputs])
    u = np.array([float(inputs[n]) if n in inputs else held[n] for n in in_names])
    try:
        comp.set_reals(dict(zip(z_names, z)))
    except FmuCallError:
        said = "; ".join(comp.messages)
        raise LinearizationError(f"{path.name}: cannot linearize its Co-Simulation step: its discrete "
                                 f"states cannot be set ({said or 'refused'}) and it provides no "
                                 "derivatives of its step") from None
    base_state = comp.serialize_state()
    nz = len(z_names)

    def evaluate(v):
        comp.restore_state(base_state)
        comp.set_reals(dict(zip(z_names, v[:nz])) | dict(zip(in_names, v[nz:])), restore=base_state)
        y = np.fromiter(comp.get_reals(out_names).values(), float, len(out_names))
        comp.do_step(t, period)
        return np.concatenate([np.fromiter(comp.get_reals(z_names).values(), float, nz), y])

    base = np.concatenate([z, u])
    scales = np.array([_scale(variables[n], b) for n, b in zip(z_names + in_names, base)])
    y0 = dict(zip(out_names, map(float, evaluate(base)[nz:])))
    J, error = _central(evaluate, base, scales)
    A, B = J[:nz, :nz], J[:nz, nz:]
    C, D = J[nz:, :nz], J[nz:, nz:]
    point = dict(zip(z_names, z)) | dict(zip(in_names, u)) | parameters
    system = _system(A, B, C, D, z_names, in_names, out_names, dt=period)
    return Linearization(system, "central differences", error, _units(z_names + in_names + out_names, variables),
                         point, y0)


# ---- files ---------------------------------------------------------------------------------------

def operating_point_of_run(scenario, instance: str, t: float, label: str | None = None) -> tuple[Path, dict[str, Any]]:
    """Fly ``scenario`` (a :class:`cosim.scenario.definition.Scenario`) to ``t`` (s), a
    communication point of its run, and return the FMU file of its instance
    ``instance`` with the operating point there: its FMU state, inputs and
    parameters (a snapshot, :class:`cosim.loop.master.Snapshot`), as keyword
    arguments of :func:`linearize_fmu`. A ``ScenarioError`` names a time that
    is no communication point, an instance the scenario lacks, or a run that
    failed before ``t``; ``label`` says how ``t`` was given (default ``t = ... s``)."""
    from ..errors import ScenarioError
    from ..scenario.assembly import build_master
    from ..time_grid import communication_point

    t0, h = scenario.start_time, scenario.step
    label = label or f"t = {t!r} s"
    n = communication_point(t, t0, h, scenario.n_steps)
    if n is None:
        raise ScenarioError(f"{label}: expected a communication point of {scenario.name} in "
                            f"[{t0:g}, {t0 + scenario.duration:g}] s (a whole number of steps of {h:g} s)")
    with build_master(scenario) as master:
        names = [f.name for f in master.fmus]
        if instance not in names:
            raise ScenarioError(f"linearize {instance!r}: no FMU instance of that name in {scenario.name} "
                                f"(its FMUs: {', '.join(names)})")
        result = master.run(max(n, 1) * h, seed=scenario.seed, t0=t0, snapshots=[t0 + n * h], raise_on_error=False)
        path = Path(master.components[instance].path)
    if not result.snapshots:
        raise ScenarioError(f"{label}: the run of {scenario.name} {result.status} before it: {result.error}")
    snap = result.snapshots[0]
    return path, dict(inputs=snap.inputs_of(instance), parameters=snap.parameters[instance],
                      fmu_state=snap.states[instance], t=snap.time)


def save_linearization(lin: Linearization, out_dir: str | Path, bode: Sequence[tuple[str, str]] = (),
                       stem: str = "linearization") -> list[Path]:
    """Write ``lin`` into ``out_dir``: ``<stem>.npz`` (A, B, C, D, dt and the
    names), ``<stem>.json`` (the same, readable, with units, method, error
    estimate, operating point and poles) and one Bode plot
    ``<stem>_bode_<input>_<output>.png`` per ``(input, output)`` pair of
    ``bode``. Returns the paths written. Unknown names in ``bode`` are a
    :class:`LinearizationError` raised before anything is written."""
    import json

    sys_ = lin.system
    states, ins, outs = list(sys_.state_labels), list(sys_.input_labels), list(sys_.output_labels)
    for i, o in bode:
        if i not in ins:
            raise LinearizationError(f"bode pair {i}:{o}: {i!r} is not an input of the system "
                                     f"(inputs: {', '.join(ins) or 'none'})")
        if o not in outs:
            raise LinearizationError(f"bode pair {i}:{o}: {o!r} is not an output of the system "
                                     f"(outputs: {', '.join(outs) or 'none'})")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    dt = float(sys_.dt) if sys_.dt else 0.0
    poles = lin.poles
    written = [out_dir / f"{stem}.npz", out_dir / f"{stem}.json"]
    np.savez(written[0], A=lin.A, B=lin.B, C=lin.C, D=lin.D, dt=dt, states=np.array(states, dtype=str),
             inputs=np.array(ins, dtype=str), outputs=np.array(outs, dtype=str))
    document = {
        "time": "discrete" if dt else "continuous", "dt": dt, "method": lin.method,
        "error_estimate": lin.error_estimate,
        "states": [{"name": n, "unit": lin.units.get(n, "")} for n in states],
        "inputs": [{"name": n, "unit": lin.units.get(n, "")} for n in ins],
        "outputs": [{"name": n, "unit": lin.units.get(n, "")} for n in outs],
        "operating_point": {k: float(v) for k, v in lin.operating_point.items()},
        "A": lin.A.tolist(), "B": lin.B.tolist(), "C": lin.C.tolist(), "D": lin.D.tolist(),
        "poles": [{"re": float(p.real), "im": float(p.imag)} for p in poles],
        "stable": bool(np.all(np.abs(poles) < 1.0) if dt else np.all(poles.real < 0.0)),
    }
    written[1].write_text(json.dumps(document, indent=1) + "\n")
    if bode:
        import control
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        for i, o in bode:
            siso = sys_[outs.index(o), ins.index(i)]
            fig = plt.figure(figsize=(7, 6), dpi=90)  # the file's dpi: the layout's text extents are the file's
            # the title over the figure's middle: over the axes python-control centres it by a layout pass more
            control.bode_plot(siso, dB=True, title=f"{i} -> {o} ({lin.units.get(i, '')} -> {lin.units.get(o, '')})",
                              title_frame="figure")
            path = out_dir / f"{stem}_bode_{i}_{o}.png".replace("(", "_").replace(")", "_")
            fig.tight_layout()  # laid out once, then drawn once: python-control's layout engine would lay it
            fig.set_layout_engine(None)  # out again in a draw of its own before the file's (docs/stability.md)
            fig.savefig(path, dpi=90)
            plt.close("all")
            written.append(path)
    return written
