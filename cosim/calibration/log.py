"""A recorded log as named columns over one time base, checked.

Readers (by the file's suffix): a CSV (the project's results, whose sidecar
``<file>.json`` gives the columns' units, or any CSV with a header), a
Parquet file (pyarrow; a field's ``unit`` metadata is its unit) and a PX4
ULog (``.ulg``, through the optional ``pyulog``: columns ``topic.field``,
every topic interpolated onto the instants of the column map's ``topic``).

Every column the calibration uses is checked, and the time: a NaN or an
infinite value, a time that repeats or goes back, and a gap (a step more
than 1.5 times the log's median step) are refused in one line naming the
file, the row (1 = the first data row) and the column
(:class:`~cosim.errors.ScenarioError`, exit 2 at the command line).
"""
from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import ConnectionCheckError, ScenarioError, shown_text
from ..files import read_text, regular_file
from ..limits import MAX_TABLE_BYTES
from .. import units as _units

__all__ = ["Log", "read_log", "GAP_FACTOR"]

GAP_FACTOR = 1.5  # a step longer than this many median steps is a gap


@dataclass(frozen=True, eq=False)
class Log:
    """``times`` (s) and ``columns`` (name -> float array, one value a row)
    with their ``units`` (name -> unit, ``""`` when the log says none)."""

    path: Path
    times: np.ndarray
    columns: dict[str, np.ndarray]
    units: dict[str, str] = field(default_factory=dict)

    @property
    def step(self) -> float:
        return float(np.median(np.diff(self.times))) if self.times.size > 1 else 0.0

    def where(self) -> str:
        return f"log {self.path.name}"

    def window(self, start: float | None, stop: float | None) -> "Log":
        """The rows with ``start <= t <= stop`` (within 1e-9 s)."""
        keep = np.ones(self.times.size, bool)
        if start is not None:
            keep &= self.times >= start - 1e-9
        if stop is not None:
            keep &= self.times <= stop + 1e-9
        if keep.sum() < 2:
            raise ScenarioError(f"{self.where()}: fewer than 2 rows between start {start} and stop {stop}")
        return Log(self.path, self.times[keep], {k: v[keep] for k, v in self.columns.items()}, self.units)

    def check(self, names: Sequence[str]) -> None:
        """Refuse the time or a column of ``names`` the calibration cannot use (module docstring)."""
        where, t = self.where(), self.times
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size:
            raise ScenarioError(f"{where}: row {bad[0] + 1}, column time: {float(t[bad[0]])!r} is not a finite number")
        steps = np.diff(t)
        if (steps == 0).any():
            i = int(np.flatnonzero(steps == 0)[0]) + 1
            raise ScenarioError(f"{where}: row {i + 1}, column time: t = {float(t[i])!r} repeats the row before "
                                f"(duplicate time)")
        if (steps < 0).any():
            i = int(np.flatnonzero(steps < 0)[0]) + 1
            raise ScenarioError(f"{where}: row {i + 1}, column time: t = {float(t[i])!r} goes back (after {float(t[i - 1])!r})")
        if steps.size:
            median = float(np.median(steps))
            gaps = np.flatnonzero(steps > GAP_FACTOR * median)
            if gaps.size:
                i = int(gaps[0]) + 1
                raise ScenarioError(f"{where}: row {i + 1}, column time: a gap of {steps[i - 1]:g} s after "
                                    f"t = {float(t[i - 1])!r} (the log's step is {median:g} s)")
        for name in names:
            values = self.columns[name]
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise ScenarioError(f"{where}: row {bad[0] + 1}, column {name}: {float(values[bad[0]])!r} is not a "
                                    f"finite number")


def read_log(path: str | Path, column_map=None) -> Log:
    """The log at ``path`` with the time column of ``column_map``
    (:class:`~cosim.calibration.columns.ColumnMap`; default ``time`` in s),
    its time converted to s. Values are not yet checked (:meth:`Log.check`)."""
    path = Path(path)
    regular_file(path, "log")
    suffix = path.suffix.lower()
    time_name = column_map.time if column_map is not None else "time"
    if suffix == ".parquet":
        times, columns, units = _read_parquet(path, time_name)
    elif suffix == ".ulg":
        times, columns, units = _read_ulog(path, column_map)
    else:
        times, columns, units = _read_csv(path, time_name)
    time_unit = column_map.time_unit if column_map is not None else (units.pop(time_name, "") or "s")
    units.pop(time_name, None)
    if time_unit not in ("s", ""):
        try:
            factor, offset = _units.conversion(time_unit, "s")
        except ConnectionCheckError as exc:
            raise ScenarioError(f"log {path.name}: time unit {time_unit!r}: {exc}") from None
        times = times * factor + offset
    return Log(path, times, columns, units)


def _missing_time(path: Path, time_name: str, names) -> ScenarioError:
    return ScenarioError(f"log {path.name}: no time column {time_name!r}; its columns: "
                         f"{shown_text(', '.join(names), 200)} (name it with 'time' in --columns)")


def _read_csv(path: Path, time_name: str):
    text = read_text(path, "log", limit=MAX_TABLE_BYTES)
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise ScenarioError(f"log {path.name}: empty") from None
    if time_name not in header:
        raise _missing_time(path, time_name, header)
    rows = [r for r in reader if r]
    if not rows:
        raise ScenarioError(f"log {path.name}: no rows after the header")
    data = np.full((len(rows), len(header)), np.nan)
    for i, row in enumerate(rows, start=1):
        if len(row) != len(header):
            raise ScenarioError(f"log {path.name}: row {i}: {len(row)} fields for {len(header)} columns")
        for j, text_value in enumerate(row):
            text_value = text_value.strip()
            try:
                data[i - 1, j] = float(text_value) if text_value else np.nan
            except ValueError:
                data[i - 1, j] = np.nan  # a text column; refused only if the calibration uses it
    units: dict[str, str] = {}
    sidecar = path.with_name(path.name + ".json")  # the project's results: columns, units (cosim.recorder)
    if sidecar.is_file():
        try:
            meta = json.loads(read_text(sidecar, "log sidecar"))
            units = {c: u for c, u in zip(meta.get("columns", []), meta.get("units", [])) if isinstance(u, str)}
        except (ValueError, AttributeError, TypeError):
            units = {}
    columns = {name: data[:, j] for j, name in enumerate(header) if name != time_name}
    return data[:, header.index(time_name)], columns, units


def _read_parquet(path: Path, time_name: str):
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except Exception as exc:  # pyarrow's errors are many types: the file is no Parquet we can read
        raise ScenarioError(f"log {path.name}: not a Parquet file pyarrow reads ({shown_text(str(exc), 200)})") \
            from None
    names = table.column_names
    if time_name not in names:
        raise _missing_time(path, time_name, names)
    units, columns = {}, {}
    for f in table.schema:
        unit = (f.metadata or {}).get(b"unit")
        if unit:
            units[f.name] = unit.decode()
        try:
            columns[f.name] = table.column(f.name).to_numpy(zero_copy_only=False).astype(float)
        except (TypeError, ValueError, Exception):  # a text column: unusable, refused if used
            columns[f.name] = np.full(table.num_rows, np.nan)
    times = columns.pop(time_name)
    return times, columns, units


def _read_ulog(path: Path, column_map):
    try:
        from pyulog import ULog
    except ImportError:
        raise ScenarioError(f"log {path.name}: reading a PX4 ULog needs pyulog "
                            "(pip install 'fnn-cosim[ulog]')") from None
    if column_map is None or not column_map.topic:
        raise ScenarioError(f"log {path.name}: a ULog needs a column map (--columns) naming its 'topic', whose "
                            f"samples are the log's instants")
    try:
        ulog = ULog(str(path))
    except Exception as exc:  # pyulog raises many types on a file that is not a ULog
        raise ScenarioError(f"log {path.name}: not a ULog pyulog reads ({shown_text(str(exc), 200)})") from None
    topics = {}
    for d in ulog.data_list:
        topics.setdefault(d.name, d)  # the first instance of a topic (multi-instance topics: instance 0)
    if column_map.topic not in topics:
        raise ScenarioError(f"log {path.name}: no topic {column_map.topic!r}; its topics: "
                            f"{shown_text(', '.join(sorted(topics)), 200)}")
    base = topics[column_map.topic].data["timestamp"].astype(float)
    columns = {}
    for name, d in topics.items():
        t = d.data["timestamp"].astype(float)
        for fname, values in d.data.items():
            if fname == "timestamp":
                continue
            v = np.asarray(values, dtype=float)
            columns[f"{name}.{fname}"] = v if name == column_map.topic else np.interp(base, t, v)
    # ULog's time is microseconds: the column map's time_unit says so ("us")
    return base, columns, {}
