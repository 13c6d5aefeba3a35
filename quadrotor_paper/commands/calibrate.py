"""``fnn-cosim calibrate``: an FMU's parameters fitted to a log (docs/calibration.md).

The command's arguments and its run; the calibration is the engine's
(:mod:`cosim.calibration`). Exit status 0: converged; 1: the fit did not
converge (its report is written with the last iterate, and says so), or,
with ``--strict``, it warned (:mod:`cosim.calibration.diagnostics`; every
file written first); 2: bad input, nothing fitted. The warnings are printed
on stderr, ``warning: ...``, after the files are written.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .options import named_values, overrides, worker_count
from . import DEFAULT_OUT, Commands

__all__ = ["add_commands"]

CALIBRATION_OUT = str(DEFAULT_OUT / "calibration")
COLUMN_MAPS = Path(__file__).resolve().parent.parent / "column_maps"  # the built-in maps: --columns px4, px4-pwm


def add_commands(commands: Commands) -> None:
    commands.add("calibrate", _arguments, _calibrate,
                 help="fit an FMU's parameters to a log: estimates, intervals, identifiability, an SSP parameter "
                      "set")


def _arguments(c: argparse.ArgumentParser) -> None:
    c.add_argument("log", help="the log: the project's results (CSV, Parquet), any CSV with --columns, a PX4 ULog "
                   "(.ulg, needs pyulog)")
    where = c.add_mutually_exclusive_group(required=True)
    where.add_argument("--fmu", metavar="FILE|MODEL", help="the FMU driven alone by the log's inputs (a file, or a "
                       "model fnn-cosim builds, e.g. Quadrotor)")
    where.add_argument("--scenario", metavar="NAME|FILE", help="an FMU instance of this scenario, its inputs fed by "
                       "the log's columns of what is connected to them")
    c.add_argument("--instance", default=None, help="with --scenario: the FMU instance (default: the one that has "
                   "every --fit name)")
    c.add_argument("--fit", default=None, metavar="NAMES", help="comma-separated parameters (and inputs the log "
                   "lacks, fitted as constants) to estimate")
    c.add_argument("--fix", action="append", default=[], metavar="K=V", help="a parameter set and not fitted "
                   "(repeatable)")
    c.add_argument("--guess", action="append", default=[], metavar="K=V", help="a first guess (repeatable; default "
                   "the FMU's start value)")
    c.add_argument("--columns", default=None, metavar="MAP.toml|px4|px4-pwm",
                   help="the column map: log columns as FMU variables; 'px4' ('px4-pwm'): a PX4 ULog onto the plant, "
                        "rotor speeds from actuator_motors (actuator_outputs' PWM)")
    c.add_argument("--settings", default=None, metavar="FILE.toml", help="calibration settings (docs/calibration.md)")
    c.add_argument("--segment", type=float, default=None, metavar="S", help="shooting segment length, s")
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="with --scenario: override a "
                   "value of the scenario (repeatable)")
    c.add_argument("--workers", type=worker_count, default=None, metavar="N",
                   help="processes that share the segments (default: the settings', 1)")
    c.add_argument("--interface", default=None, metavar="auto|CoSimulation|ModelExchange",
                   help="the FMU's interface that makes the trajectories (default: the settings', 'auto': "
                        "Co-Simulation where the FMU has it, else Model Exchange)")
    c.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version of a built model (default 2)")
    c.add_argument("--out", default=None, help=f"output directory (default {CALIBRATION_OUT})")
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    c.add_argument("--no-plots", action="store_true", help="no figures (report.md without them)")
    c.add_argument("--strict", action="store_true", help="exit status 1 when the calibration warns (residuals not "
                   "white, held-out error, Jacobian error, an estimate at its bound, an unmatched column), after "
                   "writing every file")


def _column_map_file(given: str) -> Path:
    """A built-in map's file by its name (``px4``), else the file given."""
    builtin = COLUMN_MAPS / f"{given}.toml"
    return builtin if "/" not in given and not given.endswith(".toml") and builtin.is_file() else Path(given)


def _calibrate(args) -> int:
    from cosim.scenario.assembly import fmu_file_or_model
    from cosim.calibration import calibrate, read_column_map, read_settings
    from cosim.calibration.columns import CalibrationSettings
    from cosim.calibration.outputs import estimate_lines, write_outputs
    from cosim.errors import ScenarioError
    from cosim.files import output_folder
    from cosim.scenario.schema import validate

    from ..progress import progress_bar

    settings = read_settings(args.settings) if args.settings else CalibrationSettings()
    update = {}
    if args.fit is not None:
        from cosim.names import split_top

        names = [n.strip() for n in split_top(args.fit, ",") if n.strip()]  # x[1,2], 'a,b': one name each
        if not names:
            raise ScenarioError(f"--fit {args.fit!r}: expected comma-separated names, e.g. --fit m,Ix")
        update["fit"] = names
    if args.fix:
        update["fix"] = {**settings.fix, **named_values(args.fix, "--fix")}
    if args.guess:
        update["guess"] = {**settings.guess, **named_values(args.guess, "--guess")}
    if args.segment is not None:
        if not args.segment > 0:
            raise ScenarioError(f"--segment {args.segment!r}: must be positive")
        update["segment"] = args.segment
    if args.workers is not None:
        update["workers"] = args.workers
    if args.interface is not None:
        update["interface"] = args.interface
    if update:
        settings = validate(CalibrationSettings, settings.model_dump(exclude_none=True) | update)
    column_map = read_column_map(_column_map_file(args.columns)) if args.columns else None
    out = output_folder(args.out or CALIBRATION_OUT)
    fixed, extra, instance = {}, {}, None
    if args.scenario is not None:
        from cosim.calibration.scenario_instance import scenario_instance

        instance, fmu, fixed, extra, interface = scenario_instance(args.scenario, args.instance, settings.fit,
                                                                   overrides(args.set))
        if settings.interface == "auto":  # the interface the scenario flies it in
            settings = settings.model_copy(update={"interface": interface})
    else:
        if args.set or args.instance:
            raise ScenarioError("--set and --instance go with --scenario")
        fmu = fmu_file_or_model(args.fmu, args.fmi, "--fmu")
    with progress_bar("calibrate", settings.max_iterations, enabled=not args.quiet, unit="Jacobian") as update_bar:
        cal = calibrate(args.log, fmu, settings, column_map, instance=instance, extra_columns=extra, fixed=fixed,
                        progress=update_bar)
    written = write_outputs(cal, out, args.log, fmu, instance, plots=not args.no_plots)
    for line in estimate_lines(cal):
        print(line)
    for path in written[:4]:
        print(path)
    for d in cal.diagnostics:
        print(f"warning: {d.kind}: {d.message}", file=sys.stderr)
    if not cal.converged:
        print(f"fnn-cosim: the fit did not converge ({cal.fit.message}); the report shows the last iterate")
        return 1
    if args.strict and cal.diagnostics:
        print(f"fnn-cosim: --strict: {len(cal.diagnostics)} warning(s) (report.md lists them)", file=sys.stderr)
        return 1
    return 0
