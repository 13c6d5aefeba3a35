"""The learning loop's local stability along a flight (docs/stability.md,
"Along the flight").

Every ``every`` seconds of a mission the run is frozen (the master's
snapshots: every FMU's state, :class:`cosim.loop.master.Snapshot`) and the
closed loop is linearized there from the FMUs themselves
(:func:`~.fmu_loop.snapshot_loop`: the plant held over the controller's
period, the controller's one-period map with its learned FNN state as part
of its discrete state). Two readings of the same linearization:

* **learning on**: the whole loop, the learning law's step linearized with
  the rest. Under the paper's sign law (phi = 0) the step is not
  differentiable where a sliding variable tau_c crosses 0; elsewhere
  sgn(tau_c) is locally constant, so this is the loop with the *sign
  frozen*. The controller's error estimate (relative, :attr:`FlightPoint.error`)
  says where the differences straddled a switch and the reading has no
  meaning. With the boundary layer (phi > 0) the law is smooth inside the
  layer and the reading is its linearization.
* **learning held**: the learned FNN state held at its value (removed from
  the loop's state): the flight modes of the PD + FNN controller as learned
  at that moment, defined whatever the law.

The spectral radius (largest |eigenvalue|, inert states left out) < 1 is
local stability of the sampled loop at that moment; the loop's operating
point moves along the flight, so this is a frozen-time reading, checked
against the nonlinear loop by a **perturbation check**: from the frozen
state the co-simulation is resumed for ``check`` s twice (the plant started
at its state then, plus ``delta`` for the second), and the growth of the
plant-state difference is compared with the linear loop's prediction
``C A^n (delta, 0)``, both as a rate ln(gain)/check (1/s). A second check
perturbs along the loop's least stable mode (its eigenvector, learned state
included, set in the controller's FMU state:
:meth:`cosim.fmi.fmu.FmuComponent.state_with`). Every FMU state is
read, edited and linearized on the master's own live instances (each left
in its state): the only instance made per frozen point is the plant's Model
Exchange instance the linearizer evaluates.
and compares the growth of the whole state's difference with ``A^n``'s.

The study is one :mod:`cosim.study.definition` per mission (cases: variant x law), run
by :func:`~quadrotor_paper.experiments.measure`, so on Dask like every
multi-run command; the metric, :class:`AlongFlight`, asks the runner for
the snapshots.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from cosim.scenario.definition import Scenario
from cosim.scenario.assembly import build_master
from fnn_controller.variants import variant_names

from ..controller_component import controller_settings
from .fmu_loop import FmuLoop, snapshot_loop
from .operating_points import STATE_NAMES

__all__ = ["FlightPoint", "AlongFlightRun", "AlongFlight", "along_flight", "along_flight_study", "along_flight_plan",
           "AlongFlightPlan", "flight_events", "verdict", "write_points", "learned_state_names", "VARIANTS",
           "BOUNDARY_LAYER", "MISSIONS", "DELTA", "NEUTRAL_RATE", "SECONDS_PER_POINT"]

VARIANTS = variant_names()  # every registered variant, in the registry's order
MISSIONS = ("circles", "figure8")
# m/s: the layer docs/results.md found to remove the z limit cycle (docs/stability.md)
BOUNDARY_LAYER = 0.2
# the perturbation of the plant state (SI): a gust-sized velocity kick and a small roll
DELTA = {"u": 0.05, "phi": 0.02}
# the size of the perturbation along the least stable mode (its state's units): small enough
# to stay linear after a growth of e^4 over the 1 s check
MODE_SIZE = 1e-4
# s of one worker per frozen point, its perturbation checks and its share of the flight included:
# the whole study (972 points, 1 s checks) took about 3 min on 2 workers of an idle 2-core
# machine at 0.37 s (docs/stability.md, "What the command costs"); the controller's map then set
# its values in one call each, which took a point's CPU from 0.638 to 0.401 s (circles, every
# variant and law, every 5 s, one process, the same loaded machine): 0.37 x 0.401/0.638. The
# estimate printed before the study.
SECONDS_PER_POINT = 0.23


@dataclass(frozen=True)
class FlightPoint:
    """One frozen moment ``time`` (s): ``radius`` (learning on), ``radius_held``
    (learned state held), ``error`` (the controller map's error estimate
    relative to its largest entry), ``tau_c_min`` (m/s, the smallest
    |tau_c| of the three axes: how near a switch of the sign law),
    ``linear_rate`` and ``nonlinear_rate`` (1/s, the perturbation check of
    the plant state; NaN where it was not made); ``mode_linear_rate`` and
    ``mode_nonlinear_rate`` (1/s, the same along the loop's least stable
    mode, learned state included; the co-simulated rate is the larger of the
    two directions along it)."""

    time: float
    radius: float
    radius_held: float
    error: float
    tau_c_min: float
    linear_rate: float = math.nan
    nonlinear_rate: float = math.nan
    mode_linear_rate: float = math.nan
    mode_nonlinear_rate: float = math.nan


@dataclass(frozen=True)
class AlongFlightRun:
    """The points of one run (mission, variant, boundary layer ``phi`` in m/s;
    0 is the paper's sign law), its status and error."""

    mission: str
    variant: str
    phi: float
    status: str
    error: str | None
    points: tuple[FlightPoint, ...] = field(default_factory=tuple)

    def column(self, name: str) -> np.ndarray:
        return np.array([getattr(p, name) for p in self.points], dtype=float)

    @property
    def law(self) -> str:
        return "sign law" if self.phi == 0 else f"boundary layer {self.phi:g} m/s"


def learned_state_names(variant: str) -> list[str]:
    """The controller FMU's locals that are the learned FNN state of ``variant``
    (every axis; the velocity controller's memory is not learned)."""
    from fnn_controller.position import fnn_state_size
    from fnn_controller.step import state_ports
    from fnn_controller.variants import variant as lookup

    v = lookup(variant)
    return [name for name, _, _ in state_ports(v)[:fnn_state_size(v)]]


def _relative_error(loop: FmuLoop) -> float:
    lin = loop.controller
    scale = max(np.max(np.abs(m)) if m.size else 0.0 for m in (lin.A, lin.B, lin.C, lin.D))
    return float(lin.error_estimate / scale) if scale > 0 else float(lin.error_estimate)


@dataclass(frozen=True)
class AlongFlight:
    """A study metric (module level, picklable: it may run on a Dask
    worker): :class:`AlongFlightRun` of the run, ``{"along_flight": ...}``.
    Frozen every ``every`` s from ``every`` to the end less ``check``; the
    perturbation check (``check`` s, ``delta``) at every point when
    ``check`` > 0."""

    every: float = 1.0
    check: float = 1.0
    delta: tuple[tuple[str, float], ...] = tuple(DELTA.items())

    def snapshot_times(self, scenario: Scenario) -> list[float]:
        h = scenario.step
        last = scenario.start_time + scenario.duration - max(self.check, 0.0)
        k = int(round(self.every / h))
        if k < 1 or abs(k * h - self.every) > 1e-9 * self.every:
            raise ValueError(f"along the flight every {self.every!r} s: not a whole number of steps of {h!r} s")
        n_last = int(math.floor((last - scenario.start_time) / h + 1e-9))
        return [scenario.start_time + n * h for n in range(k, n_last + 1, k)]

    def __call__(self, scenario: Scenario, result) -> dict[str, Any]:
        settings = controller_settings(scenario)
        if settings is None or not settings.plant:
            raise ValueError(f"scenario {scenario.name!r}: along the flight needs a controller and the plant FMU it "
                             "flies (its 'plant')")
        variant, phi = settings.variant, float(settings.position.phi[0])
        plant, controller = settings.plant, settings.instance
        held = learned_state_names(variant)
        points = []
        master = build_master(scenario)
        try:
            fmus = {f.name: f for f in master.fmus}
            for snap in result.snapshots:
                loop = snapshot_loop(snap, fmus[plant].path, fmus[controller].path, plant, controller,
                                     instances=fmus)
                tau_c = [abs(loop.controller.outputs[f"tau_c_{a}"]) for a in "xyz"]
                rates = self._check(master, snap, loop, result.seed, fmus, plant, controller) if self.check > 0 else (math.nan,) * 4
                points.append(FlightPoint(snap.time, loop.spectral_radius,
                                          float(np.max(np.abs(loop.poles_holding(held)))),
                                          _relative_error(loop), float(min(tau_c)), *rates))
        finally:
            master.close()
        return {"along_flight": AlongFlightRun(scenario.name, variant, phi, result.status, result.error, tuple(points))}

    def _check(self, master, snap, loop: FmuLoop, seed: int, fmus, plant: str,
               controller: str) -> tuple[float, float, float, float]:
        """(linear, nonlinear) rates over ``check`` s of the perturbation
        ``delta`` of the ``plant``'s state, then of a perturbation along the
        least stable mode; FMU states read and edited on the master's instances
        ``fmus`` (name -> :class:`~cosim.fmi.fmu.FmuComponent`)."""
        h = master.step
        n = int(round(self.check / h))
        start = {k: v for k, v in loop.plant.operating_point.items() if k in loop.plant.system.state_labels}
        labels = list(loop.system.state_labels)
        active = loop.active
        names = [labels[i] for i in active]
        ctrl_names = [k[len("controller_"):] for k in names if k.startswith("controller_")]
        plant_names = [k[len("plant_"):] for k in names if k.startswith("plant_")]

        def resume(plant_kick: dict[str, float], controller_state: bytes) -> dict[str, float]:
            """Every active state's value after ``check`` s of co-simulation from the snapshot."""
            values = {f"{plant}.{k}_0": v + plant_kick.get(k, 0.0) for k, v in start.items()}
            restore = {k: v for k, v in snap.states.items() if k != plant} | {controller: controller_state}
            end = snap.time + n * h
            run = master.run(n * h, seed=seed, t0=snap.time, parameters=values, restore=restore, snapshots=[end],
                             raise_on_error=False)
            if run.status != "ok" or not run.snapshots:
                return dict.fromkeys(names, math.nan)
            last = run.snapshots[-1]
            out = {f"plant_{k}": v for k, v in fmus[plant].state_values(last.states[plant], plant_names,
                                                                          end).items()}
            return out | {f"controller_{k}": v for k, v in fmus[controller].state_values(
                last.states[controller], ctrl_names, end).items()}

        def gap(a: dict[str, float], b: dict[str, float], keys) -> float:
            return float(np.linalg.norm([a[k] - b[k] for k in keys]))

        nominal = resume({}, snap.states[controller])
        # the plant's state kicked
        delta = dict(self.delta)
        size = float(np.linalg.norm(list(delta.values())))
        linear = np.linalg.norm(loop.propagate(delta, n)) / size
        kicked = resume(delta, snap.states[controller])
        plant12 = [f"plant_{s}" for s in STATE_NAMES]
        rates = [_rate(linear, self.check), _rate(gap(kicked, nominal, plant12) / size, self.check)]
        # along the least stable mode (its eigenvector's real part), learned state included
        A = np.asarray(loop.system.A)[np.ix_(active, active)]
        w, V = np.linalg.eig(A)
        v = np.real(V[:, int(np.argmax(np.abs(w)))])
        v = MODE_SIZE * v / np.linalg.norm(v)
        mode = dict(zip(names, v))
        now = fmus[controller].state_values(snap.states[controller], ctrl_names, snap.time)
        grown = []
        for sign in (1.0, -1.0):  # both ways along the mode: a bound (a width's floor) may stop one side only
            ctrl_state = fmus[controller].state_with(snap.states[controller],
                                                      {k: now[k] + sign * mode[f"controller_{k}"] for k in ctrl_names},
                                                      snap.time)
            moved = resume({k: sign * mode[f"plant_{k}"] for k in plant_names}, ctrl_state)
            grown.append(gap(moved, nominal, names) / MODE_SIZE)
        linear_mode = np.linalg.norm(np.linalg.matrix_power(A, n) @ v) / MODE_SIZE
        rates += [_rate(linear_mode, self.check), _rate(max(grown), self.check)]
        return tuple(rates)


def _rate(gain: float, duration: float) -> float:
    """ln(gain)/duration (1/s); -inf for a perturbation erased to the last bit
    (both runs clipped to the same bound), NaN for a run that failed."""
    if not gain > 0:
        return -math.inf if gain == 0 else math.nan
    return math.log(gain) / duration


def along_flight(scenario: Scenario, metric: AlongFlight = AlongFlight()) -> AlongFlightRun:
    """One run of ``scenario`` frozen along its flight, in this process."""
    master = build_master(scenario)
    try:
        result = master.run(scenario.duration, seed=scenario.seed, t0=scenario.start_time, raise_on_error=False,
                            snapshots=metric.snapshot_times(scenario))
    finally:
        master.close()
    return metric(scenario, result)["along_flight"]


def _cases(variants: Sequence[str], phis: Sequence[float],
           overrides: dict[str, Any] | None) -> dict[str, dict[str, Any]]:
    """The cases of one mission's study: variant x law, the ``overrides`` set in each."""
    from fnn_controller.variants import variant as lookup

    # a variant that learns nothing (the PD) does not depend on the boundary layer
    return {f"{v} / phi {phi:g}": {"set": {**dict(overrides or {}), "controller.variant": v,
                                          "controller.position.phi": [float(phi)] * 3}}
            for v in variants for phi in (phis if lookup(v).learns else phis[:1])}


@dataclass(frozen=True)
class AlongFlightPlan:
    """What :func:`along_flight_study` will do: ``runs`` flights, ``points``
    frozen moments, and an estimate of its wall time ``seconds`` on
    ``workers`` workers (:data:`SECONDS_PER_POINT`)."""

    runs: int
    points: int
    workers: int
    seconds: float

    def __str__(self) -> str:
        minutes = f"{self.seconds / 60:.1f} min" if self.seconds >= 90 else f"{self.seconds:.0f} s"
        return (f"along the flight: {self.runs} runs, {self.points} frozen points, about {minutes} on "
                f"{self.workers} worker{'s' if self.workers > 1 else ''} (estimate)")


def along_flight_plan(missions: Sequence[str] = MISSIONS, variants: Sequence[str] = VARIANTS,
                      phis: Sequence[float] = (0.0, BOUNDARY_LAYER), metric: AlongFlight = AlongFlight(),
                      workers: int = 1, overrides: dict[str, Any] | None = None) -> AlongFlightPlan:
    """The runs, frozen points and estimated time of :func:`along_flight_study`
    with the same arguments, counted from the scenarios before anything runs
    (the estimate: points x :data:`SECONDS_PER_POINT` / the workers that get a run)."""
    from cosim.scenario.definition import load_scenario

    runs = points = 0
    for mission in missions:
        cases = _cases(variants, phis, overrides)
        times = metric.snapshot_times(load_scenario(mission, overrides=overrides or None))
        runs += len(cases)
        points += len(cases) * len(times)
    busy = max(1, min(workers, runs))
    return AlongFlightPlan(runs, points, busy, points * SECONDS_PER_POINT / busy)


def along_flight_study(missions: Sequence[str] = MISSIONS, variants: Sequence[str] = VARIANTS,
                       phis: Sequence[float] = (0.0, BOUNDARY_LAYER), metric: AlongFlight = AlongFlight(),
                       workers: int = 1, overrides: dict[str, Any] | None = None,
                       progress: Callable[[int, int], None] | None = None) -> list[AlongFlightRun]:
    """Every mission x variant x law (``phis``, m/s; 0 the sign law), one study per
    mission run by :func:`~quadrotor_paper.experiments.measure`; ``overrides``
    (dotted keys) set for every run, e.g. a shorter ``simulation.duration``;
    ``progress(done, total)`` counts the runs of all missions together."""
    from cosim.study.definition import parse_study

    from ..experiments import measure

    out = []
    total = sum(len(_cases(variants, phis, overrides)) for _ in missions)
    done = 0
    for mission in missions:
        cases = _cases(variants, phis, overrides)
        study = parse_study({"scenario": mission, "name": f"along_flight_{mission}", "cases": cases})
        step = None if progress is None else (lambda n, _, before=done: progress(before + n, total))
        rows = measure(study, workers=workers, metrics=metric, metric_names=(), progress=step).rows
        done += len(cases)
        order = {name: i for i, name in enumerate(cases)}
        rows = sorted(rows, key=lambda r: order[r["case"]])
        for row in rows:
            if "along_flight" in row:
                out.append(row["along_flight"])
            else:  # the run or its metric failed: the row says why
                values = cases[row["case"]]["set"]
                out.append(AlongFlightRun(mission, values["controller.variant"], values["controller.position.phi"][0],
                                        row.get("status", "failed"), row.get("error")))
    return out


def flight_events(scenario: Scenario) -> list[tuple[float, str]]:
    """The moments to mark along ``scenario``'s flight (s, label): the gust's
    reversals and, for the two circles, the change of circle; for the
    figure-8, each crossing of its centre."""
    from ..components import TRAJECTORY_INSTANCE
    from ..trajectories import make_trajectory

    end = scenario.start_time + scenario.duration
    wind = scenario.sections.get("wind")  # the validated section and the gust FMU's parameters it set
    gust = scenario.fmus[wind["fmu"]]["parameters"] if wind else {}
    switches = [gust[k] for k in ("t_switch_1", "t_switch_2") if k in gust]
    events = [(float(t), "gust reverses") for t in switches if 0 < t < end]
    reference = scenario.components.get(TRAJECTORY_INSTANCE, {})
    kind, spec = reference.get("kind"), dict(reference.get("parameters", {}))
    if kind == "two_circles":
        events.append((make_trajectory(kind, **spec).path_time / 2, "second circle"))
    elif kind == "figure_eight":
        half = make_trajectory(kind, **spec).lap_time / 2
        events += [(k * half, "crossing") for k in range(1, int(end / half) + 1)]
    return sorted(events)


# 1/s: a mode growing at most this fast, ln|z| / dt, is neutral (a learning law's
# integrator: at most a factor e^0.5 = 1.65 over a 50 s mission), not an instability
NEUTRAL_RATE = 0.01


def _where(f: AlongFlightRun, values: np.ndarray, dt: float) -> str:
    i = int(np.argmax(values))
    rate = math.log(values[i]) / dt
    return f"max {values[i]:.4f} ({rate:+.3g} 1/s) at {f.points[i].time:g} s"


def _erased(rates: np.ndarray) -> str:
    n = int(np.sum(np.isneginf(rates)))
    return f"; erased (both runs at the same bound) at {n} points" if n else ""


def verdict(f: AlongFlightRun, dt: float = 0.01) -> dict[str, str]:
    """One line each for the learning held, the learning on and the
    perturbation check of a flight (the report's and docs/stability.md's
    words); ``dt`` the controller's period (s), for the growth rates ln|z|/dt."""
    if not f.points:
        return {"held": f"no point ({f.status}: {f.error})", "on": "–", "check": "–", "mode": "–"}
    n = len(f.points)
    held, on = f.column("radius_held"), f.column("radius")
    out = {}
    bad = int(np.sum(held >= 1.0))
    out["held"] = (f"stable at all {n} points ({_where(f, held, dt)})" if bad == 0 else
                   f"UNSTABLE at {bad} of {n} points ({_where(f, held, dt)})")
    grow = int(np.sum(np.log(on) / dt > NEUTRAL_RATE))
    if np.all(on < 1.0):
        out["on"] = f"stable at all {n} points ({_where(f, on, dt)})"
    elif grow == 0:
        out["on"] = (f"neutral: learning modes at abs(z) = 1 + {np.max(on) - 1:.1e} at most "
                     f"(growth <= {NEUTRAL_RATE:g} 1/s), the rest stable")
    else:
        out["on"] = f"UNSTABLE at {grow} of {n} points ({_where(f, on, dt)})"
    lin, nl = f.column("linear_rate"), f.column("nonlinear_rate")
    diff = np.abs(lin - nl)[np.isfinite(lin) & np.isfinite(nl)]
    out["check"] = (f"rates differ by median {np.median(diff):.3f} 1/s, max {np.max(diff):.3f} 1/s"
                    + _erased(nl) if diff.size else "not made")
    lin, nl = f.column("mode_linear_rate"), f.column("mode_nonlinear_rate")
    made = np.isfinite(lin) & ~np.isnan(nl)
    if made.any():
        lin, nl = lin[made], nl[made]
        grows = lin > NEUTRAL_RATE
        finite = np.isfinite(nl)
        out["mode"] = (f"rates differ by median {np.median(np.abs(lin - nl)[finite]):.3f} 1/s; predicted to grow at "
                       f"{int(grows.sum())} of {int(made.sum())} points, co-simulation grows at "
                       f"{int((grows & (nl > NEUTRAL_RATE)).sum())} of those" + _erased(nl))
    else:
        out["mode"] = "not made"
    return out


def write_points(flights: Sequence[AlongFlightRun], path) -> None:
    """Every point of every flight as CSV (one row per mission, variant, law, time)."""
    import csv

    names = [f.name for f in FlightPoint.__dataclass_fields__.values()]
    with open(path, "w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow(["mission", "variant", "phi_mps"] + names)
        for f in flights:
            for p in f.points:
                writer.writerow([f.mission, f.variant, f.phi] + [repr(getattr(p, n)) for n in names])
