"""Studies: one base scenario run over a sweep of its keys, into one tidy table.

A study file (TOML; full description in ``docs/studies.md``)::

    scenario = "circles"                  # required: a shipped scenario name or a path
                                          #   (relative to the study file)
    name = "wind_and_mass"                # default: the file name
    description = "..."

    [set]                                 # dotted scenario keys set for every run
    "simulation.duration" = 20.0

    [sweep]
    seeds = 10                            # simulation.seed 0..9 for each point, or a list [0, 4, 7];
                                          #   default: the scenario's seed only
    [sweep.grid]                          # the cartesian product of the lists
    "controller.variant" = ["pd", "pd+smc", "pd+lm"]
    "wind.speed" = [1.0, 3.0, 5.0]

    [sweep.random]                        # `samples` draws of every key, crossed with the grid
    samples = 20
    seed = 0                              # numpy.random.default_rng(seed), keys drawn in file order
    "fmus.Quadrotor.parameters.m" = { uniform = [0.856, 1.284] }   # [low, high)
    "wind.turbulence" = { normal = [0.5, 0.1] }                      # [mean, std]
    "trajectory.speed" = { choice = [2.0, 2.5] }                     # [values...]

A run is (grid point, random sample, seed): the plan is ordered grid point,
then sample, then seed. Every run is one row of ``runs.csv``: ``run`` (its
index in the plan), ``sample`` (the random draw's index, empty without
``[sweep.random]``), ``seed``, one column per swept key (its value),
``status``, ``error``, one column per metric, ``wall_time_s``. Rows are
appended (and flushed) as runs finish, in any order. At the end
``runs.parquet`` is written from the CSV (pyarrow), ``summary.csv`` (one row
per grid point: runs, ok, failed; per metric over the runs that finished
``ok``: mean, std, the 95 % t-interval of the mean), and box and line plots.

Resume: a row already in ``runs.csv`` of the same output folder (matched by
its swept values and seed, as written) is not run again; a half-written last
line (a killed study) is dropped first.

Errors in the study file are :class:`~cosim.errors.ScenarioError` naming the
key, e.g. ``sweep.random."wind.speed".uniform = [3, 1]: expected [low, high]
with low < high``.
"""
from __future__ import annotations

import csv
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from .errors import CosimError, ScenarioError
from .config import check_number
from .scenario import (Scenario, apply_overrides, load_scenario, parse_scenario, read_toml, refuse_unknown,
                       scenario_path, string, table)

__all__ = ["Study", "parse_study", "load_study", "plan", "run_study", "summarize_runs", "read_runs",
           "DISTRIBUTIONS", "FIXED_COLUMNS"]

DISTRIBUTIONS = ("uniform", "normal", "choice")
_TOP = {"scenario", "name", "description", "set", "sweep"}
_SWEEP = {"grid", "random", "seeds"}
FIXED_COLUMNS = ("run", "sample", "seed")


@dataclass
class Study:
    name: str
    description: str
    scenario: Scenario  # the base scenario with [set] applied
    grid: dict[str, list[Any]] = field(default_factory=dict)
    random: dict[str, tuple[str, list[Any]]] = field(default_factory=dict)
    samples: int = 0
    random_seed: int = 0
    seeds: list[int] | None = None  # None: the scenario's own seed
    source: Path | None = None

    @property
    def keys(self) -> list[str]:
        """The swept keys, grid first, in file order."""
        return list(self.grid) + [k for k in self.random if k not in self.grid]


@dataclass(frozen=True)
class Run:
    index: int
    sample: int | None
    seed: int
    values: dict[str, Any]  # swept key -> value
    grid_point: tuple


# ---- reading ------------------------------------------------------------------------------

def _q(key: str) -> str:
    return f'"{key}"' if "." in key else key


def _count(where: str, value: Any, positive: bool = False) -> int:
    """A whole number >= 0 (``positive``: >= 1), or the scenario's error naming ``where``."""
    return int(check_number(where, value, integer=True, positive=positive, nonnegative=not positive))


def _distribution(where: str, spec: Any) -> tuple[str, list[Any]]:
    if not isinstance(spec, Mapping) or len(spec) != 1 or next(iter(spec)) not in DISTRIBUTIONS:
        raise ScenarioError(f"{where} = {spec!r}: expected one of {{ uniform = [low, high] }}, "
                            f"{{ normal = [mean, std] }}, {{ choice = [values...] }}")
    kind, args = next(iter(spec.items()))
    where = f"{where}.{kind}"
    if kind == "choice":
        if not isinstance(args, list) or not args:
            raise ScenarioError(f"{where} = {args!r}: expected a non-empty list of values")
        return kind, list(args)
    if not isinstance(args, list) or len(args) != 2:
        raise ScenarioError(f"{where} = {args!r}: expected [{'low, high' if kind == 'uniform' else 'mean, std'}]")
    a, b = (float(check_number(f"{where}[{i}]", v)) for i, v in enumerate(args))
    if kind == "uniform" and not a < b:
        raise ScenarioError(f"{where} = {args!r}: expected [low, high] with low < high")
    if kind == "normal" and b < 0:
        raise ScenarioError(f"{where} = {args!r}: expected [mean, std] with std >= 0")
    return kind, [a, b]


def _check_key(where: str, base_raw: Mapping[str, Any], source: Path | None, key: str, value: Any) -> None:
    """Refuse a swept key the scenario does not take, naming the study key."""
    try:
        parse_scenario(apply_overrides(dict(base_raw), {key: value}), source=source)
    except CosimError as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def parse_study(raw: Mapping[str, Any], source: Path | None = None) -> Study:
    """Validate a study given as a mapping (a parsed TOML document)."""
    raw = dict(raw)
    refuse_unknown("", raw, _TOP)
    if "scenario" not in raw or not isinstance(raw["scenario"], str):
        raise ScenarioError(f"scenario = {raw.get('scenario')!r}: required, a shipped scenario name or a file path")
    name = string("name", raw.get("name", source.stem if source else "study"))
    if not name:
        raise ScenarioError("name = '': expected a non-empty string")
    description = string("description", raw.get("description", ""))
    path = Path(raw["scenario"])
    if not path.is_absolute() and source is not None and (source.parent / path).exists():
        path = source.parent / path
    try:
        scenario_file = scenario_path(path if path.exists() else raw["scenario"])
    except ScenarioError as exc:
        raise ScenarioError(f"scenario = {raw['scenario']!r}: {exc}") from None
    fixed = table("set", raw.get("set", {}))
    try:
        base = load_scenario(scenario_file, dict(fixed))
    except ScenarioError as exc:
        raise ScenarioError(f"set: {exc}") from None

    sweep = table("sweep", raw.get("sweep", {}))
    refuse_unknown("sweep.", sweep, _SWEEP)
    study = Study(name=name, description=description, scenario=base, source=source)

    seeds = sweep.get("seeds")
    if seeds is not None:
        if isinstance(seeds, list):
            study.seeds = [_count(f"sweep.seeds[{i}]", s) for i, s in enumerate(seeds)]
            if not study.seeds or len(set(study.seeds)) != len(study.seeds):
                raise ScenarioError(f"sweep.seeds = {seeds!r}: expected distinct seeds, at least one")
        else:
            study.seeds = list(range(_count("sweep.seeds", seeds, positive=True)))
        _check_key("sweep.seeds", base.raw, base.source, "simulation.seed", study.seeds[0])

    grid = table("sweep.grid", sweep.get("grid", {}))
    for key, values in grid.items():
        where = f"sweep.grid.{_q(key)}"
        if key == "simulation.seed":
            raise ScenarioError(f"{where}: sweep seeds with sweep.seeds")
        if not isinstance(values, list) or not values:
            raise ScenarioError(f"{where} = {values!r}: expected a non-empty list of values")
        for value in values:
            _check_key(where, base.raw, base.source, key, value)
        study.grid[key] = list(values)

    rand = sweep.get("random")
    if rand is not None:
        rand = table("sweep.random", rand)
        if "samples" not in rand:
            raise ScenarioError("sweep.random.samples: required, the number of draws")
        study.samples = _count("sweep.random.samples", rand["samples"], positive=True)
        study.random_seed = _count("sweep.random.seed", rand.get("seed", 0))
        for key, spec in rand.items():
            if key in ("samples", "seed"):
                continue
            where = f"sweep.random.{_q(key)}"
            if key in study.grid:
                raise ScenarioError(f"{where}: already swept in sweep.grid")
            if key == "simulation.seed":
                raise ScenarioError(f"{where}: sweep seeds with sweep.seeds")
            study.random[key] = _distribution(where, spec)
            kind, args = study.random[key]
            for value in (args if kind == "choice" else [args[0]]):
                _check_key(where, base.raw, base.source, key, value)
        if not study.random:
            raise ScenarioError("sweep.random: no key to draw (add e.g. \"wind.speed\" = { uniform = [1.0, 5.0] })")
    return study


def load_study(path: str | Path) -> Study:
    path = Path(path)
    if not path.exists():
        raise ScenarioError(f"study {str(path)!r}: no such file")
    return parse_study(read_toml(path), source=path)


# ---- the plan -----------------------------------------------------------------------------

def _draws(study: Study) -> list[dict[str, Any]]:
    rng = np.random.default_rng(study.random_seed)
    out = []
    for _ in range(study.samples):
        draw = {}
        for key, (kind, args) in study.random.items():
            if kind == "uniform":
                draw[key] = float(rng.uniform(args[0], args[1]))
            elif kind == "normal":
                draw[key] = float(rng.normal(args[0], args[1]))
            else:
                draw[key] = args[int(rng.integers(len(args)))]
        out.append(draw)
    return out


def plan(study: Study) -> list[Run]:
    """Every run of the study, ordered grid point, sample, seed."""
    points = [dict(zip(study.grid, combo)) for combo in itertools.product(*study.grid.values())]
    draws: list[tuple[int | None, dict[str, Any]]] = list(enumerate(_draws(study))) if study.random else [(None, {})]
    seeds = study.seeds if study.seeds is not None else [study.scenario.seed]
    runs = []
    for point in points:
        for sample, draw in draws:
            for seed in seeds:
                runs.append(Run(len(runs), sample, seed, {**point, **draw}, tuple(point.values())))
    return runs


# ---- the table ------------------------------------------------------------------------------

def _cell(value: Any) -> str:
    """A value as written in runs.csv (and compared on resume)."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, dict)):
        return json.dumps(value, sort_keys=True)
    return str(value)


def columns(study: Study, metric_names: Sequence[str]) -> list[str]:
    return [*FIXED_COLUMNS, *study.keys, "status", "error", *metric_names, "wall_time_s"]


def _match(values: Mapping[str, Any], seed: Any, keys: Sequence[str]) -> tuple[str, ...]:
    return tuple(_cell(values.get(k)) for k in keys) + (_cell(seed),)


def read_runs(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _prepare(path: Path, header: list[str]) -> list[dict[str, str]]:
    """The rows already in ``path`` (a half-written last line dropped);
    refuses a file of another study (other columns)."""
    if not path.exists() or path.stat().st_size == 0:
        return []
    data = path.read_bytes()
    if not data.endswith(b"\n"):  # killed while writing a row
        data = data[: data.rfind(b"\n") + 1]
        path.write_bytes(data)
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames != header:
            raise ScenarioError(f"{path}: holds the runs of another study (columns {reader.fieldnames}); "
                                f"choose another --out")
        return list(reader)


@dataclass
class StudyResult:
    out_dir: Path
    total: int
    skipped: int
    counts: dict[str, int]
    files: list[Path]


def run_study(study: Study, out_dir: str | Path, workers: int = 1, scheduler: str | None = None,
              metrics: Callable[[Scenario, Any], Mapping[str, Any]] | None = None,
              metric_names: Sequence[str] = (), record: Sequence[str] | None = None,
              progress: Callable[[int, int], None] | None = None, plots: bool = True) -> StudyResult:
    """Run the runs of ``study`` not yet in ``out_dir/runs.csv``, appending
    a row as each finishes; then write ``runs.parquet``, ``summary.csv`` and
    the plots. ``metrics(scenario, result)`` gives the metric columns
    ``metric_names`` of a row (runs on the workers: a module-level function);
    ``record`` replaces the recorded signals (e.g. only what the metrics
    read). ``progress(done, total)`` before the first run, then after each row."""
    from .dask_runner import Task, run_tasks

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    header = columns(study, metric_names)
    runs_csv = out / "runs.csv"
    keys = study.keys
    existing = _prepare(runs_csv, header)
    done = {_match(row, row["seed"], keys) for row in existing}
    planned = plan(study)
    todo = [r for r in planned if _match(r.values, r.seed, keys) not in done]
    total = len(todo)

    base = study.scenario
    if record is not None:
        base = parse_scenario(apply_overrides(base.raw, {"record.signals": list(record)}), source=base.source)
    by_index = {r.index: r for r in todo}
    tasks = (Task(r.index, r.values, {}, r.seed) for r in todo)
    counts: dict[str, int] = {}
    new = not runs_csv.exists() or runs_csv.stat().st_size == 0
    with open(runs_csv, "a", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        if new:
            writer.writerow(header)
            f.flush()
        if progress is not None:
            progress(0, total)
        for n, rec in enumerate(run_tasks(base, tasks, workers=workers, scheduler=scheduler, metrics=metrics), 1):
            run = by_index[rec["key"]]
            row = {"run": run.index, "sample": run.sample, "seed": run.seed, **run.values,
                   "status": rec["status"], "error": rec["error"], "wall_time_s": rec["wall_time_s"],
                   **{m: rec["metrics"].get(m) for m in metric_names}}
            writer.writerow([_cell(row.get(c)) for c in header])
            f.flush()
            counts[rec["status"]] = counts.get(rec["status"], 0) + 1
            if progress is not None:
                progress(n, total)
    files = [runs_csv]
    files.append(write_parquet(runs_csv, out / "runs.parquet"))
    rows = read_runs(runs_csv)
    summary = summarize_runs(rows, list(study.grid), metric_names)
    files.append(write_summary(out / "summary.csv", summary))
    if plots and rows:
        files += plot_study(out, rows, list(study.grid), metric_names, summary)
    return StudyResult(out, total, len(planned) - total, counts, files)


def write_parquet(csv_path: Path, path: Path) -> Path:
    """``runs.parquet`` from ``runs.csv`` (types inferred by pyarrow; an empty
    cell is null)."""
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    table = pcsv.read_csv(csv_path, convert_options=pcsv.ConvertOptions(strings_can_be_null=True))
    pq.write_table(table, path)
    return path


# ---- the summary --------------------------------------------------------------------------

def _float(text: str) -> float | None:
    try:
        v = float(text)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _t975(dof: int) -> float:
    from scipy.stats import t

    return float(t.ppf(0.975, dof))


def interval95(values: Sequence[float]) -> tuple[float, float] | None:
    """The 95 % Student t interval of the mean of ``values`` (None below 2 values)."""
    x = np.asarray(values, dtype=float)
    if x.size < 2:
        return None
    mean, half = float(x.mean()), _t975(x.size - 1) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return mean - half, mean + half


def summarize_runs(rows: Iterable[Mapping[str, str]], group_keys: Sequence[str],
                   metric_names: Sequence[str]) -> list[dict[str, Any]]:
    """One record per group (the values of ``group_keys``, in the plan's
    order where the rows carry their ``run`` index, else first-seen order):
    ``runs``, ``ok``, ``diverged``, ``failed``; per metric, over the ``ok``
    runs: ``<m>_n``, ``_mean``, ``_std`` (ddof 1), ``_ci95_low``,
    ``_ci95_high`` (Student t interval of the mean; empty below 2 runs)."""
    rows = list(rows)
    if all(str(r.get("run", "")).isdigit() for r in rows):  # rows finish in any order, a resumed study's later
        rows.sort(key=lambda r: int(r["run"]))
    groups: dict[tuple, list[Mapping[str, str]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in group_keys), []).append(row)
    out = []
    for values, members in groups.items():
        rec: dict[str, Any] = dict(zip(group_keys, values))
        rec["runs"] = len(members)
        for status in ("ok", "diverged", "failed"):
            rec[status] = sum(r["status"] == status for r in members)
        ok = [r for r in members if r["status"] == "ok"]
        for m in metric_names:
            x = np.array([v for v in (_float(r.get(m)) for r in ok) if v is not None])
            n = len(x)
            mean = float(x.mean()) if n else None
            std = float(x.std(ddof=1)) if n > 1 else None
            low, high = interval95(x) or (None, None)
            rec.update({f"{m}_n": n, f"{m}_mean": mean, f"{m}_std": std, f"{m}_ci95_low": low,
                        f"{m}_ci95_high": high})
        out.append(rec)
    return out


def write_summary(path: Path, records: list[dict[str, Any]]) -> Path:
    fields = list(dict.fromkeys(k for r in records for k in r))
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(fields)
        for r in records:
            writer.writerow([_cell(r.get(k)) for k in fields])
    return path


# ---- plots ----------------------------------------------------------------------------------

def plot_study(out: Path, rows: list[Mapping[str, str]], group_keys: Sequence[str],
               metric_names: Sequence[str], summary: list[dict[str, Any]] | None = None) -> list[Path]:
    """Per metric: ``box_<metric>.png`` (the ok runs of each grid point) and,
    when a grid key is numeric, ``line_<metric>.png`` (mean and 95 % CI
    against it, one line per combination of the other grid keys). ``summary``:
    the records of :func:`summarize_runs` on ``rows``, when the caller has them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    ok = [r for r in rows if r["status"] == "ok"]
    numeric = [k for k in group_keys if all(_float(r[k]) is not None for r in rows)]
    if summary is None:
        summary = summarize_runs(rows, group_keys, metric_names)
    for m in metric_names:
        groups: dict[tuple, list[float]] = {}
        for r in ok:
            v = _float(r.get(m))
            if v is not None:
                groups.setdefault(tuple(r[k] for k in group_keys), []).append(v)
        if not groups:
            continue
        fig, ax = plt.subplots(figsize=(max(4.0, 0.6 * len(groups) + 2), 4))
        labels = [", ".join(g) or "all" for g in groups]
        ax.boxplot(list(groups.values()))
        ax.set_xticks(range(1, len(labels) + 1), labels, rotation=45 if len(groups) > 4 else 0, ha="right"
                      if len(groups) > 4 else "center", fontsize=8)
        ax.set_xlabel(", ".join(group_keys) or "all runs")
        ax.set_ylabel(m)
        fig.tight_layout()
        files.append(out / f"box_{m}.png")
        fig.savefig(files[-1], dpi=100)
        plt.close(fig)
        if numeric:
            x_key = numeric[-1]
            others = [k for k in group_keys if k != x_key]
            fig, ax = plt.subplots(figsize=(5, 4))
            lines: dict[tuple, list[tuple[float, float, float, float]]] = {}
            for rec in summary:
                if rec[f"{m}_mean"] is None:
                    continue
                lo, hi = rec[f"{m}_ci95_low"], rec[f"{m}_ci95_high"]
                mean = rec[f"{m}_mean"]
                lines.setdefault(tuple(rec[k] for k in others), []).append(
                    (float(rec[x_key]), mean, mean - lo if lo is not None else 0.0, hi - mean if hi is not None else 0.0))
            for label, pts in lines.items():
                pts.sort()
                xs, ys, lo, hi = zip(*pts)
                ax.errorbar(xs, ys, yerr=[lo, hi], marker="o", capsize=3, label=", ".join(label) or None)
            ax.set_xlabel(x_key)
            ax.set_ylabel(f"{m} (mean, 95 % CI)")
            if others:
                ax.legend(title=", ".join(others), fontsize=8)
            fig.tight_layout()
            files.append(out / f"line_{m}.png")
            fig.savefig(files[-1], dpi=100)
            plt.close(fig)
    return files
