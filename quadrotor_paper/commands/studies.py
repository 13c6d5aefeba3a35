"""``fnn-cosim table2``, ``table3``, ``reproduce`` and ``sweep``: studies,
many runs on Dask (:mod:`quadrotor_paper.report`, :func:`quadrotor_paper.experiments.measure`)."""
from __future__ import annotations

import argparse
from typing import Any, Sequence

from .options import overrides, TABLE_WORKERS, default_workers, worker_count
from . import DEFAULT_OUT, Commands, out_folder, output_options

__all__ = ["add_commands"]


def add_commands(commands: Commands) -> None:
    commands.add("table2", _table2_arguments, _table2, help="Table 2: every controller variant at 1, 3, 5 m/s wind")
    commands.add("table3", _table3_arguments, _table3, help="Table 3: the figure-8")
    commands.add("reproduce", _table_options, _reproduce,
                 help="Tables 2 and 3 and the figures into results/report.md")
    commands.add("sweep", _sweep_arguments, _sweep,
                 help="a study: a scenario over a grid and/or random samples of its keys")


# ---- arguments ------------------------------------------------------------------------

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
    from ..options import option_names

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


def _worker_timeout(parser: argparse.ArgumentParser) -> None:
    from cosim.limits import WORKER_TIMEOUT

    parser.add_argument("--worker-timeout", type=_seconds, default=WORKER_TIMEOUT, metavar="S",
                        help=f"stop when the Dask cluster has had no worker for S seconds (default {WORKER_TIMEOUT:g}; "
                             f"'forever': wait)")


def _table_options(sp: argparse.ArgumentParser) -> None:
    """The options of the commands that run the paper's tables: the output,
    the seeds, the cluster, the rows."""
    from fnn_controller.variants import variant_names

    from ..options import DEFAULT_OPTIONS, OPTION_SEEDS, option_names

    output_options(sp)
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


def _table2_arguments(t2: argparse.ArgumentParser) -> None:
    t2.add_argument("--winds", type=_wind_list, help="wind speeds in m/s (default: the study's, 1,3,5)")
    t2.add_argument("--scenario",
                    help="the mission (default circles; e.g. circles_sensors: the same with measurement noise)")
    t2.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help='override a scenario value, e.g. --set simulation.ordering=\'"exchange"\'')
    _table_options(t2)


def _table3_arguments(t3: argparse.ArgumentParser) -> None:
    t3.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scenario value")
    t3.add_argument("--scenario", help="the mission (default: the study's, figure8)")
    _table_options(t3)


def _sweep_arguments(sw: argparse.ArgumentParser) -> None:
    sw.add_argument("study", help="study TOML file (docs/studies.md) or a shipped study's name")
    sw.add_argument("--workers", type=worker_count, help="local worker processes, 1 to the cores (default: one "
                                                        "per core; 1: in this process)")
    sw.add_argument("--scheduler", metavar="ADDRESS",
                    help="run on the Dask cluster at ADDRESS (e.g. tcp://host:8786)")
    _worker_timeout(sw)
    sw.add_argument("--no-plots", action="store_true")
    output_options(sw)


# ---- handlers -------------------------------------------------------------------------

def _table_changes(args) -> dict[str, Any]:
    """What the command line changes in a table's study (None: as the study file says)."""
    changes = {"seeds": args.seeds, "duration": args.duration, "variants": args.variants, "options": args.options,
               "option_seeds": args.option_seeds}
    for key in ("scenario", "winds"):  # the commands that have them
        if getattr(args, key, None) is not None:
            changes[key] = getattr(args, key)
    if getattr(args, "set", None):
        changes["overrides"] = overrides(args.set)
    return changes


def _table(args, study, name: str):
    """Run the table study ``study`` (:func:`quadrotor_paper.report.table2`
    or ``table3``) as the command line says, into ``results/<name>`` or
    ``--out``; print the table and where its files are."""
    out = out_folder(args.out, DEFAULT_OUT / name)
    summary = study(out, workers=default_workers(args.workers, TABLE_WORKERS), scheduler=args.scheduler,
                    show_progress=not args.quiet, worker_timeout=args.worker_timeout, **_table_changes(args))
    print(summary["markdown"])
    print(f"{summary['rows']} runs in {summary['wall_time_s']:.1f} s; table: {out / f'{name}.md'}, "
          f"data: {out} (runs.csv, runs.parquet, summary.json)")
    return 0


def _table2(args) -> int:
    from ..report import table2

    return _table(args, table2, "table2")


def _table3(args) -> int:
    from ..report import table3

    return _table(args, table3, "table3")


def _reproduce(args) -> int:
    from ..report import reproduce

    out = out_folder(args.out, DEFAULT_OUT)
    path = reproduce(out, workers=default_workers(args.workers, TABLE_WORKERS), scheduler=args.scheduler,
                     show_progress=not args.quiet, worker_timeout=args.worker_timeout, **_table_changes(args))
    print(f"report: {path}")
    return 0


def _sweep(args) -> int:
    """A study: the base scenario over its cases and sweep, one row per run in runs.csv."""
    from cosim.files import safe_name
    from cosim.study.definition import load_study
    from cosim.study.summary import cell_lines

    from ..experiments import measure
    from ..progress import progress_bar

    study = load_study(args.study)
    out = out_folder(args.out, DEFAULT_OUT / f"study-{safe_name(study.name)}")
    with progress_bar(f"sweep {study.name}", enabled=not args.quiet) as bar:
        result = measure(study, out, workers=max(1, default_workers(args.workers)), scheduler=args.scheduler,
                         progress=bar, plots=not args.no_plots, worker_timeout=args.worker_timeout)
    counts = ", ".join(f"{n} {status}" for status, n in sorted(result.counts.items())) or "nothing to run"
    print("\n".join(cell_lines(result.summary)))
    print(f"{study.name}: {result.total} runs ({result.skipped} already done); this time: {counts}")
    print(f"results: {out} (runs.csv, runs.parquet, summary.json" + ", plots" * (not args.no_plots) + ")")
    return 0
