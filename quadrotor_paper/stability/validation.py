"""The linear model checked against the nonlinear co-simulation.

The nonlinear side is the real thing: the plant FMU (FMI 2.0 co-simulation,
``fmu_models.export.build.cached_fmu``) and the controller, run by the
co-simulation master (:class:`cosim.loop.master.Master`, h = 0.01 s). The linear
side is :class:`~quadrotor_paper.stability.loops.LoopModel` in discrete time at the same
step, simulated by ``control.forced_response``. Both start at the operating
point and see the same reference from t = 0, so their samples at t_n can be
compared one to one.

* :func:`position_step` -- the PD + velocity controller + plant after a step
  of the position reference (master with :class:`~quadrotor_paper.controller_component.ControllerComponent`);
* :func:`velocity_step` -- the inner loop alone after a step of the desired
  velocity (master with :class:`VelocityCommandComponent`, which runs
  the step's inner loop, ``bound_inner_function`` -- the law inside the full controller);
* :func:`ramp_lag` -- the PD's steady lag behind a ramp (master with a
  :class:`Ramp` reference);
* :func:`growth_rate` -- how fast an oscillation grows or decays, to compare a
  gain pair's nonlinear run with its dominant closed-loop pole.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Mapping

import numpy as np

from fmu_models.models.quadrotor import QUADROTOR
from fnn_controller import FastFunction, GeometricParams
from fnn_controller.parametric import INNER_Y, bound_inner_function
from fnn_controller.geometric import initial_velocity_state

from cosim.component import Port, PythonComponent
from ..components import CONTROLLER_INSTANCE
from ..controller_component import DEFAULT_PLANT, ControllerComponent
from cosim.fmi.fmu import FmuComponent
from cosim.loop.master import Master
from ..trajectories import Hover, ReferenceComponent
from .loops import LoopModel
from .operating_points import STATE_NAMES, OperatingPoint

__all__ = [
    "Response", "Ramp", "VelocityCommandComponent", "plant_fmu_path", "position_step", "velocity_step",
    "linear_position_step", "linear_velocity_step", "ramp_lag", "growth_rate", "pd_mission_rmse",
    "StepCheck", "GainCheck", "check_step", "check_gains", "ENVELOPE",
]

_STATE_GROUP = "{" + ",".join(STATE_NAMES) + "}"
# flipping over or falling out of the sky ends a run as "diverged"
ENVELOPE = {f"{DEFAULT_PLANT}.phi": (-1.2, 1.2), f"{DEFAULT_PLANT}.theta": (-1.2, 1.2), f"{DEFAULT_PLANT}.z": (-100.0, 0.0)}


@dataclass(frozen=True, eq=False)
class Response:
    """A time response: ``t`` (n,), plant states ``x`` (n, 12) as deviations
    from the operating point (position relative to the start), and the run's
    status (``ok``, ``diverged`` or ``failed``, with the master's message)."""

    t: np.ndarray
    x: np.ndarray
    status: str = "ok"
    error: str | None = None

    def signal(self, name: str) -> np.ndarray:
        return self.x[:, STATE_NAMES.index(name)]


@dataclass(frozen=True)
class Ramp:
    """A trajectory (the contract of ``quadrotor_paper.trajectories``): hold ``start``,
    then from ``t_start`` move along +x at ``speed`` (m/s)."""

    speed: float = 2.5  # m/s
    t_start: float = 0.0  # s
    x0: float = 0.0  # m
    y0: float = 0.0  # m
    z0: float = -15.0  # m (NED)

    def reference(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        moving = np.clip(t - self.t_start, 0.0, None)
        p = np.column_stack([self.x0 + self.speed * moving, np.full_like(t, self.y0), np.full_like(t, self.z0)])
        v = np.column_stack([np.where(t >= self.t_start, self.speed, 0.0), np.zeros_like(t), np.zeros_like(t)])
        return p, v

    def acceleration(self, t):
        """d²p*/dt² = 0 (m/s²): constant speed; the step at ``t_start`` is no sample."""
        return np.zeros((np.atleast_1d(np.asarray(t, dtype=float)).size, 3))


class VelocityCommandComponent(PythonComponent):
    """The geometric velocity controller alone, at a constant desired
    velocity: plant state in, rotor speeds out (eqs. 13-18, evaluated by
    the inner loop the step runs, ``bound_inner_function``, through its fast
    buffer path)."""

    inputs = tuple(Port(v.name, v.unit, description="plant state")
                   for v in (QUADROTOR.variable(name) for name in STATE_NAMES))
    outputs = tuple(Port(f"Omega_{i}", "rad/s", description=f"rotor {i} speed command") for i in range(1, 5))

    def __init__(self, v_ref=(0.0, 0.0, 0.0), geometric: GeometricParams = GeometricParams(),
                 psi_ref: float = 0.0, name: str = "velocity"):
        super().__init__(name)
        self.v_ref = np.asarray(v_ref, float)
        self.psi_ref = float(psi_ref)
        self._f = FastFunction(bound_inner_function(geometric), state=("state", "state_next"))

    def start(self, t0: float, h: float, n_steps: int, seed: int) -> None:
        self._f.state[:] = initial_velocity_state()
        self._f.inputs["v_ref"][:] = self.v_ref
        self._f.inputs["psi_ref"][0] = self.psi_ref
        self._f.inputs["a_ref"][:] = 0.0

    def step(self, n: int, t: float, u: np.ndarray) -> np.ndarray:
        self._f.inputs["x"][:] = u[3:12]  # u v w phi theta psi p q r
        self._f.evaluate()
        self._f.commit()
        return self._f.outputs["y"][INNER_Y["Omega"]]


def plant_fmu_path(fmi_version: int = 2) -> Path:
    """The quadrotor FMU (built on demand, content-addressed cache)."""
    from fmu_models.export.build import cached_fmu

    return cached_fmu(QUADROTOR, fmi_version)


def _start_parameters(op: OperatingPoint) -> dict[str, float]:
    params = {f"{n}_0": float(v) for n, v in zip(STATE_NAMES, op.x)}
    params.update({f"wind_{a}": float(w) for a, w in zip("xyz", op.wind)})
    params.update({k: float(v) for k, v in op.plant_parameters.items()})
    return params


def _run(op: OperatingPoint, python: list[PythonComponent], controller: str, duration: float, dt: float,
         fmu: Path | None) -> Response:
    connections = [f"{DEFAULT_PLANT}.{_STATE_GROUP} -> {controller}.{_STATE_GROUP}",
                   f"{controller}.Omega_{{1,2,3,4}} -> {DEFAULT_PLANT}.Omega_{{1,2,3,4}}"]
    if any(c.name == "reference" for c in python):
        connections.append("reference.{x,y,z,vx,vy,vz} -> controller.{x_ref,y_ref,z_ref,vx_ref,vy_ref,vz_ref}")
    plant = FmuComponent(DEFAULT_PLANT, fmu or plant_fmu_path())
    record = [f"{DEFAULT_PLANT}.{n}" for n in STATE_NAMES]
    with Master([plant], python, connections, dt, record, ENVELOPE,
                {DEFAULT_PLANT: _start_parameters(op)}) as master:
        result = master.run(duration, raise_on_error=False)
    return Response(result.time, result.data[:, 1:] - op.x, result.status, result.error)


def position_step(op: OperatingPoint, step=(0.1, 0.0, 0.0), duration: float = 5.0, dt: float = 0.01,
                  kp: float | None = None, kd: float | None = None, fmu: Path | None = None) -> Response:
    """Nonlinear co-simulation from the hover point ``op`` (at rest) after a
    step of the position reference by ``step`` (m): plant FMU + PD (the
    controller component, its one step function ``parametric_step_function("pd")``)
    run by the master."""
    if op.speed != 0.0:
        raise ValueError(f"position_step starts from rest; {op.name} flies at {op.speed:g} m/s")
    position = replace(op.position, kp=op.position.kp if kp is None else kp,
                       kd=op.position.kd if kd is None else kd, dt=dt)
    p = op.x[0:3] + np.asarray(step, float)
    python = [ReferenceComponent(Hover(*p)),
              ControllerComponent("pd", asdict(position), asdict(replace(op.geometric, dt=dt)), op.psi_ref)]
    return _run(op, python, CONTROLLER_INSTANCE, duration, dt, fmu)


def velocity_step(op: OperatingPoint, step=(0.1, 0.0, 0.0), duration: float = 3.0, dt: float = 0.01,
                  fmu: Path | None = None) -> Response:
    """Nonlinear co-simulation of the inner loop alone from ``op`` after a
    step of the desired velocity from v*(op) to v*(op) + ``step`` (m/s)."""
    component = VelocityCommandComponent(op.v_ref + np.asarray(step, float), op.geometric, op.psi_ref)
    return _run(op, [component], "velocity", duration, dt, fmu)


def _linear(sys: ct.StateSpace, t: np.ndarray, u: np.ndarray) -> np.ndarray:
    import control as ct
    return ct.forced_response(sys, t, u).outputs[:12].T


def linear_position_step(op: OperatingPoint, step=(0.1, 0.0, 0.0), duration: float = 5.0,
                         dt: float | None = 0.01, kp: float | None = None, kd: float | None = None) -> Response:
    """The same step as :func:`position_step` on the linear loop at ``op``."""
    sys = LoopModel(op, dt, kp=kp, kd=kd).closed_loop()
    t = np.arange(int(round(duration / (dt or 0.01))) + 1) * (dt or 0.01)
    u = np.zeros((sys.ninputs, t.size))
    u[0:3] = np.asarray(step, float)[:, None]
    return Response(t, _linear(sys, t, u))


def linear_velocity_step(op: OperatingPoint, step=(0.1, 0.0, 0.0), duration: float = 3.0,
                         dt: float | None = 0.01) -> Response:
    """The same step as :func:`velocity_step` on the linear inner loop at ``op``."""
    sys = LoopModel(op, dt).inner_loop()
    t = np.arange(int(round(duration / (dt or 0.01))) + 1) * (dt or 0.01)
    u = np.zeros((sys.ninputs, t.size))
    u[0:3] = np.asarray(step, float)[:, None]
    return Response(t, _linear(sys, t, u))


def ramp_lag(op: OperatingPoint, speed: float = 2.5, duration: float = 15.0, dt: float = 0.01,
             fmu: Path | None = None) -> tuple[float, Response]:
    """The PD's lag behind a ramp along +x at ``speed`` from hover, in the
    nonlinear co-simulation: ``x*(t_end) - x(t_end)`` (m) and the run."""
    p = op.x[0:3]
    python = [ReferenceComponent(Ramp(speed, 0.0, *p)),
              ControllerComponent("pd", asdict(replace(op.position, dt=dt)), asdict(replace(op.geometric, dt=dt)),
                                  op.psi_ref)]
    run = _run(op, python, CONTROLLER_INSTANCE, duration, dt, fmu)
    return float(speed * run.t[-1] - run.x[-1, 0]), run


def growth_rate(t: np.ndarray, y: np.ndarray, t_min: float = 0.0) -> float:
    """Exponential growth rate (1/s) of an oscillation: the slope of a
    least-squares line through log |y| at its local maxima after ``t_min``
    (positive: growing, negative: decaying; nan with fewer than 3 peaks)."""
    a = np.abs(np.asarray(y, float))
    inner = (a[1:-1] > a[:-2]) & (a[1:-1] >= a[2:]) & (t[1:-1] >= t_min) & (a[1:-1] > 0)
    idx = np.flatnonzero(inner) + 1
    if idx.size < 3:
        return math.nan
    return float(np.polyfit(t[idx], np.log(a[idx]), 1)[0])


def pd_mission_rmse(wind_speeds=(0.0, 1.0, 3.0, 5.0), scenario: str = "circles",
                    plant: Mapping[str, float] | None = None) -> dict[float, float]:
    """Euclidean RMSE (m) of the PD alone on the paper's mission (the shipped
    ``circles`` scenario, §5.2) for each gust speed (m/s) -- Table 2's PD row,
    a study (the case ``pd``, the wind speeds its grid) measured by
    :func:`quadrotor_paper.experiments.study_metrics`; ``plant``: the plant's
    parameters set on every run (the controller's nominal vehicle follows)."""
    from cosim.study.definition import parse_study

    from ..experiments import measure

    study = parse_study({"scenario": scenario, "name": "pd_mission_rmse", "cases": {"pd": {}},
                         "set": {f"fmus.{DEFAULT_PLANT}.parameters.{k}": float(v) for k, v in (plant or {}).items()},
                         "sweep": {"grid": {"wind.speed": [float(w) for w in wind_speeds]}}})
    return {row["wind.speed"]: row["rmse_m"] for row in measure(study).rows}


# ---- checks (what the tests and the report state) --------------------------------------

@dataclass(frozen=True, eq=False)
class StepCheck:
    """A step from ``op`` in the linear model and in the co-simulation.

    ``kind`` is ``"position"`` (reference step of ``size`` m on ``axis``; the
    positions are compared) or ``"velocity"`` (desired-velocity step of
    ``size`` m/s; the velocities are compared). ``max_error`` is the largest
    |linear - nonlinear| over the run and the three axes of the compared
    quantity, ``relative`` that divided by the step size.
    """

    kind: str
    axis: str
    size: float
    max_error: float
    linear: Response
    nonlinear: Response

    @property
    def relative(self) -> float:
        return self.max_error / abs(self.size)


def check_step(op: OperatingPoint, kind: str = "position", axis: str = "x", size: float = 0.02,
               duration: float | None = None, fmu: Path | None = None) -> StepCheck:
    """Run a step in both models and compare (see :class:`StepCheck`)."""
    step = np.zeros(3)
    step["xyz".index(axis)] = size
    if kind == "position":
        duration = duration or 5.0
        lin, nl, cols = linear_position_step(op, step, duration), position_step(op, step, duration, fmu=fmu), slice(0, 3)
    elif kind == "velocity":
        duration = duration or 3.0
        lin, nl, cols = linear_velocity_step(op, step, duration), velocity_step(op, step, duration, fmu=fmu), slice(3, 6)
    else:
        raise ValueError(f"kind = {kind!r}: expected 'position' or 'velocity'")
    if nl.status != "ok":
        raise RuntimeError(f"the co-simulation of the {kind} step failed: {nl.error}")
    return StepCheck(kind, axis, size, float(np.abs(lin.x[:, cols] - nl.x[:, cols]).max()), lin, nl)


@dataclass(frozen=True, eq=False)
class GainCheck:
    """A gain pair: the linear verdict and what the co-simulation does after
    a small position step (``size`` m on x) from hover.

    ``pole_growth`` (1/s) and ``pole_frequency`` (rad/s) are those of the
    dominant closed-loop pole (``log(z)/h``); ``linear_growth`` and
    ``nonlinear_growth`` the growth rates of the x oscillation fitted on each
    model's response (:func:`growth_rate`, after ``t_min``).
    """

    kp: float
    kd: float
    linear_stable: bool
    pole_growth: float
    pole_frequency: float
    linear_growth: float
    nonlinear_growth: float
    nonlinear_status: str
    size: float
    linear: Response
    nonlinear: Response

    @property
    def amplification(self) -> float:
        """max |x - x*| over the last second / the initial error."""
        late = self.nonlinear.t >= self.nonlinear.t[-1] - 1.0
        return float(np.abs(self.nonlinear.x[late, 0] - self.size).max() / self.size)


def check_gains(op: OperatingPoint, kp: float, kd: float, size: float = 0.01, duration: float = 8.0,
                dt: float = 0.01, t_min: float = 1.0, fmu: Path | None = None) -> GainCheck:
    """Linear stability of (kp, kd) at ``op`` and the co-simulation's growth."""
    from .analysis import closed_loop_poles

    poles = closed_loop_poles(LoopModel(op, dt, kp=kp, kd=kd).closed_loop())
    z = poles.poles[np.argmax(np.abs(poles.poles))]
    step = (size, 0.0, 0.0)
    lin = linear_position_step(op, step, duration, dt, kp=kp, kd=kd)
    nl = position_step(op, step, duration, dt, kp=kp, kd=kd, fmu=fmu)
    return GainCheck(kp, kd, poles.stable, float(np.log(abs(z)) / dt), float(abs(np.angle(z)) / dt),
                     growth_rate(lin.t, lin.x[:, 0] - size, t_min), growth_rate(nl.t, nl.x[:, 0] - size, t_min),
                     nl.status, size, lin, nl)

