"""``fnn-cosim``: run scenarios, reproduce Table 2 and Table 3, build the FMUs.

Subcommands::

    fnn-cosim run SCENARIO|FILE.ssp [--out DIR] [--set KEY=VALUE ...] [--seed N] [--variant V] [--no-plots] [--record-every K]
                 [--profile] [--save-learned FILE] [--load-learned FILE] [--fmu-log [INSTANCE=]LEVEL]
    fnn-cosim export-ssp SCENARIO --out FILE.ssp [--set KEY=VALUE ...]
    fnn-cosim table2 [--out DIR] [--seeds 10] [--winds 1,3,5] [--duration S] [--workers 2] [--scheduler ADDRESS]
    fnn-cosim table3 [--out DIR] [--seeds 10] [--duration S] [--workers 2] [--scheduler ADDRESS]
    fnn-cosim reproduce [--out DIR] [--seeds 10] [--duration S] [--workers 2] [--scheduler ADDRESS]
    fnn-cosim sweep STUDY.toml|NAME [--out DIR] [--workers N] [--scheduler ADDRESS] [--no-plots]
    fnn-cosim scenarios
    fnn-cosim schema scenario|study|settings|column-map [--out FILE]
    fnn-cosim build-fmu [--out DIR]
    fnn-cosim linearize FMU|MODEL [--fmi 2|3] [--parameter N=V ...] [--input N=V ...] [--start N=V ...]
                 [--method auto|derivatives|differences] [--interface auto|me|cs] [--bode IN:OUT ...] [--out DIR]
    fnn-cosim linearize INSTANCE --scenario SCENARIO --time T [--set KEY=VALUE ...] [--bode IN:OUT ...] [--out DIR]
    fnn-cosim stability [--out DIR] [--kp KP] [--kd KD] [--speed V] [--wind W] [--no-cosim] [--along-flight [--along-every S]]
                 [--figures [NAME ...]] [--workers N]

SCENARIO is a TOML file or the name of a shipped scenario (``circles``, ``circles_sensors``,
``figure8``); STUDY a study file (``docs/studies.md``) or the name of a
shipped one (``quadrotor_paper/studies/``). The sweeps run on Dask: a local
cluster of ``--workers`` processes (``--workers 1``: in this process), or
the running cluster at ``--scheduler``. Results go under ``results/`` unless
``--out`` says otherwise.
Errors print one line on stderr (``--debug`` adds the traceback): a bad
scenario, connection or FMU file (a broken archive, no binary for this
platform, a parameter the FMU refuses) exits with status 2 before anything
runs; a run that diverges or fails mid-way exits with status 1 and keeps its
partial results.
"""
from __future__ import annotations

import argparse
import gc
import os
import sys
from pathlib import Path
from typing import Any, Sequence

from .fmu_log_option import apply_fmu_log, fmu_log_option
from .set_option import overrides as _overrides
from .workers_option import TABLE_WORKERS, default_workers, worker_count

__all__ = ["main"]

DEFAULT_OUT = Path("results")
EXIT_RUN_FAILED = 1  # a run diverged or an FMU failed mid-run (partial results kept)
EXIT_BAD_INPUT = 2  # a scenario, connection or FMU file is wrong: refused before anything ran


def _out_folder(given: str | None, default: Path) -> Path:
    """The output folder, checked (made, writable) before anything runs."""
    from cosim.files import output_folder

    return output_folder(given or default)


# ---- run ------------------------------------------------------------------------------

def _record_every(text: str) -> int:
    """The ``type`` of ``--record-every``: a whole number from 1."""
    from cosim.errors import shown_text

    try:
        k = int(text)
    except ValueError:  # not a whole number, or beyond Python's digits
        k = 0
    if k < 1:
        raise argparse.ArgumentTypeError(f"{shown_text(repr(text))}: expected a whole number from 1 (every K-th "
                                         f"row written)")
    return k


def _results_room(scenario, master, out: Path, every: int, quiet: bool) -> None:
    """What results.csv will take, said before the run, and refused when the
    output folder's file system cannot hold it (memory does not grow with
    the run: disk is the only bound, and it is the user's; docs/security.md)."""
    from cosim.files import room_for
    from cosim.loop.recorder import csv_bytes

    rows = int(round(scenario.duration / scenario.step)) + 1
    written = -(-rows // every)
    need = csv_bytes(written, master.record_columns, master.plan.record_types)
    room_for(out, need, f"results.csv: {written} rows of {len(master.record_columns)} columns",
             "write every K-th row: --record-every K, or record fewer signals")
    if not quiet and need > 100e6:  # a long mission: say what it will write before it starts
        print(f"results.csv: {written} rows of {len(master.record_columns)} columns, up to {need / 1e9:.1f} GB "
              f"(--record-every K writes every K-th)", file=sys.stderr)

def _cmd_run(args) -> int:
    from cosim.scenario.definition import load_scenario
    from cosim.files import write_json

    from .experiments import run_once
    from .progress import progress_bar
    from .run_summary import summary_lines

    from cosim.errors import CosimError, ScenarioError, one_line
    from cosim.files import is_ssp, not_others_results, output_file, output_folder, safe_name

    from cosim.notes import show_on_stderr

    show_on_stderr(not args.quiet)  # what the engine decides for the user (a default step, a unit's radian)
    overrides = _overrides(args.set)
    if args.seed is not None:
        overrides["simulation.seed"] = args.seed
    if is_ssp(args.scenario):
        for flag, value in (("--variant", args.variant), ("--load-learned", args.load_learned)):
            if value:
                raise ScenarioError(f"{flag} {value}: an SSP archive's controller is an FMU it holds, with its "
                                    f"own model and state; give it to a TOML scenario's [controller]")
        from cosim.ssp.archive import load_ssp

        scenario = load_ssp(args.scenario, overrides=overrides)
    else:
        if args.variant:
            overrides["controller.variant"] = args.variant
        if args.load_learned:
            overrides["controller.learned"] = str(args.load_learned)
        scenario = load_scenario(args.scenario, overrides)
    from cosim.scenario.assembly import build_master

    with build_master(scenario) as master:  # every input refused before anything is written
        _started()
        from cosim.notes import release

        release()  # the inputs are taken: the notes the engine held for them (none with --quiet)
        # every place a result goes is checked before the run: nothing computed is lost for want of it
        out = not_others_results(output_folder(args.out or DEFAULT_OUT / f"run-{safe_name(scenario.name)}"), "run")
        learned_file = output_file(args.save_learned, "--save-learned") if args.save_learned else None
        if learned_file is not None:
            from .learned import learned_variant, save_learned

            if "controller" not in master.components:
                raise ScenarioError(f"--save-learned {learned_file}: the scenario has no controller")
            learned_variant(master.components["controller"], f"--save-learned {learned_file}")
        _results_room(scenario, master, out, args.record_every, quiet=args.quiet)
        with progress_bar(f"run {scenario.name}", enabled=not args.quiet, unit="step") as bar:
            result, summary = run_once(scenario, out, progress=bar, master=master, profile=args.profile,
                                       record_every=args.record_every)
        if args.load_learned:
            summary["resumed_from"] = str(args.load_learned)
        plots = not args.no_plots and summary["rows"] > 1
        if plots or learned_file is not None:  # the run's results first, kept if an optional part below fails
            write_json(out / "summary.json", summary)
        learned_error = None
        if learned_file is not None:
            try:  # a state that cannot be saved (not finite after a diverged run) loses nothing else
                summary["learned_state"] = str(save_learned(master.components["controller"], learned_file))
            except (CosimError, ValueError, OSError) as exc:
                learned_error = summary["learned_state_error"] = f"--save-learned {learned_file}: {one_line(str(exc))}"
    figures = []
    if plots:
        from .plots import run_figures  # matplotlib only when there is something to draw

        figures = run_figures(out, result, scenario)
    summary["figures"] = [str(p) for p in figures]
    write_json(out / "summary.json", summary)
    lines = summary_lines(scenario, result, summary, figures, learned_error)
    (out / "summary.md").write_text("\n".join(lines))
    print("\n".join(lines[4:-2]))
    print(f"results: {out}")
    failure = summary["error"] if summary["status"] != "ok" else learned_error  # the run's own first
    if failure:
        print(f"fnn-cosim: error: {failure}", file=sys.stderr)
        return EXIT_RUN_FAILED
    return 0


# ---- tables and reproduction ------------------------------------------------------------

def _table_changes(args) -> dict[str, Any]:
    """What the command line changes in a table's study (None: as the study file says)."""
    changes = {"seeds": args.seeds, "duration": args.duration, "variants": args.variants, "options": args.options,
               "option_seeds": args.option_seeds}
    for key in ("scenario", "winds"):  # the commands that have them
        if getattr(args, key, None) is not None:
            changes[key] = getattr(args, key)
    if getattr(args, "set", None):
        changes["overrides"] = _overrides(args.set)
    return changes


def _cmd_table2(args) -> int:
    from .report import table2

    out = _out_folder(args.out, DEFAULT_OUT / "table2")
    workers = default_workers(args.workers, TABLE_WORKERS)
    summary = table2(out, workers=workers, scheduler=args.scheduler, show_progress=not args.quiet,
                     worker_timeout=args.worker_timeout,
                     **_table_changes(args))
    return _print_table(summary, out / "table2.md", out)


def _cmd_table3(args) -> int:
    from .report import table3

    out = _out_folder(args.out, DEFAULT_OUT / "table3")
    workers = default_workers(args.workers, TABLE_WORKERS)
    summary = table3(out, workers=workers, scheduler=args.scheduler, show_progress=not args.quiet,
                     worker_timeout=args.worker_timeout,
                     **_table_changes(args))
    return _print_table(summary, out / "table3.md", out)


def _print_table(summary, table_path: Path, out: Path) -> int:
    print(summary["markdown"])
    print(f"{summary['rows']} runs in {summary['wall_time_s']:.1f} s; table: {table_path}, "
          f"data: {out} (runs.csv, runs.parquet, summary.json)")
    return 0


def _cmd_reproduce(args) -> int:
    from .report import reproduce

    out = _out_folder(args.out, DEFAULT_OUT)
    workers = default_workers(args.workers, TABLE_WORKERS)
    path = reproduce(out, workers=workers, scheduler=args.scheduler, show_progress=not args.quiet,
                     worker_timeout=args.worker_timeout,
                     **_table_changes(args))
    print(f"report: {path}")
    return 0


def _cell_means(summary) -> str:
    """The study's cells, one line each: case, grid point, ok runs and each
    metric's mean over them (what summary.json holds, to read at a glance)."""
    lines = []
    for cell in summary.get("cells", []):
        point = ", ".join(f"{k}={v}" for k, v in cell["values"].items())
        means = ", ".join(f"{m} {s['mean']:.4g}" for m, s in cell["metrics"].items() if s["mean"] is not None)
        lines.append(f"{' / '.join(x for x in (cell['label'], point) if x)}: {cell['ok']} ok; {means}")
    return "\n".join(lines)


def _cmd_sweep(args) -> int:
    """A study: the base scenario over its cases and sweep, one row per run in runs.csv."""
    from cosim.study.definition import load_study

    from .experiments import measure
    from .progress import progress_bar

    from cosim.files import safe_name

    study = load_study(args.study)
    out = _out_folder(args.out, DEFAULT_OUT / f"study-{safe_name(study.name)}")
    workers = default_workers(args.workers)
    with progress_bar(f"sweep {study.name}", enabled=not args.quiet) as bar:
        result = measure(study, out, workers=max(1, workers), scheduler=args.scheduler, progress=bar,
                         plots=not args.no_plots, worker_timeout=args.worker_timeout)
    counts = ", ".join(f"{n} {status}" for status, n in sorted(result.counts.items())) or "nothing to run"
    print(_cell_means(result.summary))
    print(f"{study.name}: {result.total} runs ({result.skipped} already done); this time: {counts}")
    print(f"results: {out} (runs.csv, runs.parquet, summary.json" + ", plots" * (not args.no_plots) + ")")
    return 0


def _cmd_export_ssp(args) -> int:
    """Write the scenario, every component as an FMU, as an SSP archive."""
    from cosim.scenario.definition import load_scenario
    from cosim.ssp.export import export_ssp

    from .portable import all_fmu

    from cosim.files import output_file

    out = output_file(args.out, "--out")
    print(export_ssp(all_fmu(load_scenario(args.scenario, _overrides(args.set))), out))
    return 0


def _cmd_schema(args) -> int:
    """Print the JSON Schema of a scenario, a study or a calibration file (for editors: docs/cosim.md)."""
    import json

    if args.kind == "scenario":
        from cosim.scenario.definition import scenario_json_schema as schema
    elif args.kind == "study":
        from cosim.study.definition import study_json_schema as schema
    else:  # fnn-cosim calibrate's files: --settings, --columns
        from cosim.calibration.columns import calibration_schema

        schema = lambda: calibration_schema()[args.kind.replace("-", "_")]  # noqa: E731
    text = json.dumps(schema(), indent=1)
    if args.out:
        from cosim.files import output_file

        output_file(args.out, "--out").write_text(text + "\n")
        print(args.out)
    else:
        print(text)
    return 0


def _cmd_scenarios(args) -> int:
    from cosim.scenario.definition import load_scenario, shipped_scenarios

    shipped = sorted(shipped_scenarios().items())
    width = max(len(name) for name, _ in shipped)
    for name, path in shipped:
        print(f"{name:{width}s}  {load_scenario(path).description}  ({path})")
    return 0


# ---- build-fmu (FMU export; owned with fmu_models) ---------------------------------------

def _cmd_build_fmu(args) -> int:
    """Build every registered model (the plant, the wind, the references, the
    controller of every variant) in every FMI version the exporter supports,
    side by side (:func:`cosim.scenario.registry.build_fmu_models`); print the path
    of each FMU written, one per line."""
    import shutil

    from cosim.scenario import registry
    from fmu_models.export.build import FMI_VERSIONS

    from cosim.files import output_folder

    out = output_folder(args.out)
    for name, version, path in registry.build_fmu_models(sorted(FMI_VERSIONS)):
        target = out / f"fmi{version}" / f"{name}.fmu"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, target)
        print(target)
    return 0


# ---- linearize -------------------------------------------------------------------------

def _named_values(pairs: Sequence[str], option: str) -> dict[str, float]:
    """``NAME=VALUE`` pairs of ``option``, every value a finite number (one line otherwise)."""
    import math

    from cosim.errors import ScenarioError, shown_text
    from cosim.names import partition_top

    out = {}
    for pair in pairs:  # a variable name as FMI writes it: x[1], der(x), 'a=b' (cosim.names)
        name, eq, text = partition_top(pair, "=")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not eq or not name.strip() or not math.isfinite(value):
            raise ScenarioError(f"{option} {shown_text(pair)!r}: expected NAME=VALUE with a finite number, e.g. {option} m=1.2")
        out[name.strip()] = value
    return out


def _operating_point_of_run(args) -> tuple[Path, dict[str, Any]]:
    """``--scenario S --time T``: the FMU file of instance ``args.fmu`` and its
    operating point at T of S's run (:func:`cosim.linearize.linearization.operating_point_of_run`)."""
    from cosim.errors import ScenarioError
    from cosim.linearize.linearization import operating_point_of_run
    from cosim.scenario.definition import load_scenario

    if args.parameter:
        raise ScenarioError("--parameter: with --scenario the parameters are the run's; set them with --set")
    if args.time is None:
        raise ScenarioError("--scenario: give the time of the run to linearize at with --time")
    return operating_point_of_run(load_scenario(args.scenario, _overrides(args.set)), args.fmu, args.time,
                                  f"--time {args.time!r}")


def _cmd_linearize(args) -> int:
    """Linearize an FMU file or a registered model (built as FMI ``--fmi``) at
    the operating point given, or an FMU instance of a scenario at time
    ``--time`` of its run; write the system, its poles and Bode plots."""
    from cosim.scenario.assembly import fmu_file_or_model
    from cosim.errors import ScenarioError
    from cosim.linearize.linearization import LinearizationError, linearize_fmu, save_linearization

    if args.scenario is not None or args.time is not None:
        if args.scenario is None:
            raise ScenarioError("--time: give the run's scenario with --scenario")
        path, point = _operating_point_of_run(args)
    else:
        path = fmu_file_or_model(args.fmu, args.fmi, "linearize")
        point = dict(parameters=_named_values(args.parameter, "--parameter"))
    pairs = []
    from cosim.names import partition_top

    for pair in args.bode:
        i, colon, o = partition_top(pair, ":")
        if not colon or not i or not o:
            raise ScenarioError(f"--bode {pair!r}: expected INPUT:OUTPUT, e.g. --bode Omega_1:z")
        pairs.append((i, o))
    out = _out_folder(args.out, DEFAULT_OUT / "linearize")
    try:
        point["inputs"] = point.get("inputs", {}) | _named_values(args.input, "--input")
        lin = linearize_fmu(path, start=_named_values(args.start, "--start"), method=args.method,
                            interface=args.interface, **point)
        written = save_linearization(lin, out, pairs, stem=path.stem)
    except LinearizationError as exc:
        raise ScenarioError(str(exc)) from None
    system = lin.system
    kind = f"discrete, dt = {system.dt:g} s" if system.dt else "continuous"
    print(f"{path.name}: {system.nstates} states, {system.ninputs} inputs, {system.noutputs} outputs ({kind}); "
          f"{lin.method}, error estimate {lin.error_estimate:.3g}")
    import numpy as np

    poles = np.linalg.eigvals(lin.A) if system.nstates else np.zeros(0)
    if system.nstates:
        measure = ("spectral radius", float(np.max(np.abs(poles)))) if system.dt else \
            ("largest real part", float(np.max(poles.real)))
        print(f"poles: {measure[0]} {measure[1]:.6g}")
    for f in written:
        print(f)
    return 0


# ---- entry point ------------------------------------------------------------------------

def _names(text: str, known: Sequence[str], kind: str, extra: str = "") -> list[str]:
    """The comma-separated names of ``text``, each one of ``known`` (an
    ``ArgumentTypeError`` naming the unknown ones and the known, before any run)."""
    names = [v.strip() for v in text.split(",") if v.strip()]
    unknown = [v for v in names if v not in known]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"{text!r}: unknown {kind} {', '.join(map(repr, unknown)) or '(none given)'}; "
                                         f"known: {', '.join(known)}{extra}")
    return names


def _wind_list(text: str) -> list[float]:
    """``--winds 1,3,5``: numbers (each then checked by the study, as its grid values are)."""
    try:
        winds = [float(w) for w in text.split(",") if w.strip()]
    except ValueError:
        winds = []
    if not winds:
        raise argparse.ArgumentTypeError(f"{text!r}: expected wind speeds in m/s, e.g. 1,3,5")
    return winds


def _variant_list(text: str) -> list[str]:
    """``--variants a,b``: every name a registered variant."""
    from fnn_controller.variants import variant_names

    return _names(text, variant_names(), "variant")


def _option_list(text: str) -> list[str]:
    """``--options a,b``: every name a known option row; ``none``: no option rows."""
    from .options import option_names

    return [] if text.strip() == "none" else _names(text, option_names(), "option", ", or none")


def _seconds(text: str) -> float | None:
    """``--worker-timeout``: seconds >= 0, or ``forever``."""
    if text.strip() == "forever":
        return None
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r}: expected seconds (a number >= 0) or 'forever'")
    return value


def _worker_timeout(parser) -> None:
    from cosim.limits import WORKER_TIMEOUT

    parser.add_argument("--worker-timeout", type=_seconds, default=WORKER_TIMEOUT, metavar="S",
                        help=f"stop when the Dask cluster has had no worker for S seconds (default {WORKER_TIMEOUT:g}; "
                             f"'forever': wait)")


class _Parser(argparse.ArgumentParser):
    """argparse with its refusals in the tool's one line (exit 2: nothing ran)."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"fnn-cosim: error: {self.prog.removeprefix('fnn-cosim ')}: {message}\n"
                  if self.prog != "fnn-cosim" else f"fnn-cosim: error: {message}\n")


class _Commands(argparse._SubParsersAction):
    """The subcommands, each one's parser made when it is the one given:
    ``fnn-cosim run`` builds the run's parser and not every other command's
    (argparse builds a parser per command, and asks gettext for its
    headings' translations, several file lookups each), and imports nothing
    only another command's options need (start-up, docs/cosim.md). The
    names and one-line helps are there from the start, for the usage
    lines, ``--help`` and the refusal of an unknown command. What a command
    accepts, refuses and prints is what it would be with every parser built
    at once."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._pending: dict[str, Any] = {}  # command -> what makes its parser, until it is given

    def add_parser(self, name, arguments=None, func=None, **kwargs):
        """The command ``name``: ``arguments(parser)`` adds its arguments and
        ``func`` is its handler (``args.func``), both when it is given;
        ``kwargs``: the parser's (``help``: the command's line in the listing)."""
        if name in self._name_parser_map:
            raise argparse.ArgumentError(self, f"conflicting subparser: {name}")
        kwargs.setdefault("prog", f"{self._prog_prefix} {name}")
        if "help" in kwargs:
            self._choices_actions.append(self._ChoicesPseudoAction(name, (), kwargs.pop("help")))
        self._name_parser_map[name] = None  # one of the choices; its parser made by _made
        self._pending[name] = (arguments, func, kwargs)

    def _made(self, name: str) -> argparse.ArgumentParser:
        """The parser of the command ``name``, made when first asked for."""
        pending = self._pending.pop(name, None)
        if pending is not None:
            arguments, func, kwargs = pending
            parser = self._name_parser_map[name] = self._parser_class(**kwargs)
            if arguments is not None:
                arguments(parser)
            if func is not None:
                parser.set_defaults(func=func)
        return self._name_parser_map[name]

    def __call__(self, parser, namespace, values, option_string=None):
        if values[0] in self._pending:
            self._made(values[0])
        super().__call__(parser, namespace, values, option_string)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="fnn-cosim", description=__doc__.split("\n\n")[0])
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    sub = p.add_subparsers(dest="command", required=True, action=_Commands)

    def common(sp, seeds=True):
        sp.add_argument("--out", help="output directory (default: under results/)")
        fmu_log_option(sp)
        sp.add_argument("--quiet", action="store_true", help="no progress bar, no notes")
        if seeds:
            from fnn_controller.variants import variant_names

            from .options import DEFAULT_OPTIONS, OPTION_SEEDS, option_names

            sp.add_argument("--seeds", type=int, help="runs per cell of the variants' rows, seeds 0..N-1 "
                                                      "(default: the study's, 10)")
            sp.add_argument("--duration", type=float, help="override the missions' duration (s)")
            sp.add_argument("--workers", type=worker_count, help=f"worker processes, 1 to the cores (default "
                                                                 f"{TABLE_WORKERS}; 1: in this process)")
            sp.add_argument("--scheduler", metavar="ADDRESS", help="run on the Dask cluster at ADDRESS instead")
            _worker_timeout(sp)
            sp.add_argument("--variants", type=_variant_list,
                            metavar="A,B", help="the variants' rows, e.g. pd,pd+smc,pd+lm (default: the study's: "
                                                + ", ".join(variant_names()) + ")")
            sp.add_argument("--options", type=_option_list, metavar="A,B",
                            help="option rows below the paper's (settings beyond the paper, "
                                 "quadrotor_paper/options.py): " + ", ".join(option_names())
                                 + "; none for none (default: the study's, " + ",".join(DEFAULT_OPTIONS) + ")")
            sp.add_argument("--option-seeds", type=int, metavar="N",
                            help=f"runs per option cell (default: the smaller of --seeds and {OPTION_SEEDS}; "
                                 f"without --seeds the study's, {OPTION_SEEDS})")

    def run(r):
        from fnn_controller.variants import variant_names

        r.add_argument("scenario", help="TOML file, shipped scenario name (see fnn-cosim scenarios), or SSP archive "
                                        "(.ssp)")
        r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                       help="override a scenario value, e.g. --set wind.speed=5 (repeatable)")
        r.add_argument("--seed", type=int, help="the run's seed (simulation.seed): every seeded component and FMU "
                       "draws from it (the FNN's initial weights, sensor noise, wind)")
        r.add_argument("--variant", choices=variant_names(), help="controller variant")
        r.add_argument("--no-plots", action="store_true")
        r.add_argument("--record-every", type=_record_every, default=1, metavar="K",
                       help="write every K-th row to results.csv (rows 0, K, 2K, ...): a long mission in less disk; "
                            "the metrics still take every row (default 1)")
        r.add_argument("--profile", action="store_true",
                       help="time each phase of the loop (summary.json: cost_per_step_us; python_loop: why the "
                            "compiled loop cannot run the plan)")
        r.add_argument("--save-learned", metavar="FILE", help="write the controller's learned state after the run")
        r.add_argument("--load-learned", metavar="FILE",
                       help="start the controller from a saved learned state (resume learning)")
        common(r, seeds=False)

    sub.add_parser("run", run, _cmd_run, help="run one scenario: results CSV, plots, summary")

    def table2(t2):
        t2.add_argument("--winds", type=_wind_list, help="wind speeds in m/s (default: the study's, 1,3,5)")
        t2.add_argument("--scenario",
                        help="the mission (default circles; e.g. circles_sensors: the same with measurement noise)")
        t2.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help='override a scenario value, e.g. --set simulation.ordering=\'"exchange"\'')
        common(t2)

    sub.add_parser("table2", table2, _cmd_table2, help="Table 2: every controller variant at 1, 3, 5 m/s wind")

    def table3(t3):
        t3.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scenario value")
        t3.add_argument("--scenario", help="the mission (default: the study's, figure8)")
        common(t3)

    sub.add_parser("table3", table3, _cmd_table3, help="Table 3: the figure-8")
    sub.add_parser("reproduce", common, _cmd_reproduce, help="Tables 2 and 3 and the figures into results/report.md")

    def sweep(sw):
        sw.add_argument("study", help="study TOML file (docs/studies.md) or a shipped study's name")
        sw.add_argument("--workers", type=worker_count, help="local worker processes, 1 to the cores (default: one "
                                                            "per core; 1: in this process)")
        sw.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on the Dask cluster at ADDRESS (e.g. tcp://host:8786)")
        _worker_timeout(sw)
        sw.add_argument("--no-plots", action="store_true")
        common(sw, seeds=False)

    sub.add_parser("sweep", sweep, _cmd_sweep, help="a study: a scenario over a grid and/or random samples of its keys")

    def export_ssp(e):
        e.add_argument("scenario", help="TOML file or shipped scenario name (see fnn-cosim scenarios)")
        e.add_argument("--out", required=True, help="the .ssp file to write")
        e.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scenario value")

    sub.add_parser("export-ssp", export_ssp, _cmd_export_ssp,
                   help="write a scenario as an SSP 1.0 archive, every component an FMU")

    def schema(js):
        js.add_argument("kind", choices=("scenario", "study", "settings", "column-map"),
                        help="settings, column-map: fnn-cosim calibrate's --settings and --columns files")
        js.add_argument("--out", help="write it to this file instead")

    sub.add_parser("schema", schema, _cmd_schema, help="print the JSON Schema of a scenario, study or calibration file "
                                                       "(for editors)")
    sub.add_parser("scenarios", None, _cmd_scenarios, help="list the shipped scenarios")

    def build_fmu(b):
        b.add_argument("--out", default="build/fmus", help="output directory (default build/fmus)")

    sub.add_parser("build-fmu", build_fmu, _cmd_build_fmu, help="build every model as FMI 2.0 (and 3.0) FMUs")

    def linearize(lz):
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

    sub.add_parser("linearize", linearize, _cmd_linearize, help="linearize an FMU (Model Exchange, or a sampled-data "
                   "Co-Simulation FMU's step): system (.npz, .json), poles, Bode plots")

    # the subcommand's own module: argparse only; python-control loads when it runs
    from .stability.cli import add_parser as add_stability_parser

    add_stability_parser(sub)
    from .calibrate_cli import add_parser as add_calibrate_parser  # its own module: argparse only

    add_calibrate_parser(sub, _named_values, _overrides)
    return p


# The command's own process (main() of the command line, not a caller's main([...])) starts with Python's
# cycle collector off: start-up (imports, the parser, the master's build) makes thousands of objects that
# live as long as the process and few cycles, and the collector scanned them again and again (a tenth of a
# run's start-up). When start-up is over (_started), they are set aside for good (gc.freeze) and the
# collector runs as before on what the command makes from then on.
_START_UP = [False]


def _started() -> None:
    """Start-up is over: the cycle collector on again, what start-up made set aside (see above)."""
    if _START_UP[0]:
        _START_UP[0] = False
        gc.freeze()
        gc.enable()


def _end(code: int) -> None:
    """The command's own process ends with the command: its output flushed
    and the ``atexit`` handlers run, as Python's exit does them, then
    ``os._exit(code)``, without the interpreter's teardown, which frees
    every object of the process one by one (what the system does at once
    with the process's memory) and was a run's longest step after its loop.
    Left to Python's exit, as before, when another thread is alive (its
    exit waits for it) or the output cannot be flushed (Python's exit
    reports it and its status). Every file a command writes is closed by the
    command (docs/cosim.md, "Start-up of a run")."""
    import atexit
    import threading

    if threading.active_count() > 1:
        return
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:  # e.g. a closed pipe: Python's exit says so and exits with 120
        return
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:
        return
    os._exit(code)


def main(argv: Sequence[str] | None = None) -> int:
    """``fnn-cosim``: ``main()`` is the command's own process (the entry
    point's call), which ends the process once the command returns
    (:func:`_end`); ``main([...])`` runs a command for a caller (the tests,
    an application) and returns its exit status."""
    if argv is None and gc.isenabled():  # the process is the command: see _started
        gc.disable()
        _START_UP[0] = True
    try:
        code = _main(argv)
    except SystemExit as exc:  # argparse's end: --help, or arguments refused (exit 2)
        if argv is None and (exc.code is None or isinstance(exc.code, int)):
            code = exc.code or 0
        else:
            raise
    finally:
        _started()
        if argv is None:  # the process ends with the command: its exit need not scan what the command made
            gc.freeze()
    if argv is None:
        _end(code)
    return code


def _main(argv: Sequence[str] | None) -> int:
    from cosim.errors import ConnectionCheckError, CosimError, FmuLoadError, ScenarioError, one_line

    args = _parser().parse_args(argv)
    try:
        apply_fmu_log(getattr(args, "fmu_log", ()))
        if args.func is not _cmd_run:  # a run's start-up ends when its master is built
            _started()
        return args.func(args)
    except CosimError as exc:
        if args.debug:
            import traceback

            traceback.print_exc()
        print(f"fnn-cosim: error: {one_line(str(exc))}", file=sys.stderr)
        bad_input = isinstance(exc, (ScenarioError, ConnectionCheckError, FmuLoadError))
        return EXIT_BAD_INPUT if bad_input else EXIT_RUN_FAILED
    except KeyboardInterrupt:
        print("fnn-cosim: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a fault of ours, not of the input: still one line (the traceback with --debug)
        if args.debug:
            raise
        print(f"fnn-cosim: internal error: {type(exc).__name__}: {one_line(str(exc))[:300]} "
              f"(a bug of fnn-cosim; --debug shows where)", file=sys.stderr)
        return EXIT_RUN_FAILED


if __name__ == "__main__":
    sys.exit(main())
