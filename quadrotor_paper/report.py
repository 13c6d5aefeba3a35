"""The reproduction: Table 2, Table 3 and the figures, into one report.

:func:`table2` and :func:`table3` run the shipped studies ``table2`` and
``table3`` (``quadrotor_paper/studies/``; :func:`table_study` changes their
seeds, winds, rows or mission as the command line asks) through
:func:`~quadrotor_paper.experiments.measure` (in this process for one worker,
else on Dask) and write the study's results layout (``runs.csv``,
``runs.parquet``, ``summary.json``) and ``table2.md`` / ``table3.md``.
:func:`figures` runs the single missions the figures need (with their CSV)
and draws them. :func:`reproduce` does all three and writes ``report.md``
and ``summary.json`` beside them.
"""
from __future__ import annotations

import datetime as _dt
import os
import platform
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

from cosim.scenario import registry
from cosim.limits import WORKER_TIMEOUT
from cosim.files import read_toml
from cosim.scenario.definition import load_scenario
from cosim.study.definition import Study, parse_study, study_path
from cosim.study.run import write_json
from fnn_controller.variants import variant, variant_names

from .experiments import measure, run_once
from .metrics import pd_share
from .sections import metric_signals
from .options import OPTION_SEEDS, OPTIONS, variant_case
from .progress import progress_bar
from .tables import DEVIATION_LIMIT, WIND_KEY, deviations, table2_markdown, table3_markdown

__all__ = ["table_study", "table2", "table3", "figures", "reproduce"]



def table_study(number: int, *, scenario: str | None = None, seeds: int | None = None,
                winds: Sequence[float] | None = None, duration: float | None = None,
                overrides: Mapping[str, Any] | None = None, variants: Sequence[str] | None = None,
                options: Sequence[str] | None = None, option_seeds: int | None = None) -> Study:
    """The shipped study ``table<number>``, changed where an argument is given:
    the mission (``scenario``, ``duration``, ``overrides``: dotted keys), the
    seeds of the variant rows (0..``seeds``-1), Table 2's wind speeds, the
    variant rows (``variants``) and the option rows (``options``) with their
    seeds (``option_seeds``, default: the smaller of ``seeds`` and
    :data:`OPTION_SEEDS`). With no argument it is the study file's, run for
    run (``fnn-cosim sweep table2`` runs the same runs). Every value is
    checked as the study file's are (a bad wind speed names its key)."""
    path = study_path(f"table{number}")
    raw = read_toml(path, "study")
    base = None
    if scenario is not None or duration is not None or overrides:
        base = load_scenario(scenario or raw["scenario"],
                             {**(overrides or {}), **({"simulation.duration": duration} if duration is not None else {})})
    cases = dict(raw.get("cases", {}))
    sweep = raw.setdefault("sweep", {})
    if seeds is not None:
        sweep["seeds"] = seeds
        if option_seeds is None and seeds >= 1:  # (a bad --seeds is refused by the study, naming sweep.seeds)
            option_seeds = min(seeds, OPTION_SEEDS)
    if option_seeds is not None:
        cases = {name: ({**spec, "seeds": option_seeds} if name in OPTIONS else spec) for name, spec in cases.items()}
    if variants is not None:
        for name in variants:  # a variant registered after the plugins were loaded gets its case now
            variant(name)
            if name not in registry.cases():
                registry.register_case(variant_case(name))
        cases = {**{name: {} for name in variants}, **{n: s for n, s in cases.items() if n in OPTIONS}}
    if options is not None:
        extra = {} if option_seeds is None else {"seeds": option_seeds}
        cases = {**{n: s for n, s in cases.items() if n not in OPTIONS},
                 **{name: cases.get(name, {"seeds": OPTION_SEEDS}) | extra for name in options}}
    raw["cases"] = cases
    if winds is not None:
        sweep.setdefault("grid", {})[WIND_KEY] = list(winds)
    return parse_study(raw, source=path, base=base)


def _run_table(number: int, study: Study, out_dir: Path, workers: int, scheduler: str | None,
               show_progress: bool, worker_timeout: float | None = WORKER_TIMEOUT) -> dict[str, Any]:
    """Run a table's study into ``out_dir`` (afresh) and write ``table<number>.md``;
    returns the summary with its markdown."""
    with progress_bar(f"table{number}", enabled=show_progress) as bar:
        result = measure(study, out_dir, workers=workers, scheduler=scheduler, progress=bar, resume=False,
                         worker_timeout=worker_timeout)
    summary = result.summary
    md = (table2_markdown if number == 2 else table3_markdown)(summary)
    (Path(out_dir) / f"table{number}.md").write_text(f"# Table {number}: {study.description}\n\n{md}")
    return {**summary, "markdown": md}


def table2(out_dir: Path, workers: int = 2, scheduler: str | None = None, show_progress: bool = True,
           worker_timeout: float | None = WORKER_TIMEOUT, **changes) -> dict[str, Any]:
    """Table 2: the study :func:`table_study` ``(2, **changes)`` run on
    ``workers`` local processes (or on the Dask cluster at ``scheduler``)."""
    return _run_table(2, table_study(2, **changes), out_dir, workers, scheduler, show_progress, worker_timeout)


def table3(out_dir: Path, workers: int = 2, scheduler: str | None = None, show_progress: bool = True,
           worker_timeout: float | None = WORKER_TIMEOUT, **changes) -> dict[str, Any]:
    """Table 3: the study :func:`table_study` ``(3, **changes)`` (no wind speeds)."""
    return _run_table(3, table_study(3, **changes), out_dir, workers, scheduler, show_progress, worker_timeout)


def _share_stats(result, early=(0.0, 5.0), late_seconds: float = 10.0) -> dict[str, dict[str, float]]:
    """Mean PD share |tau_c| / (|tau_c| + |tau_n|) per axis early and late in the run
    (over the rows the run kept: every row of the figures' missions; evenly
    thinned beyond :data:`~quadrotor_paper.experiments.PLOT_ROWS`)."""
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
    from . import plots  # matplotlib: loaded by what draws, not by fnn-cosim table2 / table3

    out_dir = Path(out_dir)
    info: dict[str, Any] = {"runs": {}, "files": []}
    for name, label in (("circles", "circles"), ("figure8", "figure8")):
        overrides: dict[str, Any] = {"simulation.duration": duration} if duration is not None else {}
        if name == "circles":
            overrides["wind.speed"] = wind
        results = {}
        with progress_bar(f"figures ({name})", total=len(variant_names()), enabled=show_progress) as bar:
            for v in variant_names():
                sc = load_scenario(name, {**overrides, "controller.variant": v})
                run_dir = out_dir / "runs" / f"{label}-{v.replace('+', '_')}"
                result, summary = run_once(sc, run_dir, seed=seed)
                write_json(run_dir / "summary.json", summary)
                results[v] = result
                entry = dict(summary)
                if result.status == "ok" and "controller.tau_c_x" in result.columns and v != "pd":
                    entry["pd_share"] = _share_stats(result)
                info["runs"][f"{label}/{v}"] = entry
                bar(len(results), len(variant_names()))
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


def _seed_note(summary: Mapping[str, Any]) -> str:
    """How many runs each cell of a table's rows had: the variants', the option rows'."""
    runs = lambda rows: "/".join(str(n) for n in sorted({c["runs"] for c in summary["cells"]  # noqa: E731
                                                         if (c["case"] in OPTIONS) == rows}))
    text = f"{runs(False)} seeds per cell of the paper's rows"
    options = [c["name"] for c in summary["cases"] if c["name"] in OPTIONS]
    if options:
        text += (f"; {runs(True)} per cell of the option rows ({', '.join(options)}: settings beyond the paper, "
                 "quadrotor_paper/options.py, docs/results.md)")
    return text


def reproduce(out_dir: Path, workers: int = 2, scheduler: str | None = None, show_progress: bool = True,
              worker_timeout: float | None = WORKER_TIMEOUT, **changes) -> Path:
    """Table 2, Table 3 (their studies, changed by ``changes`` as
    :func:`table_study` takes them, checked before any run) and the figures;
    returns the path of ``report.md``."""
    out_dir = Path(out_dir)
    t0 = time.perf_counter()
    studies = {n: table_study(n, **({k: v for k, v in changes.items() if k != "winds"} if n == 3 else changes))
               for n in (2, 3)}  # both checked before any run
    t2 = _run_table(2, studies[2], out_dir / "table2", workers, scheduler, show_progress, worker_timeout)
    t3 = _run_table(3, studies[3], out_dir / "table3", workers, scheduler, show_progress, worker_timeout)
    figs = figures(out_dir / "figures", duration=changes.get("duration"), show_progress=show_progress)
    devs = deviations(t2, t3)
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
(Python {platform.python_version()}, {os.cpu_count()} cores, {workers} worker processes; {_seed_note(t2)}).
The plant is the Quadrotor FMU, the wind the WindGust FMU, co-simulated with the controller of
`fnn_controller` by the `cosim` master (docs/cosim.md). Each table is a study (`quadrotor_paper/studies/`):
`table2/` and `table3/` hold its runs (`runs.csv`, `runs.parquet`) and `summary.json`; `summary.json`
here and `figures/runs/*/summary.json` the rest. Discussion of every difference from the paper:
docs/results.md.

## Table 2: simulation, two circles at 2.5 m/s in a periodic gust ({t2['duration_s']:g} s, {t2['wall_time_s']:.1f} s for {t2['rows']} runs)

{t2['markdown']}
## Table 3: figure-8 at up to 1 m/s in a 2 m/s wind ({t3['duration_s']:g} s, {t3['wall_time_s']:.1f} s for {t3['rows']} runs; simulated, the paper's are flights)

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
    strip = lambda s: {k: v for k, v in s.items() if k != "markdown"}  # noqa: E731
    write_json(out_dir / "summary.json", {"wall_time_s": wall, "table2": strip(t2), "table3": strip(t3),
                                          "figures": figs, "deviations": devs})
    return path
