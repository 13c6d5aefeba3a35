"""``fnn-cosim linearize`` and ``stability``: linear systems from FMUs.
``linearize``: any FMU, or an FMU instance of a scenario at a time of its
run (:mod:`cosim.linearize`); ``stability``: the linear stability report of
the PD baseline (:mod:`quadrotor_paper.stability`).
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .options import fmu_log_option, named_values, overrides, default_workers, worker_count
from . import DEFAULT_OUT, Commands, out_folder

__all__ = ["add_commands"]

STABILITY_OUT = str(DEFAULT_OUT / "stability")
_DESCRIPTION = ("Linear stability report of the PD baseline (poles, margins, Bode/Nyquist/pole-zero plots, "
                "kp-kd sweep, ramp error), checked against the co-simulation, in seconds; with --along-flight "
                "also the learning laws (minutes): their finite-time claims on recorded runs and the learning "
                "loop of every variant linearized along the circles and figure-8 missions; see docs/stability.md.")
ALONG_EVERY = 1.0  # s: the along-flight study's default


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=STABILITY_OUT, help=f"output directory (default: {STABILITY_OUT})")
    parser.add_argument("--kp", type=float, default=None, help="PD proportional gain (default: the paper's 2.5)")
    parser.add_argument("--kd", type=float, default=None, help="PD derivative gain (default: the paper's 0.005)")
    parser.add_argument("--feedforward", type=float, default=0.0,
                        help="velocity feed-forward gain of the analysed PD, in [0, 1] (default 0: the paper's law); "
                             "the report compares 0 and 1 either way")
    parser.add_argument("--speed", type=float, default=2.5, help="forward-flight and ramp speed, m/s (default 2.5)")
    parser.add_argument("--wind", type=float, default=3.0,
                        help="steady wind of the third operating point, m/s, along [-1, -1, 0] (default 3)")
    parser.add_argument("--no-cosim", action="store_true",
                        help="linear analysis only: skip the co-simulation checks (and --along-flight)")
    parser.add_argument("--along-flight", action="store_true",
                        help="also the learning laws: their finite-time claims on recorded runs and the learning "
                             "loop of every variant along the missions (about 3 min on 2 cores; its estimate is "
                             "printed before it starts, a progress bar while it runs)")
    parser.add_argument("--along-every", type=float, default=None,
                        help=f"with --along-flight: freeze the learning loop every this many seconds of each mission "
                             f"(default {ALONG_EVERY:g}; 0 skips it)")
    parser.add_argument("--figures", nargs="*", default=None, metavar="NAME",
                        help="write only these figures (their names as the report lists them, without .png, e.g. "
                             "gain_sweep bode_outer_hover); --figures alone writes none: the numbers alone, in about "
                             "half the CPU (default: every figure)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="the plant's parameters, as `fnn-cosim run` takes them: fmus.Quadrotor.parameters."
                             "<name>=VALUE, or fmus.Quadrotor.parameter_set=FILE.ssv (a calibration's); in the plant "
                             "and the controller's nominal vehicle alike (repeatable; not with --along-flight)")
    parser.add_argument("--workers", type=worker_count, default=None,
                        help="processes: Dask workers for the runs, and with 2 or more the operating points' "
                             "figures drawn in a second process while the study goes on (default: one per core; "
                             "1 runs everything in this process)")
    fmu_log_option(parser)


def add_commands(commands: Commands) -> None:
    commands.add("linearize", _linearize_arguments, _linearize,
                 help="linearize an FMU (Model Exchange, or a sampled-data Co-Simulation FMU's step): system (.npz, "
                      ".json), poles, Bode plots")
    commands.add("stability", _arguments, _stability, description=_DESCRIPTION,
                 help="linear stability analysis of the PD baseline, checked against the co-simulation")


def _checked(args: argparse.Namespace) -> None:
    """The physical meaning of the arguments, checked before anything runs (one line each)."""
    from typing import Annotated

    from pydantic import Field

    from cosim.errors import ScenarioError
    from cosim.files import output_folder
    from cosim.scenario.schema import NonNegative, Positive, Table, validate

    class Arguments(Table):
        kp: Positive = None  # a PD with kp <= 0 has no operating point to linearize around
        kd: NonNegative = None
        feedforward: Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0.0, le=1.0)] = 0.0
        speed: Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0.0, le=10.0)] = 2.5  # m/s: trimmed flight
        wind: Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0.0, le=10.0)] = 3.0  # m/s
        along_every: Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0.0, le=60.0)] = 1.0  # s
        workers: Annotated[int, Field(strict=True, ge=1)] = None

    names = ("kp", "kd", "feedforward", "speed", "wind", "along_every", "workers")
    given = {k: getattr(args, k) for k in names if getattr(args, k, None) is not None}
    from ..stability.study import check_pd_gains

    try:
        validate(Arguments, given)
        check_pd_gains(given.get("kp", 0.0), given.get("kd", 0.0))  # their bounds (the study checks them too)
    except ScenarioError as exc:  # named as the command line names them
        raise ScenarioError(f"--{str(exc).replace('along_every', 'along-every')}") from None
    if args.set and args.along_flight:  # the learning laws' recorded runs fly the shipped plant
        raise ScenarioError(f"--set {args.set[0]}: --along-flight analyses the shipped plant; a plant of your own "
                            f"goes without it")
    if args.along_every is not None and not args.along_flight:
        raise ScenarioError(f"--along-every {args.along_every:g}: applies only with --along-flight")
    if args.figures:
        from ..stability.report import FIGURES

        unknown = [name for name in args.figures if name not in FIGURES]
        if unknown:
            raise ScenarioError(f"--figures {unknown[0]}: no such figure (the report's are {', '.join(FIGURES)})")
    output_folder(args.out)


def _stability(args: argparse.Namespace) -> int:
    """Run the study for parsed arguments; prints the report's path and verdicts."""
    from ..stability.study import StabilitySettings, plant_parameters, run_stability_analysis

    _checked(args)
    plant = plant_parameters(overrides(args.set)) if args.set else {}
    workers = default_workers(args.workers)
    along_every = ALONG_EVERY if args.along_every is None else args.along_every
    settings = StabilitySettings(speed=args.speed, wind_speed=args.wind, kp=args.kp, kd=args.kd,
                                 cosim=not args.no_cosim, feedforward=args.feedforward,
                                 along_flight=args.along_flight, along_every=along_every, plant=plant)
    study = run_stability_analysis(args.out, settings, workers=workers, show_progress=True, figures=args.figures)
    for a in study.analyses:
        p = a.poles["discrete"]
        outer = min(m.gain_margin for m in a.margins["discrete"] if m.loop.startswith("outer"))
        pm = min(m.phase_margin for m in a.margins["discrete"] if m.loop.startswith("outer"))
        print(f"{a.op.name:>13}: {'stable' if p.stable else 'UNSTABLE'} (max |z| = {p.stability_measure:.5f}, "
              f"least damping {p.least_damping:.3f}); outer loops GM >= {outer:.3g}, PM >= {pm:.3g} deg")
    print(f"ramp lag at {study.ramp.speed:g} m/s: V/kp = {study.ramp.ideal:.3f} m, linear {study.ramp.linear_discrete:.3f} m, "
          f"trim {study.ramp.trim:.3f} m"
          + (f", co-simulation {study.ramp_nonlinear:.3f} m" if study.ramp_nonlinear is not None else ""))
    for case in study.feedforward_cases:
        cosim = study.feedforward_ramp_nonlinear.get(case.feedforward)
        print(f"feed-forward {case.feedforward:g}: ramp lag linear {case.ramp.linear_discrete:.4f} m, "
              f"trim {case.ramp.trim:.4f} m" + (f", co-simulation {cosim:.4f} m" if cosim is not None else "")
              + f"; circle RMS {case.circle.rms:.4f} m; outer GM >= {min(case.outer_gain_margin.values()):.3g}")
    if study.along_flight:
        from ..stability.along_flight import verdict

        for f in study.along_flight:
            v = verdict(f, study.dt)
            print(f"along {f.mission}, {f.variant}, {f.law}: learning held {v['held']}; learning on {v['on']}")
    if not args.along_flight:
        print("the learning laws (finite-time claims, the learning loop along the flight): "
              "fnn-cosim stability --along-flight (minutes)")
    print(f"report: {study.report_path}")
    return 0



# ---- linearize -------------------------------------------------------------------------

def _linearize_arguments(lz: argparse.ArgumentParser) -> None:
    lz.add_argument("fmu", help="an FMU file, or the name of a model fnn-cosim builds (e.g. Quadrotor, ControllerPDLM); "
                    "with --scenario, an FMU instance of the scenario (e.g. Quadrotor, controller)")
    lz.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version of a built model (default 2)")
    lz.add_argument("--parameter", action="append", default=[], metavar="NAME=VALUE", help="a parameter (repeatable)")
    lz.add_argument("--input", action="append", default=[], metavar="NAME=VALUE", help="an input (repeatable)")
    lz.add_argument("--start", action="append", default=[], metavar="NAME=VALUE",
                    help="a continuous (ME) or discrete (CS) state (repeatable)")
    lz.add_argument("--method", choices=("auto", "derivatives", "differences"), default="auto")
    lz.add_argument("--interface", choices=("auto", "me", "cs"), default="auto")
    lz.add_argument("--bode", action="append", default=[], metavar="INPUT:OUTPUT", help="a Bode plot (repeatable)")
    lz.add_argument("--scenario", default=None, metavar="NAME|FILE",
                    help="take the operating point from a run of this scenario at --time: the instance's FMU state, "
                         "inputs and parameters then")
    lz.add_argument("--time", type=float, default=None, metavar="T", help="the run's time (s) for --scenario")
    lz.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a value of --scenario (repeatable)")
    lz.add_argument("--out", default=None, help="output directory (default results/linearize)")
    fmu_log_option(lz)


def _operating_point(args) -> tuple[Path, dict[str, Any]]:
    """The FMU file and the operating point to linearize at: ``--scenario S
    --time T``, instance ``args.fmu`` at T of S's run
    (:func:`cosim.linearize.linearization.operating_point_of_run`); else the FMU file or
    built model ``args.fmu`` at ``--parameter``'s values."""
    from cosim.scenario.assembly import fmu_file_or_model
    from cosim.errors import ScenarioError

    if args.scenario is None and args.time is None:
        return fmu_file_or_model(args.fmu, args.fmi, "linearize"), dict(parameters=named_values(args.parameter,
                                                                                                "--parameter"))
    if args.scenario is None:
        raise ScenarioError("--time: give the run's scenario with --scenario")
    if args.parameter:
        raise ScenarioError("--parameter: with --scenario the parameters are the run's; set them with --set")
    if args.time is None:
        raise ScenarioError("--scenario: give the time of the run to linearize at with --time")
    from cosim.linearize.linearization import operating_point_of_run
    from cosim.scenario.definition import load_scenario

    return operating_point_of_run(load_scenario(args.scenario, overrides(args.set)), args.fmu, args.time,
                                  f"--time {args.time!r}")


def _bode_pairs(pairs: list[str]) -> list[tuple[str, str]]:
    """``--bode INPUT:OUTPUT`` pairs (a name as FMI writes it: ``x[1]``, ``'a:b'``)."""
    from cosim.errors import ScenarioError
    from cosim.names import partition_top

    out = []
    for pair in pairs:
        i, colon, o = partition_top(pair, ":")
        if not colon or not i or not o:
            raise ScenarioError(f"--bode {pair!r}: expected INPUT:OUTPUT, e.g. --bode Omega_1:z")
        out.append((i, o))
    return out


def _linearize(args) -> int:
    """Linearize an FMU file or a registered model (built as FMI ``--fmi``) at
    the operating point given, or an FMU instance of a scenario at time
    ``--time`` of its run; write the system, its poles and Bode plots."""
    from cosim.errors import ScenarioError
    from cosim.linearize.linearization import LinearizationError, linearize_fmu, save_linearization

    path, point = _operating_point(args)
    pairs = _bode_pairs(args.bode)
    out = out_folder(args.out, DEFAULT_OUT / "linearize")
    try:
        point["inputs"] = point.get("inputs", {}) | named_values(args.input, "--input")
        lin = linearize_fmu(path, start=named_values(args.start, "--start"), method=args.method,
                            interface=args.interface, **point)
        written = save_linearization(lin, out, pairs, stem=path.stem)
    except LinearizationError as exc:
        raise ScenarioError(str(exc)) from None
    system = lin.system
    kind = f"discrete, dt = {system.dt:g} s" if system.dt else "continuous"
    print(f"{path.name}: {system.nstates} states, {system.ninputs} inputs, {system.noutputs} outputs ({kind}); "
          f"{lin.method}, error estimate {lin.error_estimate:.3g}")
    measure = lin.stability_measure()
    if measure is not None:
        print(f"poles: {measure[0]} {measure[1]:.6g}")
    for f in written:
        print(f)
    return 0
