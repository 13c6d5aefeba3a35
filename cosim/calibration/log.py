"""A recorded log as named columns over one time base, checked.

Readers (by the file's suffix): a CSV (the project's results, whose sidecar
``<file>.json`` gives the columns' units, or any CSV with a header), a
Parquet file (pyarrow; a field's ``unit`` metadata is its unit) and a PX4
ULog (``.ulg``, through the optional ``pyulog``: columns ``topic.field``,
the topics the column map names resampled onto one time base). A CSV's or
Parquet file's columns are read when used, only those (:mod:`cosim.columns_io`,
the signal table's reader too: pyarrow, streamed or columnar):
a log's memory is that of the columns used, not the file's.

Every column the calibration uses is checked, and the time: a NaN or an
infinite value, a time that repeats or goes back, and a gap (a step more
than 1.5 times the log's median step) are refused in one line naming the
file, the row (1 = the first data row) and the column
(:class:`~cosim.errors.ScenarioError`, exit 2 at the command line).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterator, Mapping, Sequence

import numpy as np

from ..columns_io import csv_floats, csv_header, parquet_read, parquet_schema, unique_columns
from ..errors import ConnectionCheckError, ScenarioError, shown_text
from ..files import read_text, regular_file
from ..fmi import units as _units

__all__ = ["Log", "Columns", "read_log", "GAP_FACTOR"]

GAP_FACTOR = 1.5  # a step longer than this many median steps is a gap


class Columns(Mapping[str, np.ndarray]):
    """A log's columns by name, each read from the file when first used:
    the memory a log takes is that of the columns a calibration uses, not
    the file's (issue 42 item 5). ``load(names)`` reads several in one pass;
    ``derived`` columns (frames converted, :mod:`~cosim.calibration.frames`)
    are held as given."""

    def __init__(self, names: Sequence[str], read: Callable[[list[str]], dict[str, np.ndarray]],
                 derived: Mapping[str, np.ndarray] | None = None):
        self._names = list(dict.fromkeys([*names, *(derived or {})]))
        self._read = read
        self._held: dict[str, np.ndarray] = dict(derived or {})

    def load(self, names: Sequence[str]) -> None:
        missing = [n for n in dict.fromkeys(names) if n not in self._held and n in self._names]
        if missing:
            self._held.update(self._read(missing))

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._held:
            if name not in self._names:
                raise KeyError(name)
            self.load([name])
        return self._held[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def __contains__(self, name) -> bool:
        return name in self._names

    def rows(self, keep: np.ndarray) -> "Columns":
        """The same columns, each at the rows ``keep`` (a mask) only."""
        def read(names):
            self.load(names)
            return {n: self._held[n][keep] for n in names}
        return Columns(self._names, read)

    def adding(self, derived: Mapping[str, np.ndarray]) -> "Columns":
        """These columns and ``derived`` (name -> values, one a row)."""
        def read(names):
            self.load(names)
            return {n: self._held[n] for n in names}
        return Columns(self._names, read, derived)


@dataclass(frozen=True, eq=False)
class Log:
    """``times`` (s) and ``columns`` (name -> float array, one value a row,
    read when used: :class:`Columns`) with their ``units`` (name -> unit,
    ``""`` when the log says none); ``resampling``: how a log of several
    rates was put on one time base (a ULog), for the report, else ``None``."""

    path: Path
    times: np.ndarray
    columns: Mapping[str, np.ndarray]
    units: dict[str, str] = field(default_factory=dict)
    resampling: str | None = None

    @property
    def step(self) -> float:
        return float(np.median(np.diff(self.times))) if self.times.size > 1 else 0.0

    def where(self) -> str:
        return f"log {self.path.name}"

    def no_column(self, name: str, what: str) -> ScenarioError:
        """The one line for a column ``name`` the log lacks, named for ``what``."""
        from ..names import nearest_told

        return ScenarioError(f"{self.where()}: no column {name!r} (named by the column map for {what})"
                             + (nearest_told(name, self.columns)
                                or f"; its columns: {shown_text(', '.join(self.columns), 200)}"))

    def window(self, start: float | None, stop: float | None) -> "Log":
        """The rows with ``start <= t <= stop`` (within 1e-9 s)."""
        keep = np.ones(self.times.size, bool)
        if start is not None:
            keep &= self.times >= start - 1e-9
        if stop is not None:
            keep &= self.times <= stop + 1e-9
        if keep.sum() < 2:
            raise ScenarioError(f"{self.where()}: fewer than 2 rows between start {start} and stop {stop}")
        columns = self.columns.rows(keep) if isinstance(self.columns, Columns) else \
            {k: v[keep] for k, v in self.columns.items()}
        return replace(self, times=self.times[keep], columns=columns)

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
        if isinstance(self.columns, Columns):
            self.columns.load(names)  # one pass over the file for them all
        for name in names:
            values = self.columns[name]
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise ScenarioError(f"{where}: row {bad[0] + 1}, column {name}: {float(values[bad[0]])!r} is not a "
                                    f"finite number")


def read_log(path: str | Path, column_map=None) -> Log:
    """The log at ``path`` with the time column of ``column_map``
    (:class:`~cosim.calibration.columns.ColumnMap`; default ``time`` in s),
    its time converted to s. Only the header is read here; a column is read
    when used (:class:`Columns`). Two columns of one name are refused in one
    line. Values are not yet checked (:meth:`Log.check`)."""
    path = Path(path)
    regular_file(path, "log")
    suffix = path.suffix.lower()
    time_name = column_map.time if column_map is not None else "time"
    resampling = None
    if suffix == ".parquet":
        times, columns, units = _read_parquet(path, time_name)
    elif suffix == ".ulg":
        times, columns, units, resampling = _read_ulog(path, column_map)
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
    return Log(path, times, columns, units, resampling)


def _missing_time(path: Path, time_name: str, names) -> ScenarioError:
    return ScenarioError(f"log {path.name}: no time column {time_name!r}; its columns: "
                         f"{shown_text(', '.join(names), 200)} (name it with 'time' in --columns)")


def _floats(column) -> np.ndarray:
    """A pyarrow column as floats: numbers as they are, a null as NaN, text
    parsed where it is a number and NaN elsewhere (refused only if used)."""
    import pyarrow as pa

    if pa.types.is_integer(column.type) or pa.types.is_floating(column.type) or pa.types.is_boolean(column.type) \
            or pa.types.is_null(column.type):
        return column.to_numpy(zero_copy_only=False).astype(float)
    out = np.full(len(column), np.nan)
    for i, value in enumerate(column.to_pylist()):
        try:
            out[i] = float(value)
        except (TypeError, ValueError):
            pass
    return out


def _row(i: int) -> str:
    return f"row {i + 1}"  # 1 = the first data row


def _read_csv(path: Path, time_name: str):
    """Its header now; its columns when used, only those, streamed
    (:func:`cosim.columns_io.csv_floats`)."""
    where = f"log {path.name}"
    raw = csv_header(path, where, errors="replace")
    if not raw:
        raise ScenarioError(f"{where}: empty")
    header = [h.strip() for h in raw]
    unique_columns(header, where)
    if time_name not in header:
        raise _missing_time(path, time_name, header)
    raw_of = dict(zip(header, raw))
    rows: list[int] = []

    def read(names: list[str]) -> dict[str, np.ndarray]:
        return csv_floats(path, where, {n: raw_of[n] for n in names}, raw, header, _row,
                          rows[0] if rows else None)

    columns = Columns([h for h in header if h != time_name], read)
    times = read([time_name])[time_name]
    if times.size == 0:
        raise ScenarioError(f"{where}: no rows after the header")
    rows.append(times.size)
    units: dict[str, str] = {}
    sidecar = path.with_name(path.name + ".json")  # the project's results: columns, units (cosim.loop.recorder)
    if sidecar.is_file():
        try:
            meta = json.loads(read_text(sidecar, "log sidecar"))
            units = {c: u for c, u in zip(meta.get("columns", []), meta.get("units", [])) if isinstance(u, str)}
        except (ValueError, AttributeError, TypeError):
            units = {}
    return times, columns, units


def _read_parquet(path: Path, time_name: str):
    """Its schema now; its columns when used (Parquet is columnar: a column
    read is that column's pages only)."""
    where = f"log {path.name}"
    schema, _ = parquet_schema(path, where)
    names = schema.names
    unique_columns(names, where)
    if time_name not in names:
        raise _missing_time(path, time_name, names)
    units = {}
    for f in schema:
        unit = (f.metadata or {}).get(b"unit")
        if unit:
            units[f.name] = unit.decode()

    def read(wanted: list[str]) -> dict[str, np.ndarray]:
        table = parquet_read(path, where, wanted)
        return {n: _floats(table.column(n)) for n in wanted}

    times = read([time_name])[time_name]
    return times, Columns([n for n in names if n != time_name], read), units


def _ulog_topics(column_map) -> set[str]:
    """The topics a column map's columns name (``topic.field``)."""
    named = [c.column for c in column_map.columns.values()]
    if column_map.attitude is not None:
        named += [c.column for c in (column_map.attitude.quaternion or column_map.attitude.euler)]
    if column_map.rotors is not None:
        named += [c.column for c in column_map.rotors.columns]
    return {n.split(".", 1)[0] for n in named if "." in n} | {column_map.topic}


def _read_ulog(path: Path, column_map):
    """The topics the column map names, each at its own rate, resampled onto
    one time base (docs/calibration.md, "PX4 ULog"): the instants of the
    map's ``topic`` within the span every used topic covers (no
    extrapolation), the ``hold`` topics held from their last sample
    (zero-order: commands), the others interpolated linearly."""
    try:
        from pyulog import ULog
    except ImportError:
        raise ScenarioError(f"log {path.name}: reading a PX4 ULog needs pyulog "
                            "(pip install 'fnn-cosim[ulog]')") from None
    if column_map is None or not column_map.topic:
        raise ScenarioError(f"log {path.name}: a ULog needs a column map (--columns) naming its 'topic', whose "
                            f"samples are the log's instants")
    wanted = _ulog_topics(column_map)

    def parse(only):
        try:
            return ULog(str(path), only)  # only the topics used are parsed and kept
        except Exception as exc:  # pyulog raises many types on a file that is not a ULog
            raise ScenarioError(f"log {path.name}: not a ULog pyulog reads ({shown_text(str(exc), 200)})") from None

    topics = {}
    for d in parse(sorted(wanted)).data_list:
        if d.name in wanted:
            topics.setdefault(d.name, d)  # the first instance of a topic (multi-instance topics: instance 0)
    missing = sorted(wanted - set(topics))
    if missing:
        present = sorted({d.name for d in parse(None).data_list})
        raise ScenarioError(f"log {path.name}: no topic {missing[0]!r} (named by the column map); its topics: "
                            f"{shown_text(', '.join(present), 300)}")
    stamps = {name: d.data["timestamp"].astype(float) for name, d in topics.items()}
    lo, hi = max(t[0] for t in stamps.values()), min(t[-1] for t in stamps.values())
    base = stamps[column_map.topic]
    base = base[(base >= lo) & (base <= hi)]
    if base.size < 2:
        raise ScenarioError(f"log {path.name}: the topics {', '.join(sorted(topics))} overlap in fewer than 2 "
                            f"samples of {column_map.topic!r}")
    held = sorted(set(column_map.hold) & set(topics))
    columns = {}
    for name, d in topics.items():
        t = stamps[name]
        last = np.searchsorted(t, base, side="right") - 1  # the sample at or before each instant
        for fname, values in d.data.items():
            if fname == "timestamp":
                continue
            v = np.asarray(values, dtype=float)
            columns[f"{name}.{fname}"] = v[last] if name in held else np.interp(base, t, v)
    rate = (base.size - 1) / (base[-1] - base[0]) * 1e6 if column_map.time_unit == "us" else None
    resampling = (f"onto the {base.size} samples of {column_map.topic}"
                  + (f" ({rate:.4g} Hz)" if rate else "")
                  + f" within the span all of {', '.join(sorted(topics))} cover; "
                  + (f"{', '.join(held)} held (zero-order), " if held else "")
                  + "the others interpolated linearly")
    # ULog's time is microseconds: the column map's time_unit says so ("us")
    return base, columns, {}, resampling
