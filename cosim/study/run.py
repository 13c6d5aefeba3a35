"""Running a study: its runs on the engine's runner, one row per run, the summary.

:func:`run_study` executes the plan of a :class:`~cosim.study.definition.Study`
(:func:`~cosim.study.definition.runs`) through :func:`cosim.study.runner.fly`
(in this process or on a Dask cluster) and writes one results layout for
every study, tables included (``docs/studies.md``)::

    <out>/study.json     what the folder holds: the study's definition, its fingerprint, progress
    <out>/runs.csv       one row per run, appended and flushed as each run (on Dask, its batch) finishes
    <out>/runs.parquet   the same table (pyarrow), written at the end
    <out>/summary.json   per cell (case, grid point): counts and, per metric, n, mean, std, 95 % interval
    <out>/box_<m>.png, line_<m>.png   with ``plots``

Without ``out_dir`` nothing is written: the rows and the summary are returned
(the one-off analyses fly their missions this way).

Resume: the runs already in ``runs.csv`` of the same study (same
fingerprint) are not run again; a half-written last line (a killed study)
is dropped first. A folder holding another study's runs is refused, and so
is a folder another driver is writing (a lock).
"""
from __future__ import annotations

import contextlib
import csv
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

from ..errors import ScenarioError, one_line, shown_text
from ..files import STUDY_SIDECAR as SIDECAR
from ..files import not_others_results, output_folder
from ..files import write_json  # noqa: F401  (where the study writers have always found it)
from ..scenario.definition import apply_overrides, parse_scenario
from .definition import Study, count, runs
from ..limits import WORKER_TIMEOUT
from .summary import STATUSES, summarize

__all__ = ["run_study", "StudyResult", "read_runs", "columns", "write_json", "FIXED_COLUMNS", "summary_of"]

FIXED_COLUMNS = ("run", "case", "sample", "seed")
LOCK = ".study.lock"
FORMAT = "fnn-cosim study"


@dataclass
class StudyResult:
    """What :func:`run_study` did: the planned runs (``total``), those already
    done before (``skipped``), this time's rows by status (``counts``), the
    files written, the summary (the content of ``summary.json``) and, without
    an output folder, every row (typed records, in plan order)."""

    out_dir: Path | None
    total: int
    skipped: int
    counts: dict[str, int]
    files: list[Path]
    summary: dict[str, Any]
    rows: list[dict[str, Any]] = field(default_factory=list)


# ---- the runs table -------------------------------------------------------------------------

def _cell(value: Any) -> str:
    """A value as written in runs.csv (floats as repr: an exact round trip)."""
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


def read_runs(path: str | Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _rows_of(path: Path) -> Iterator[dict[str, str]]:
    """The rows of a runs.csv, one at a time."""
    with open(path, newline="", encoding="utf-8") as f:
        yield from csv.DictReader(f)


def _done(path: Path, header: list[str], total: int, numbers: Sequence[str] = ()) -> bytearray:
    """Which runs ``path`` already holds, as a bitmap over the plan's indices
    (a half-written last line dropped first); a file with other columns, a
    row that is no run of the plan or a run on two lines, a status that is
    none, or a word in a column of ``numbers``, is refused."""
    done = bytearray((total + 7) // 8)
    if not path.exists() or path.stat().st_size == 0:
        return done
    with open(path, "rb+") as f:  # killed while writing a row: cut the last line
        f.seek(0, os.SEEK_END)
        size = f.tell()
        f.seek(max(0, size - 1))
        if f.read(1) != b"\n":
            tail = min(size, 1 << 20)
            f.seek(size - tail)
            chunk = f.read(tail)
            f.truncate(size - tail + chunk.rfind(b"\n") + 1)
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames != header:
            raise ScenarioError(f"{path}: holds the runs of another study (columns {reader.fieldnames}); "
                                f"choose another --out")
        for line, row in enumerate(reader, 2):
            if None in row or None in row.values():  # csv's marks of a row longer or shorter than the header
                fields = sum(v is not None for k, v in row.items() if k is not None) + len(row.get(None) or ())
                raise ScenarioError(f"{path}: line {line}: {fields} fields where the header has {len(header)}; "
                                    f"remove the line, or choose another --out")
            run = row.get("run", "")
            if not run.isdigit() or int(run) >= total:
                raise ScenarioError(f"{path}: line {line}: run = {shown_text(repr(run))} is no run of this study's "
                                    f"plan (0..{total - 1})")
            if _is_done(done, int(run)):  # counted twice: the cell's n and its interval would lie
                raise ScenarioError(f"{path}: line {line}: run {run} is on an earlier line too; remove one, or "
                                    f"choose another --out")
            _check_row(row, numbers, f"{path}: line {line}")
            done[int(run) >> 3] |= 1 << (int(run) & 7)
    return done


def _check_row(row: Mapping[str, str], numbers: Sequence[str], where: str) -> None:
    """A resumed row's status one of :data:`~cosim.study.summary.STATUSES` and its
    ``numbers`` (the metrics, the wall time) each a number or empty (an
    undefined metric): a word in a metric's cell was kept, and its run
    counted as ok over one value fewer."""
    if row["status"] not in STATUSES:
        raise ScenarioError(f"{where}: status = {shown_text(repr(row['status']))}: expected one of "
                            f"{', '.join(STATUSES)}; remove the line, or choose another --out")
    for name in numbers:
        cell = row[name]
        if cell:
            try:
                float(cell)
            except ValueError:
                raise ScenarioError(f"{where}: {name} = {shown_text(repr(cell))}: not a number; remove the line, or "
                                    f"choose another --out") from None


def _is_done(done: bytearray, index: int) -> bool:
    return bool(done[index >> 3] & (1 << (index & 7)))


def write_parquet(csv_path: Path, path: Path) -> Path:
    """``runs.parquet`` from ``runs.csv`` (types inferred by pyarrow; an empty cell is null)."""
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    table = pcsv.read_csv(csv_path, convert_options=pcsv.ConvertOptions(strings_can_be_null=True))
    pq.write_table(table, path)
    return path


# ---- the folder ---------------------------------------------------------------------------------

class _Lock:
    """An exclusive lock on the output folder while a driver writes into it."""

    def __init__(self, folder: Path):
        self.path = folder / LOCK
        self.file = None

    def __enter__(self):
        import fcntl

        self.file = open(self.path, "a")
        try:
            fcntl.flock(self.file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self.file.close()
            raise ScenarioError(f"{self.path.parent}: another study is being written into this folder now; "
                                f"wait for it, or choose another --out") from None
        return self

    def __exit__(self, *exc):
        self.file.close()  # releases the lock


def _check_sidecar(out: Path, study: Study) -> None:
    path = out / SIDECAR
    if not path.exists():
        return
    try:
        held = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: not a study sidecar ({one_line(str(exc))}); choose another --out") from None
    if not isinstance(held, dict) or held.get("fingerprint") != study.fingerprint:
        other = held.get("study") if isinstance(held, dict) else None
        raise ScenarioError(f"{out}: holds the runs of another study ({other!r}, or this one with other settings); "
                            f"choose another --out")


def _sidecar(out: Path, study: Study, total: int, rows: int, status: str) -> None:
    write_json(out / SIDECAR, {"format": FORMAT, "study": study.name, "fingerprint": study.fingerprint,
                               "runs": total, "rows": rows, "status": status, "definition": study.definition()})


# ---- running ------------------------------------------------------------------------------------

# What a study imports once its runs are over: the summary's t quantile (scipy.special, about 0.4 s
# of CPU) and the Parquet writer. Imported by a thread while the runs fly, whose compiled loops leave
# the GIL free most of the time, rather than after the last run, when every other core is idle; from
# the first row on, not before: until then the runner's own start (its imports, the first masters'
# builds) is all Python, which the thread would only slow down.
# SciPy only when the summary's t quantiles are not kept for the cells' planned runs (cosim.study.summary).
AFTER_THE_RUNS = ("scipy.special", "pyarrow.csv", "pyarrow.parquet")


def _after_the_runs(study: Study, files: bool) -> tuple[str, ...]:
    """What to import while the runs fly (:data:`AFTER_THE_RUNS`): the
    Parquet writer when there are ``files``; SciPy when the t quantile of a
    full cell (its samples x seeds ok runs) is not kept
    (:func:`cosim.study.summary.kept_t975`)."""
    from .summary import kept_t975

    dofs = {(study.samples or 1) * len(study.case_seeds(case)) - 1 for case in study.cases or (None,)}
    kept = kept_t975()
    modules = AFTER_THE_RUNS if files else AFTER_THE_RUNS[:1]
    return tuple(m for m in modules if m != "scipy.special" or not all(d in kept for d in dofs if d >= 1))


def _import_ahead(modules: Sequence[str]) -> None:
    """Import ``modules`` in a background thread (a later import of one waits for it, or finds it done)."""
    import importlib
    import threading

    def load() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # the import where the module is needed says why, in its own thread
                return

    threading.Thread(target=load, name="cosim-import-ahead", daemon=True).start()


def summary_of(study: Study, rows: Iterable[Mapping[str, Any]], metric_names: Sequence[str],
               wall_time: float | None = None) -> dict[str, Any]:
    """The content of ``summary.json``: the study, its cases, and
    :func:`~cosim.study.summary.summarize` over ``rows`` (records or runs.csv lines)."""
    cells = summarize(study, rows, metric_names)
    counts = {s: sum(c[s] for c in cells) for s in STATUSES if any(c[s] for c in cells)}
    return {"study": study.name, "description": study.description, "scenario": study.scenario.name,
            "fingerprint": study.fingerprint, "duration_s": study.scenario.duration, "keys": list(study.grid),
            "random_keys": list(study.random), "metrics": list(metric_names),
            "cases": [c.describe() for c in study.cases], "runs": count(study),
            "rows": sum(c["runs"] for c in cells), "counts": counts, "wall_time_s": wall_time, "cells": cells}


def run_study(study: Study, out_dir: str | Path | None = None, *, workers: int = 1, scheduler: str | None = None,
              metrics: Callable[[Any, Any], Mapping[str, Any]] | None = None, metric_names: Sequence[str] = (),
              record: Sequence[str] | None = None, progress: Callable[[int, int], None] | None = None,
              plots: bool = True, resume: bool = True, worker_timeout: float | None = WORKER_TIMEOUT,
              threads: bool = False) -> StudyResult:
    """Run the runs of ``study`` (those not yet in ``out_dir/runs.csv`` when
    ``resume``; all of them, the folder's old rows dropped, otherwise),
    appending a row as each finishes; then write ``runs.parquet``,
    ``summary.json`` and the plots. ``metrics(scenario, result)`` gives the
    metric columns ``metric_names`` of a row (it runs on the workers: a
    module-level function); ``record`` replaces the recorded signals (e.g.
    only what the metrics read). ``progress(done, total)`` before the first
    run, then after each row. Without ``out_dir`` nothing is written and the
    rows come back in :attr:`StudyResult.rows`, with whatever else ``metrics``
    returned (an analysis may return a recorded run). With ``out_dir`` the
    driver keeps no row in memory: its memory does not grow with the study.
    ``workers`` local worker processes, or ``scheduler``, the address of a
    running Dask scheduler (``tcp://host:8786``) whose cluster flies the runs
    (:mod:`cosim.study.runner`); with neither (1 worker) the runs fly in this
    process; ``threads``: the local workers are threads of this process
    (:func:`cosim.study.runner.fly`: for runs whose every FMU the caller
    knows reentrant). ``plots``: the study's figures beside its summary.
    ``worker_timeout``: how long a Dask cluster without a worker is waited
    for before the study stops (:func:`cosim.study.runner.fly`; ``None``: for ever)."""
    from .runner import fly

    started = time.perf_counter()
    base = study.scenario
    if record is not None:
        base = parse_scenario(apply_overrides(base.raw, {"record.signals": list(record)}), source=base.source)
    header = columns(study, metric_names)
    total = count(study)
    out = not_others_results(output_folder(out_dir), "study") if out_dir is not None else None
    with (_Lock(out) if out is not None else contextlib.nullcontext()):
        done = bytearray((total + 7) // 8)
        runs_csv = None
        if out is not None:
            runs_csv = out / "runs.csv"
            if resume:
                _check_sidecar(out, study)
                done = _done(runs_csv, header, total, [*metric_names, "wall_time_s"])
            else:
                runs_csv.unlink(missing_ok=True)
        skipped = sum(bin(b).count("1") for b in done)
        if out is not None:
            _sidecar(out, study, total, skipped, "running")
        pending: dict[int, Any] = {}

        def todo():
            for run in runs(study):
                if not _is_done(done, run.index):
                    pending[run.index] = run
                    yield run

        kept: list[dict[str, Any]] = []
        counts: dict[str, int] = {}
        f = writer = None
        if runs_csv is not None:
            new = not runs_csv.exists() or runs_csv.stat().st_size == 0
            f = open(runs_csv, "a", newline="", encoding="utf-8")
            writer = csv.writer(f)
            if new:
                writer.writerow(header)
                f.flush()
        try:
            if progress is not None:
                progress(0, total - skipped)
            for n, rec in enumerate(fly(base, todo(), workers=workers, scheduler=scheduler, metrics=metrics,
                                        worker_timeout=worker_timeout, total=total - skipped,
                                        threads=threads), 1):
                if n == 1:
                    _import_ahead(_after_the_runs(study, out is not None))
                run = pending.pop(rec["key"])
                # every metric the function gave stays in a row kept in memory (an analysis may return
                # more than numbers); the metric_names are the table's columns
                row = {"run": run.index, "case": run.case, "sample": run.sample, "seed": run.seed, **run.values,
                       "status": rec["status"], "error": rec["error"], "wall_time_s": rec["wall_time_s"],
                       **{m: None for m in metric_names}, **rec["metrics"]}
                if writer is not None:
                    writer.writerow([_cell(row.get(c)) for c in header])
                    f.flush()
                else:
                    kept.append(row)
                counts[rec["status"]] = counts.get(rec["status"], 0) + 1
                if progress is not None:
                    progress(n, total - skipped)
        finally:
            if f is not None:
                f.close()
        wall = time.perf_counter() - started
        if out is None:
            kept.sort(key=lambda r: r["run"])
            return StudyResult(None, total, skipped, counts, [], summary_of(study, kept, metric_names, wall), kept)
        summary = summary_of(study, _rows_of(runs_csv), metric_names, wall)
        files = [runs_csv, write_parquet(runs_csv, out / "runs.parquet"), write_json(out / "summary.json", summary)]
        if plots and summary["rows"]:
            from .plots import plot_study

            files += plot_study(out, study, _rows_of(runs_csv), metric_names, summary["cells"])
        _sidecar(out, study, total, summary["rows"], "done")
        return StudyResult(out, total, skipped, counts, files, summary)
