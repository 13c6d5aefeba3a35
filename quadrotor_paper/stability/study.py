"""The whole stability study in one call: every analysis of the package at
the default operating points, checked against the co-simulation and, on
request (``along_flight=True``, ``fnn-cosim stability --along-flight``), the
learning laws: their finite-time claims on recorded runs (those come from
:mod:`quadrotor_paper.learning_claims`, outside this package) and the
learning loop along the flight (:mod:`.along_flight`).

>>> from quadrotor_paper.stability import run_stability_analysis
>>> study = run_stability_analysis("results/stability")   # doctest: +SKIP
>>> study.analyses[0].poles["discrete"].stable             # doctest: +SKIP
True

:func:`stability_study` computes (no files); :func:`run_stability_analysis`
also writes the markdown report and the PNG figures
(:mod:`quadrotor_paper.stability.report`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from fnn_controller import GeometricParams, PositionParams

from .analysis import (CircleError, FeedForwardCase, GainSweep, OperatingPointAnalysis, RampError, analyze,
                       circle_error, critical_gain_factor, feedforward_comparison, gain_sweep, ramp_error)
from ..learning_claims import AxisClaims, Recording, default_runs, evaluate_claims
from .operating_points import OperatingPoint, default_operating_points
from .validation import GainCheck, StepCheck, check_gains, check_step, pd_mission_rmse, ramp_lag

__all__ = ["StabilityStudy", "StabilitySettings", "stability_study", "run_stability_analysis", "check_pd_gains", "DT", "SWEEP_KP",
           "SWEEP_KD", "STEP_CHECKS"]

DT = 0.01  # s: the controller and communication step the study analyses (the paper's)

SWEEP_KP = np.linspace(0.05, 25.0, 126)  # 1/s
SWEEP_KD = np.linspace(-1.5, 8.0, 96)  # 1
# (kind, axis, size): small enough to keep the rotors away from saturation
# (about 0.9 N m of roll/pitch torque at hover: a 4 cm position step already
# asks for 3 degrees of tilt at once)
STEP_CHECKS = (("position", "x", 0.02), ("position", "y", 0.02), ("position", "z", 0.1),
               ("velocity", "x", 0.05), ("velocity", "y", 0.05), ("velocity", "z", 0.05))
GAIN_FACTORS = (0.85, 1.07, 1.3)  # gain pairs checked: these multiples of the critical factor


def check_pd_gains(kp: float, kd: float, dt: float = DT, geometric: GeometricParams = GeometricParams()) -> None:
    """Refuse PD gains (eq. 19) no sampled controller at step ``dt`` (s)
    realises, in one line naming the gain and its bound: no loop faster than
    the Nyquist frequency pi/dt (rad/s). The position loop's crossover is
    kp (1/s): kp <= pi/dt. The derivative term feeds the velocity error back
    through the velocity loop (eqs. 13-18), whose gain k_v becomes
    k_v (1 + kd): kd <= pi/(k_v dt) - 1. At the paper's 0.01 s and
    k_v = 5 1/s: kp <= 314 1/s, kd <= 61.8 (the gain sweep ends at 25 and
    8). Within them an unstable pair is an answer of the study; beyond, its
    numbers are no longer finite (kp = 1e308: no trim of the PD).

    Raises
    ------
    cosim.errors.ScenarioError
        ``kp = 1e+308: must be at most 314.2 1/s (...)``.
    """
    from cosim.errors import ScenarioError

    nyquist = math.pi / dt
    why = f"pi/dt, the Nyquist frequency of the controller's {dt:g} s step"
    if kp > nyquist:
        raise ScenarioError(f"kp = {kp!r}: must be at most {nyquist:.4g} 1/s ({why}: no faster position loop)")
    if geometric.k_v > 0 and kd > nyquist / geometric.k_v - 1.0:
        raise ScenarioError(f"kd = {kd!r}: must be at most {nyquist / geometric.k_v - 1.0:.4g} ({why}: the velocity "
                            f"loop's gain k_v (1 + kd), k_v = {geometric.k_v:g} 1/s, no faster)")


@dataclass(eq=False)
class StabilityStudy:
    """Everything :func:`stability_study` computed (see the module docstring)."""

    dt: float
    position: PositionParams
    operating_points: list[OperatingPoint]
    analyses: list[OperatingPointAnalysis]
    sweeps: list[GainSweep]
    critical_factors: dict[str, dict[str, float]]
    ramp: RampError
    circle: CircleError
    ramp_nonlinear: float | None = None
    feedforward_cases: list[FeedForwardCase] = field(default_factory=list)
    feedforward_ramp_nonlinear: dict[float, float] = field(default_factory=dict)  # gain -> co-simulated lag (m)
    mission_rmse: dict[float, float] | None = None
    step_checks: list[StepCheck] = field(default_factory=list)
    gain_checks: list[GainCheck] = field(default_factory=list)
    runs: list[Recording] = field(default_factory=list)
    finite_time: list[AxisClaims] = field(default_factory=list)
    along_flight: list = field(default_factory=list)  # AlongFlightRun, every mission x variant x law
    flight_events: dict[str, list[tuple[float, str]]] = field(default_factory=dict)  # mission -> (t, label)
    report_path: Path | None = None
    figures: dict[str, Path] = field(default_factory=dict)


@dataclass(frozen=True)
class StabilitySettings:
    """What the study analyses and how far it goes.

    speed : forward-flight speed (m/s) of the operating points and the ramp.
    wind_speed : steady wind (m/s) of the third operating point, along the
        paper's gust direction [-1, -1, 0].
    dt : controller and communication step (s) of the discrete loops.
    kp, kd : PD gains (default ``None``: the paper's 2.5, 0.005).
    geometric : the velocity controller's gains (its ``dt`` is ``dt``).
    feedforward : velocity feed-forward gain of the analysed PD (default 0,
        the paper's law; ``PositionParams.feedforward``).
    feedforward_gains : the gains compared side by side (poles, margins,
        ramp and circle error; with ``cosim`` the co-simulated ramp lag too).
    sweep_kp, sweep_kd : the grid of the gain sweep.
    cosim : also run the co-simulation checks of the PD (steps, gains, ramp,
        mission).
    plant : the plant's parameters other than its defaults (``fnn-cosim
        stability --set``: :func:`plant_parameters`), in the plant and in the
        controller's nominal vehicle alike, as a scenario ties them (an X's
        ``arm_angle`` makes the mixer an X); the operating points are
        trimmed on that plant, the co-simulation checks fly it.
    along_flight : with ``cosim``, also the learning laws (minutes, not
        seconds: docs/stability.md, "What the command costs"): the finite-time
        runs of :mod:`quadrotor_paper.learning_claims` and the learning loop
        along the missions (:mod:`.along_flight`, frozen every ``along_every``
        s; 0 skips it).
    """

    speed: float = 2.5
    wind_speed: float = 3.0
    dt: float = DT
    kp: float | None = None
    kd: float | None = None
    geometric: GeometricParams = GeometricParams()
    feedforward: float = 0.0
    feedforward_gains: tuple[float, ...] = (0.0, 1.0)
    sweep_kp: Any = field(default_factory=lambda: SWEEP_KP)
    sweep_kd: Any = field(default_factory=lambda: SWEEP_KD)
    cosim: bool = True
    along_flight: bool = False
    along_every: float = 1.0
    plant: Any = field(default_factory=dict)  # plant parameter -> value, over its defaults (plant_parameters)

    @property
    def vehicle(self):
        """The controller's nominal vehicle: the plant's (``plant``, else its defaults)."""
        from dataclasses import fields

        from fnn_controller import VehicleParams

        return VehicleParams(**{f.name: float(self.plant[f.name]) for f in fields(VehicleParams)
                                if f.name in self.plant})

    @property
    def position(self) -> PositionParams:
        """The analysed PD's parameters (eq. 19): the paper's, with these gains and step."""
        default = PositionParams()
        return replace(default, kp=default.kp if self.kp is None else self.kp,
                       kd=default.kd if self.kd is None else self.kd, dt=self.dt, feedforward=self.feedforward)


def plant_parameters(overrides: Mapping[str, Any]) -> dict[str, float]:
    """The plant's parameters that ``fnn-cosim stability --set`` gives, read as
    ``fnn-cosim run`` reads them: ``fmus.Quadrotor.parameters.<name>`` and
    ``fmus.Quadrotor.parameter_set`` (an SSP parameter set, e.g. a calibration's
    ``parameters.ssv``) applied to the ``circles`` scenario (names and ranges
    checked there, one line each), less the values the plant has anyway (the
    scenario's, the defaults) and the initial states (``<state>_0``: the
    operating points set the states). Any other key is refused in one line,
    and so is a motor lag: the loop model takes the rotors as instantaneous
    (the plant's 12 rigid-body states; ``tau_m > 0`` would leave the rotor
    commands acting through states it does not carry)."""
    from cosim.errors import ScenarioError
    from cosim.scenario.definition import load_scenario
    from fmu_models.models.quadrotor import QUADROTOR

    from ..controller_component import DEFAULT_PLANT

    prefix = f"fmus.{DEFAULT_PLANT}."
    for key in overrides:
        if not (key.startswith(prefix + "parameters.") or key == prefix + "parameter_set"):
            raise ScenarioError(f"--set {key}: the stability analysis takes the plant's parameters only "
                                f"({prefix}parameters.<name>=VALUE or {prefix}parameter_set=FILE.ssv)")
    if not overrides:
        return {}
    own = load_scenario("circles").fmus[DEFAULT_PLANT]["parameters"]
    given = load_scenario("circles", dict(overrides)).fmus[DEFAULT_PLANT]["parameters"]
    initial = {f"{v.name}_0" for v in QUADROTOR.states}
    plant = {k: float(v) for k, v in given.items()
             if k not in initial and float(v) != float(own.get(k, QUADROTOR.variable(k).start))}
    if plant.get("tau_m", 0.0) != 0.0:
        raise ScenarioError(f"--set: tau_m = {plant['tau_m']:g} s: the linear analysis takes the rotors as "
                            f"instantaneous (tau_m = 0; docs/stability.md); add --set "
                            f"{prefix}parameters.tau_m=0 to analyse this plant without its motor lag")
    return plant


def stability_study(settings: StabilitySettings = StabilitySettings(), *, workers: int = 1,
                    show_progress: bool = False, analysed=None) -> StabilityStudy:
    """Run every analysis ``settings`` asks for: the linear analysis of the
    PD baseline, then (``settings.cosim``) its co-simulation checks, then
    (``settings.along_flight``) the learning laws.

    workers : Dask worker processes of the studies (1: in this process).
    show_progress : print the along-flight study's plan and estimated time
        (:func:`~.along_flight.along_flight_plan`) before it starts, and draw its
        progress bar (stderr).
    analysed : called with the operating points' analyses as soon as they are
        computed, before the rest of the study (:func:`run_stability_analysis`
        starts drawing their figures there).
    """
    study = _linear(settings, analysed)
    if settings.cosim:
        _cosim_checks(study, settings)
        if settings.along_flight:
            _learning(study, settings, workers, show_progress)
    return study


def _linear(settings: StabilitySettings, analysed=None) -> StabilityStudy:
    """The linear analysis of the PD baseline at the default operating points."""
    dt, speed, position = settings.dt, settings.speed, settings.position
    geometric = replace(settings.geometric, dt=dt, vehicle=settings.vehicle)
    check_pd_gains(position.kp, position.kd, dt, geometric)
    ops = default_operating_points(speed, settings.wind_speed, position=position, geometric=geometric,
                                   plant_parameters=dict(settings.plant))
    analyses = [analyze(op, dt, every_loop=("discrete",)) for op in ops]  # what the report shows
    if analysed is not None:
        analysed(analyses)
    sweep_kp, sweep_kd = settings.sweep_kp, settings.sweep_kd
    sweeps = [gain_sweep(ops[0], sweep_kp, sweep_kd, None), gain_sweep(ops[0], sweep_kp, sweep_kd, dt),
              gain_sweep(ops[0], sweep_kp, sweep_kd, dt, 1), gain_sweep(ops[-1], sweep_kp, sweep_kd, dt)]
    bases = {"continuous": (None, 0), "discrete": (dt, 0), "discrete+1": (dt, 1)}
    critical = {op.name: {k: critical_gain_factor(op, s, d) for k, (s, d) in bases.items()} for op in ops}
    cases = feedforward_comparison(ops, dt, speed, settings.feedforward_gains, analyses)
    # the analysed gain's ramp and circle error are its feed-forward case's (the same calls on the same
    # points), computed there once: otherwise the same two linear simulations again
    same = next((c for c in cases if c.feedforward == position.feedforward), None)
    ramp = same.ramp if same is not None else ramp_error(ops[0], ops[1], speed, dt)
    circle = same.circle if same is not None else circle_error(ops[0], dt=dt)
    return StabilityStudy(dt, position, ops, analyses, sweeps, critical, ramp, circle, feedforward_cases=cases)


def _cosim_checks(study: StabilityStudy, settings: StabilitySettings) -> None:
    """The PD's linear answers checked in the co-simulation, into ``study``."""
    dt, speed, hover = settings.dt, settings.speed, study.operating_points[0]
    study.feedforward_ramp_nonlinear = {float(g): ramp_lag(hover.with_feedforward(g), speed, dt=dt)[0]
                                        for g in settings.feedforward_gains}
    study.step_checks = [check_step(hover, kind, axis, size) for kind, axis, size in STEP_CHECKS]
    c = study.critical_factors[hover.name]["discrete"]
    study.gain_checks = [check_gains(hover, f * c * study.position.kp, f * c * study.position.kd, dt=dt)
                         for f in GAIN_FACTORS]
    study.ramp_nonlinear = ramp_lag(hover, speed, dt=dt)[0]
    study.mission_rmse = pd_mission_rmse(plant=settings.plant)


def _learning(study: StabilityStudy, settings: StabilitySettings, workers: int, show_progress: bool) -> None:
    """The learning laws into ``study``: their finite-time claims on recorded
    runs, then the learning loop along the missions."""
    study.runs = default_runs(kp=settings.kp, kd=settings.kd, workers=workers)
    study.finite_time = [evaluate_claims(run, a) for run in study.runs for a in range(3)]
    if settings.along_every > 0:
        _along_flight(study, settings.kp, settings.kd, settings.along_every, workers, show_progress)


def _along_flight(study: StabilityStudy, kp: float | None, kd: float | None, every: float, workers: int,
                  show_progress: bool) -> None:
    """The learning loop along the missions into ``study`` (its plan printed first when ``show_progress``)."""
    from cosim.scenario.definition import load_scenario

    from ..progress import progress_bar
    from .along_flight import MISSIONS, AlongFlight, along_flight_plan, along_flight_study, flight_events

    gains = {f"controller.position.{k}": float(v) for k, v in (("kp", kp), ("kd", kd)) if v is not None}
    metric = AlongFlight(every=every)
    if show_progress:
        print(along_flight_plan(metric=metric, workers=workers, overrides=gains), flush=True)
    with progress_bar("along the flight", enabled=show_progress) as bar:
        study.along_flight = along_flight_study(metric=metric, workers=workers, overrides=gains, progress=bar)
    study.flight_events = {m: flight_events(load_scenario(m)) for m in MISSIONS}


def run_stability_analysis(out_dir: str | Path = "results/stability",
                           settings: StabilitySettings = StabilitySettings(), *, workers: int = 1,
                           show_progress: bool = False, figures=None) -> StabilityStudy:
    """:func:`stability_study` (same arguments), then write
    ``out_dir/stability.md`` and the PNG figures (``figures``: only these
    names of :data:`~quadrotor_paper.stability.report.FIGURES`, default every
    one; the report lists those written); returns the study with
    ``report_path`` and ``figures`` set. With ``workers`` > 1 the operating
    points' figures are drawn in a second process while the study goes on
    (:func:`~quadrotor_paper.stability.report.point_figures_aside`); the
    files are the same."""
    from .report import point_figures_aside, write_report

    aside = []
    analysed = (lambda analyses: aside.append(point_figures_aside(analyses, out_dir, names=figures))
                if workers > 1 else None)
    study = stability_study(settings, workers=workers, show_progress=show_progress, analysed=analysed)
    write_report(study, out_dir, aside[0] if aside else None, figures)
    return study
