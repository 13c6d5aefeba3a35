"""The reproduction: Table 2, Table 3 and the figures, into one report.

:func:`table2` and :func:`table3` run the sweeps (through the engine's
runner, :mod:`cosim.dask_runner`: in this process for one worker, else on
Dask) and write ``table2.md`` /
``table3.md`` and a ``summary.json`` (every cell's mean, std and runs, every
run's RMSE and wall time). :func:`figures` runs the single missions the
figures need (with their CSV) and draws them. :func:`reproduce` does all three
and writes ``report.md`` and ``summary.json`` beside them.
"""
from __future__ import annotations

import datetime as _dt
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from . import plots
from fnn_controller.variants import variant, variant_names

from .experiments import Job, cells, run_once, sweep, write_json
from .options import DEFAULT_OPTIONS, OPTION_SEEDS, check_options
from .metrics import pd_share, rmse
from .missions import metric_signals
from cosim.progress import Progress
from cosim.scenario import Scenario, load_scenario
from .tables import DEVIATION_LIMIT, PAPER_TABLE2, PAPER_TABLE3, deviations, table2_markdown, table3_markdown

__all__ = ["table2", "table3", "figures", "reproduce"]


def _sweep_with_progress(scenario: Scenario, jobs: Sequence[Job], workers: int, label: str, show: bool,
                         scheduler: str | None = None):
    bar = Progress(len(jobs), label, enabled=show)
    t = time.perf_counter()
    results = sweep(scenario, jobs, workers, progress=lambda r: bar.update(), scheduler=scheduler)
    bar.close()
    return results, time.perf_counter() - t


def _overrides(duration: float | None, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    return {**(overrides or {}), **({"simulation.duration": duration} if duration else {})}


def _variants(names: Sequence[str] | None) -> tuple[str, ...]:
    """The variants to run, checked before any run starts (a ``ValueError``
    naming an unknown one)."""
    if names is None:
        return variant_names()
    for name in names:
        variant(name)
    if not names:
        raise ValueError("variants: empty list; give at least one of " + ", ".join(variant_names()))
    return tuple(dict.fromkeys(names))


def _option_jobs(options: Sequence[str], option_seeds: int | None, seeds: int, winds) -> list[Job]:
    """The jobs of the option rows: each option at each wind, ``option_seeds``
    seeds (default: ``seeds``, at most :data:`OPTION_SEEDS`), after the paper's."""
    n = min(seeds, OPTION_SEEDS) if option_seeds is None else option_seeds
    if n < 1 and options:
        raise ValueError(f"option_seeds = {n}: at least 1 run per option cell")
    return [Job.of_option(o, w, s) for s in range(n) for w in winds for o in check_options(options)]


def table2(out_dir: Path, seeds: int = 10, winds: Sequence[float] = (1.0, 3.0, 5.0), duration: float | None = None,
           workers: int = 2, scenario: str = "circles", show_progress: bool = True,
           overrides: Mapping[str, Any] | None = None, scheduler: str | None = None,
           variants: Sequence[str] | None = None, options: Sequence[str] = DEFAULT_OPTIONS,
           option_seeds: int | None = None) -> dict[str, Any]:
    """Table 2: each of ``variants`` (default: every registered one) at every
    wind speed, ``seeds`` runs each (``overrides``: dotted scenario keys, e.g.
    the master's ordering; the runs on ``workers`` local processes, or on the
    Dask cluster at ``scheduler``); then the option rows ``options``
    (:mod:`quadrotor_paper.options`), ``option_seeds`` runs each (default
    ``min(seeds, OPTION_SEEDS)``)."""
    sc = load_scenario(scenario, _overrides(duration, overrides))
    jobs = [Job(v, float(w), s) for s in range(seeds) for w in winds for v in _variants(variants)]
    jobs += _option_jobs(options, option_seeds, seeds, [float(w) for w in winds])
    results, wall = _sweep_with_progress(sc, jobs, workers, "table2", show_progress, scheduler)
    table = cells(results)
    md = table2_markdown(table, tuple(float(w) for w in winds))
    summary = {
        "table": 2, "scenario": sc.name, "duration_s": sc.duration, "seeds": list(range(seeds)),
        "winds_m_s": [float(w) for w in winds], "workers": workers, "wall_time_s": wall,
        "cells": {v: {f"{w:g}": c for w, c in by.items()} for v, by in table.items()},
        "paper": {v: {f"{w:g}": x for w, x in by.items()} for v, by in PAPER_TABLE2.items()},
        "options": {o: job_option_summary(o) for o in dict.fromkeys(j.option for j in jobs if j.option)},
        "runs": results,
    }
    return _write_table(out_dir, 2, sc.description, md, table, summary)


def table3(out_dir: Path, seeds: int = 10, duration: float | None = None, workers: int = 2,
           scenario: str = "figure8", show_progress: bool = True,
           overrides: Mapping[str, Any] | None = None, scheduler: str | None = None,
           variants: Sequence[str] | None = None, options: Sequence[str] = DEFAULT_OPTIONS,
           option_seeds: int | None = None) -> dict[str, Any]:
    """Table 3: each of ``variants`` (default: every registered one) on the
    figure-8, ``seeds`` runs each; then the option rows as in :func:`table2`."""
    sc = load_scenario(scenario, _overrides(duration, overrides))
    jobs = [Job(v, None, s) for s in range(seeds) for v in _variants(variants)]
    jobs += _option_jobs(options, option_seeds, seeds, [None])
    results, wall = _sweep_with_progress(sc, jobs, workers, "table3", show_progress, scheduler)
    table = cells(results)
    md = table3_markdown(table)
    summary = {
        "table": 3, "scenario": sc.name, "duration_s": sc.duration, "seeds": list(range(seeds)),
        "workers": workers, "wall_time_s": wall,
        "cells": {v: next(iter(by.values())) for v, by in table.items()}, "paper": PAPER_TABLE3,
        "options": {o: job_option_summary(o) for o in dict.fromkeys(j.option for j in jobs if j.option)},
        "runs": results,
    }
    return _write_table(out_dir, 3, sc.description, md, table, summary)


def job_option_summary(name: str) -> dict[str, Any]:
    """What an option row flew, for ``summary.json``: label, variant, overrides, connections."""
    from .options import option

    o = option(name)
    return {"label": o.label, "variant": o.variant, "overrides": dict(o.overrides), "connections": list(o.connections)}


def _write_table(out_dir, number: int, description: str, md: str, table, summary: dict[str, Any]) -> dict[str, Any]:
    """Write ``table<number>.md`` and ``summary.json``; return the summary with
    the markdown and the float-keyed cells added for the caller."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / f"table{number}.md").write_text(f"# Table {number}: {description}\n\n{md}")
    write_json(out_dir / "summary.json", summary)
    summary["markdown"] = md
    summary["cells_by_float"] = table
    return summary


def _share_stats(result, early=(0.0, 5.0), late_seconds: float = 10.0) -> dict[str, dict[str, float]]:
    """Mean PD share |tau_c| / (|tau_c| + |tau_n|) per axis early and late in the run."""
    t = result.time
    out = {}
    for a in "xyz":
        share = pd_share(result[f"controller.tau_c_{a}"], result[f"controller.tau_n_{a}"])
        first = (t >= early[0]) & (t < early[1])
        last = t >= t[-1] - late_seconds
        out[a] = {"first_5s": float(share[first].mean()), "last_10s": float(share[last].mean())}
    return out


def figures(out_dir: Path, wind: float = 3.0, seed: int = 0, duration: float | None = None,
            show_progress: bool = True) -> dict[str, Any]:
    """The single runs behind Figs. 5-9 (circles, 3 m/s) and 11-12 (figure-8), and the figures."""
    out_dir = Path(out_dir)
    info: dict[str, Any] = {"runs": {}, "files": []}
    for name, label in (("circles", "circles"), ("figure8", "figure8")):
        overrides = _overrides(duration)
        if name == "circles":
            overrides["wind.speed"] = wind
        sc = load_scenario(name, overrides)
        results = {}
        bar = Progress(len(variant_names()), f"figures ({name})", enabled=show_progress)
        for v in variant_names():
            run_dir = out_dir / "runs" / f"{label}-{v.replace('+', '_')}"
            result, summary = run_once(sc, run_dir, seed=seed, variant=v)
            write_json(run_dir / "summary.json", summary)
            results[v] = result
            entry = dict(summary)
            if result.status == "ok" and "controller.tau_c_x" in result.columns and v != "pd":
                entry["pd_share"] = _share_stats(result)
            info["runs"][f"{label}/{v}"] = entry
            bar.update()
        bar.close()
        pos, ref = metric_signals(sc)
        if name == "circles":
            info["files"].append(plots.wind_profile(out_dir / "fig5_wind_profile.png",
                                                    plots.wind_series(sc, (1.0, 3.0, 5.0))))
            info["files"].append(plots.trajectories_3d(out_dir / "fig6_trajectories.png", results, pos, ref,
                                                       f"Trajectory tracking, v_w = {wind:g} m/s (paper Fig. 6)"))
            info["files"].append(plots.control_signals(out_dir / "fig7_pd_smc_signals.png", results["pd+smc"],
                                                       "pd+smc", f"PD and SMC-FNN outputs, v_w = {wind:g} m/s "
                                                       "(paper Fig. 7)"))
            info["files"].append(plots.control_signals(out_dir / "fig8_pd_lm_signals.png", results["pd+lm"],
                                                       "pd+lm", f"PD and LM-FNN outputs, v_w = {wind:g} m/s "
                                                       "(paper Fig. 8)"))
            info["files"].append(plots.euclidean_errors(out_dir / "fig9_euclidean_error.png", results, pos, ref,
                                                        f"Euclidean error, v_w = {wind:g} m/s (paper Fig. 9)"))
        else:
            info["files"].append(plots.trajectories_3d(out_dir / "fig11_figure8_trajectories.png", results, pos, ref,
                                                       "Figure-8, 2 m/s wind (paper Fig. 11, simulated)"))
            info["files"].append(plots.euclidean_errors(out_dir / "fig12_figure8_error.png", results, pos, ref,
                                                        "Figure-8: Euclidean error (paper Fig. 12, simulated)"))
            info["files"].append(plots.control_signals(out_dir / "fig14_figure8_pd_lm_signals.png",
                                                       results["pd+lm"], "pd+lm",
                                                       "Figure-8: PD and LM-FNN outputs (paper Fig. 14, simulated)"))
    info["files"] = [str(p) for p in info["files"]]
    return info


def _share_table(fig_info: dict[str, Any]) -> str:
    lines = ["| run | axis | PD share, first 5 s | PD share, last 10 s |", "|---|---|---|---|"]
    for key, run in fig_info["runs"].items():
        for axis, s in (run.get("pd_share") or {}).items():
            lines.append(f"| {key} | {axis} | {s['first_5s']:.2f} | {s['last_10s']:.2f} |")
    return "\n".join(lines) + "\n"


def _option_note(options: Sequence[str], option_seeds: int | None, seeds: int) -> str:
    if not options:
        return ""
    n = min(seeds, OPTION_SEEDS) if option_seeds is None else option_seeds
    return (f"; {n} per cell of the option rows ({', '.join(options)}: settings beyond the paper, "
            "quadrotor_paper/options.py, docs/results.md)")


def reproduce(out_dir: Path, seeds: int = 10, workers: int = 2, duration: float | None = None,
              show_progress: bool = True, scheduler: str | None = None,
              variants: Sequence[str] | None = None, options: Sequence[str] = DEFAULT_OPTIONS,
              option_seeds: int | None = None) -> Path:
    """Table 2, Table 3 (rows: ``variants``, default every registered one,
    then the option rows ``options``, default :data:`DEFAULT_OPTIONS` with
    ``min(seeds, OPTION_SEEDS)`` seeds each) and the figures; returns the
    path of ``report.md``."""
    out_dir = Path(out_dir)
    t0 = time.perf_counter()
    options = check_options(options)  # before any run
    t2 = table2(out_dir / "table2", seeds=seeds, duration=duration, workers=workers, show_progress=show_progress,
                scheduler=scheduler, variants=variants, options=options, option_seeds=option_seeds)
    t3 = table3(out_dir / "table3", seeds=seeds, duration=duration, workers=workers, show_progress=show_progress,
                scheduler=scheduler, variants=variants, options=options, option_seeds=option_seeds)
    figs = figures(out_dir / "figures", duration=duration, show_progress=show_progress)
    devs = deviations(t2["cells_by_float"], t3["cells_by_float"])
    wall = time.perf_counter() - t0

    rel = lambda p: os.path.relpath(p, out_dir)  # noqa: E731
    fig_lines = "\n\n".join(f"![{Path(p).stem}]({rel(p)})" for p in figs["files"])
    dev_lines = "\n".join(
        f"- Table {d['table']}, {d['variant']}" + (f" at {d['wind_m_s']:g} m/s" if "wind_m_s" in d else "")
        + f": ours {d['ours']:.3f} m vs paper {d['paper']:.3f} m ({d['relative']:+.0%})" for d in devs) or "- none"
    fig_runs = "\n".join(f"| {k} | {r['status']} | {r.get('rmse_m', float('nan')):.3f} | {r['wall_time_s']:.3f} |"
                         for k, r in figs["runs"].items())
    report = f"""# Reproduction of Tables 2 and 3 (Sarabakha & Kayacan, LM-FNN)

Generated {_dt.datetime.now().isoformat(timespec='seconds')} by `fnn-cosim reproduce` in {wall:.1f} s
(Python {platform.python_version()}, {os.cpu_count()} cores, {workers} worker processes; {seeds} seeds per cell
of the paper's rows{_option_note(options, option_seeds, seeds)}).
The plant is the Quadrotor FMU, the wind the WindGust FMU, co-simulated with the controller of
`fnn_controller` by the `cosim` master (docs/cosim.md). Machine-readable: `summary.json` here,
`table2/summary.json`, `table3/summary.json`, `figures/runs/*/summary.json`. Discussion of every
difference from the paper: docs/results.md.

## Table 2: simulation, two circles at 2.5 m/s in a periodic gust ({t2['duration_s']:g} s, {t2['wall_time_s']:.1f} s for {len(t2['runs'])} runs)

{t2['markdown']}
## Table 3: figure-8 at up to 1 m/s in a 2 m/s wind ({t3['duration_s']:g} s, simulated; the paper's are flights)

{t3['markdown']}
## Cells more than {DEVIATION_LIMIT:.0%} away from the paper

{dev_lines}

## Figures (seed 0; Figs. 5-9 at v_w = 3 m/s)

| run | status | RMSE (m) | wall time (s) |
|---|---|---|---|
{fig_runs}

Share of the PD in the control effort, |tau_c| / (|tau_c| + |tau_n|) per axis (Figs. 7-8: it should fall
toward zero as the FNN learns):

{_share_table(figs)}
{fig_lines}
"""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "report.md"
    path.write_text(report)
    strip = lambda s: {k: v for k, v in s.items() if k not in ("markdown", "cells_by_float")}  # noqa: E731
    write_json(out_dir / "summary.json", {"wall_time_s": wall, "table2": strip(t2), "table3": strip(t3),
                                          "figures": figs, "deviations": devs})
    return path
