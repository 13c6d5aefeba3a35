"""The signal table: a recorded CSV or Parquet file played as outputs (``kind = "signal_table"``).

The engine's one table component (it knows no model): a file with a time
column and one row per instant -- the Reference FMUs' ``<Model>_in.csv``
input tables, test-bench data, a log, or this engine's own results
(``results.csv`` and its sidecar) -- becomes a source whose outputs are the
columns (docs/cosim.md, "The signal table"):

* **files**: CSV (a header ``time,col1,col2,...``) or Parquet (``.parquet``,
  ``.pq``: a column ``time``, numbers, Booleans and strings, no nulls);
* **units** per column: from the header (``x [m]``: the column ``x`` in
  metres; ``time [s]``), from this engine's results sidecar
  (``results.csv.json``: its ``units``), from a Parquet field's ``unit``
  metadata, or declared in the scenario (``columns.x.unit``, the map); two
  that disagree are refused in one line; checked on connections like any
  port's (``km/h -> m/s`` is converted);
* **types** per column (default Float64; the results sidecar's types): any
  of :data:`cosim.component.TYPES`; a field holding several numbers
  separated by spaces (``"1 2"``, as ``StateSpace_in.csv`` writes the input
  vector) makes the column an array of that many elements (every row the
  same), connected whole or element by element (``table.u[1]``); Strings as
  the csv module reads them (quoted or not), Binary as hexadecimal digits;
* **interpolation** per column: ``hold`` (sample and hold: at ``t`` the
  value of the last row whose time is ``<= t``) or ``linear`` (between the
  rows around ``t``, for Float32 and Float64 columns only). Times within
  1e-9 relative of ``t`` count as ``<= t`` (``math.isclose``, as fmpy's
  input does). Several rows at one time are a step: from that time on, the
  last of them holds (fmpy's ``Input`` at a communication point, after the
  event);
* **the time column** (:func:`check_times`): finite, never decreasing (with
  ``duplicates = "refuse"`` increasing), and, with ``max_gap``, no two rows
  further apart than that; one line naming the row and the column otherwise;
* **outside the recorded times** (``outside``): ``"refuse"`` (default: a
  run that starts before the first row or ends after the last is refused
  before its first step, in one line naming the table, its file, its first
  and last times and the run's span) or ``"hold"`` (before the first row the
  first value holds, after the last row the last: a table of constants may
  be one row);
* **the columns played**: those the scenario uses -- the sources of its
  connections, its recorded and bounded signals (:func:`played`; every one
  where it records every output) -- and only those are read: a column no
  one uses may hold anything;
* **form** (``form``): a table of Float64 scalar columns runs as an FMU
  (``fmu_models``' generic table FMU, registered with
  :func:`cosim.scenario.registry.register_table_fmu`: the same values, in the
  compiled loop and inside SSP archives) where one is registered
  (``"auto"``, the default; ``"fmu"`` insists), else as this Python
  component (``"python"``).

The file is data from anyone, and a log may be hours at hundreds of hertz
with dozens of columns: it is read through :mod:`cosim.columns_io` (a CSV
streamed, only the columns played converted; a Parquet file's chunks of
those columns alone), so a table holds its time and the columns played as
float64 arrays (or lists, for the types a double does not hold exactly),
not the file. Bounded by rows (:data:`~cosim.limits.MAX_TABLE_ROWS`) and
the data of the columns read (:data:`~cosim.limits.MAX_TABLE_DATA`), every
field checked against its column's type, in one line naming the file, the
row and the column (``docs/security.md``). Two columns of one name are
refused in one line naming it and the file.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Collection, Mapping, Sequence

import numpy as np
from pydantic import Field

from ..columns_io import FieldError, csv_floats, csv_batches, csv_header, parquet_read, parquet_schema, unique_columns
from ..component import FLOAT_HELD, TYPES, Port, PythonComponent, element_of, element_ports, typed_value
from ..errors import ScenarioError, shown_text
from ..files import read_json, regular_file
from ..limits import MAX_TABLE_DATA, MAX_TABLE_ROWS
from .schema import Positive, Table, one_of
from ..time_grid import TOLERANCE  # a time within it of a row's counts as the row's (math.isclose, as fmpy)

__all__ = ["SignalTable", "RecordedTable", "TableData", "read_table", "load_table", "check_times", "split_unit",
           "table_component", "fmu_entry", "KIND", "INTERPOLATIONS", "OUTSIDE", "DUPLICATES", "FORMS",
           "PARQUET_SUFFIXES", "played"]

KIND = "signal_table"
INTERPOLATIONS = ("hold", "linear")
OUTSIDE = ("refuse", "hold")  # the first the default: a run beyond the rows plays no made-up values
DUPLICATES = ("step", "refuse")
FORMS = ("auto", "fmu", "python")
PARQUET_SUFFIXES = (".parquet", ".pq")


class ColumnSpec(Table):
    """``[components.<name>.columns.<column>]``: one column's declaration."""

    type: one_of(TYPES) = Field(None, description="its signal type (docs/cosim.md, 'Signal types'; default "
                                                  "Float64, or what the results sidecar says)")
    unit: str = Field(None, description="its unit (checked on connections; must agree with the file's)")
    interpolation: one_of(INTERPOLATIONS) = Field(None, description="'hold' or 'linear' (default: the table's)")


class TableSpec(Table):
    """``[components.<name>] kind = "signal_table"``: a recorded CSV or Parquet file played as outputs."""

    file: str = Field(..., description="the CSV or Parquet file (relative to the scenario file): a time column "
                                       "'time' (CSV: the first, header 'time,col1,...'), one row per instant; "
                                       "units in the header as 'x [m]'")
    interpolation: one_of(INTERPOLATIONS) = Field("hold", description="every column's, unless it says its own: "
                                                                      "'hold' (sample and hold) or 'linear'")
    columns: dict[str, ColumnSpec] = Field(default_factory=dict, description="type, unit, interpolation per "
                                                                             "column (default Float64)")
    outside: one_of(OUTSIDE) = Field(OUTSIDE[0], description="a run that starts before the first row or ends "
                                                             "after the last: 'refuse' it (before it starts), or "
                                                             "'hold' the first / last values there")
    max_gap: Positive = Field(None, description="the most two rows may lie apart [s]; a table with a wider gap "
                                                "is refused (default: any)")
    duplicates: one_of(DUPLICATES) = Field("step", description="two rows at one time: 'step' (from then on the "
                                                               "last holds) or 'refuse' (a log sampled once per "
                                                               "instant)")
    form: one_of(FORMS) = Field("auto", description="'fmu' (the table FMU: compiled loop, SSP archives), "
                                                    "'python', or 'auto': the FMU when every column is a Float64 "
                                                    "scalar and an FMU builder is registered")
    fmi_version: one_of((2, 3), type_=int) = Field(2, description="FMI version of the table FMU")


# the unit follows the name after a space: "x[1]" is an FMI name (an array element, FMI 2.0 section 2.2.9)
_UNIT = re.compile(r"^(?P<name>.*?)\s+\[(?P<unit>[^\[\]]*)\]\s*$")


def split_unit(header: str) -> tuple[str, str | None]:
    """``"x [m]"`` -> ``("x", "m")``, ``"x[1] [m]"`` -> ``("x[1]", "m")``; a
    name without a bracketed unit after a space (``x``, ``x[1]``) has none."""
    match = _UNIT.match(header.strip())
    if match is None:
        return header.strip(), None
    return match["name"], match["unit"].strip() or None


def _num(x: float) -> str:
    """A time as written: the shortest text that reads back as it (``1``, ``0.1``)."""
    text = repr(float(x))
    return text[:-2] if text.endswith(".0") else text


def check_times(times: np.ndarray, where: str, column: str = "time", max_gap: float | None = None,
                steps: bool = True, line_of=lambda i: f"line {i + 2}") -> None:
    """Refuse, in one line naming the row (``line_of(i)``: a CSV's line, by default) and
    the column, a time column that is not finite, goes back, repeats a time
    (unless ``steps``: two rows at one time are a step) or has two rows more
    than ``max_gap`` apart."""
    times = np.asarray(times, dtype=float)
    bad = np.flatnonzero(~np.isfinite(times))
    if bad.size:
        i = int(bad[0])
        raise ScenarioError(f"{where}: {line_of(i)}, column {column}: {_num(times[i])}: expected a finite number")
    step = np.diff(times)
    back = np.flatnonzero(step < 0 if steps else step <= 0)
    if back.size:
        i = int(back[0]) + 1
        how = "goes back" if times[i] < times[i - 1] else "repeats the row before's"
        rule = "the times must not decrease" if steps else "the times must increase"
        raise ScenarioError(f"{where}: {line_of(i)}, column {column}: time = {_num(times[i])} {how} "
                            f"(after {_num(times[i - 1])}); {rule}")
    if max_gap is not None:
        wide = np.flatnonzero(step > max_gap)
        if wide.size:
            i = int(wide[0]) + 1
            raise ScenarioError(f"{where}: {line_of(i)}, column {column}: time = {_num(times[i])} is "
                                f"{_num(step[i - 1])} s after the row before ({_num(times[i - 1])}); max_gap = "
                                f"{_num(max_gap)} s")


def _names(header: Sequence[str], where: str, told_units: Sequence[str | None] | None) -> tuple[list, list]:
    """Column names and units of a header (``x [m]``; the sidecar's units where it gives them)."""
    names, units = [], []
    for k, field in enumerate(header):
        name, unit = split_unit(field)
        told = told_units[k] if told_units is not None else None
        if unit is not None and told not in (None, unit):
            raise ScenarioError(f"{where}: column {name}: unit {unit!r} in the header but {told!r} in the sidecar")
        if not name:
            raise ScenarioError(f"{where}: header: column {k + 1} has no name")
        names.append(name)
        units.append(unit if unit is not None else told)
    unique_columns(names, where)  # "x" and "x [m]" are one name too
    if "time" in names and units[names.index("time")] not in (None, "s"):
        raise ScenarioError(f"{where}: column time: unit {units[names.index('time')]!r}; the time is in s")
    return names, units


def _chosen(names: Sequence[str], types: Mapping[str, str], use: Collection[str] | None, where: str) -> list[str]:
    """The data columns to read, in the file's order: those ``use`` names
    (a column, or an array column's element ``u[1]``), every one if ``None``;
    a declared or used name that is no column is refused in one line."""
    data = [n for n in names if n != "time"]
    wanted = set()
    for name, used in [*((n, False) for n in types), *((n, True) for n in use or ())]:
        base = name if name in data or not used else element_of(name)[0]
        if base not in data:
            raise ScenarioError(f"{where}: no column {name!r}; its columns are: {shown_text(', '.join(data), 300)}")
        if used:
            wanted.add(base)
    return data if use is None else [n for n in data if n in wanted]


def _sidecar(path: Path, header: Sequence[str]) -> tuple[list | None, list | None]:
    """Units and types of this engine's results file (its ``.json`` sidecar,
    :mod:`cosim.loop.recorder`) when it describes these very columns."""
    side = Path(str(path) + ".json")
    if not side.is_file():
        return None, None
    info = read_json(side, "results sidecar")
    if not isinstance(info, dict) or info.get("columns") != list(header):
        return None, None
    units, types = info.get("units"), info.get("types")
    ok = lambda v: isinstance(v, list) and len(v) == len(header)  # noqa: E731
    return ([u if isinstance(u, str) and u else None for u in units] if ok(units) else None,
            [t if t in TYPES else "Float64" for t in types] if ok(types) else None)


def _line(i: int) -> str:
    return f"line {i + 2}"  # a CSV's line: the header is line 1


class _Budget:
    """What the columns read may still hold (:data:`~cosim.limits.MAX_TABLE_DATA` in all)."""

    def __init__(self):
        self.left = MAX_TABLE_DATA

    def limits(self) -> dict:
        return {"nulls": False, "max_rows": MAX_TABLE_ROWS, "max_bytes": self.left}

    def took(self, columns: Mapping[str, Any]) -> None:
        self.left -= sum(v.nbytes if isinstance(v, np.ndarray) else 8 * len(v) for v in columns.values())


def _typed_columns(path: Path, where: str, kinds: Mapping[str, str], raw_of: Mapping[str, str], raw: Sequence[str],
                   names: Sequence[str], budget: _Budget) -> dict[str, Any]:
    """Columns read field by field as their types (:func:`typed_value`):
    every type, an array column (several numbers in a field, the same
    count in every row), the one-line refusal of a field that is none.
    Streamed as strings; a batch's Python objects are the most held."""
    import pyarrow as pa

    parts_of: dict[str, list] = {n: [] for n in kinds}
    sizes: dict[str, int] = {}
    at = 0
    for batch in csv_batches(path, where, {raw_of[n]: pa.string() for n in kinds}, raw, names, _line,
                             **budget.limits()):
        for name, type_ in kinds.items():
            values = []
            for k, field in enumerate(batch.column(raw_of[name]).to_pylist()):
                here = f"{where}: {_line(at + k)}, column {name}"
                # several numbers separated by spaces: an array column (a String keeps its spaces)
                parts = [field] if type_ == "String" else field.split() or [field]
                if type_ not in ("String", "Binary") and not all(p.strip() for p in parts):  # b"" is a Binary
                    raise ScenarioError(f"{here}: empty field")
                if sizes.setdefault(name, len(parts)) != len(parts):
                    raise ScenarioError(f"{here}: {len(parts)} values; the rows before have {sizes[name]}")
                try:
                    parsed = [typed_value(type_, p.strip() if type_ != "String" else p, "value") for p in parts]
                except ValueError as exc:
                    raise ScenarioError(f"{here}: {exc}") from None
                if type_ in ("Float64", "Float32") and not all(math.isfinite(v) for v in parsed):
                    raise ScenarioError(f"{here}: {field!r}: expected finite numbers")
                values.append(parsed if len(parts) > 1 else parsed[0])
            # numbers a double holds exactly (Booleans as 0/1) as float arrays, a batch at a time
            parts_of[name].append(np.array(values, dtype=float) if type_ in FLOAT_HELD else values)
        at += batch.num_rows
    out = {n: np.concatenate(p) if kinds[n] in FLOAT_HELD else [v for chunk in p for v in chunk]
           for n, p in parts_of.items()}
    budget.took(out)
    return out


def _csv_columns(path: Path, where: str, types: dict[str, str],
                 use: Collection[str] | None) -> tuple[np.ndarray, dict, dict, dict]:
    """A CSV table's time and the columns ``use`` names (:func:`_chosen`),
    read by :mod:`cosim.columns_io`: the Float64 and Float32 scalar columns
    by pyarrow's float parser (the value Python's ``float`` gives: both
    round correctly), a column that is not one field by field
    (:func:`_typed_columns`)."""
    regular_file(path, "signal table")
    raw = csv_header(path, where)
    if not raw:
        raise ScenarioError(f"{where}: empty (expected a header 'time,col1,...')")
    header = [h.strip() for h in raw]
    if split_unit(header[0])[0] != "time" or len(header) < 2:
        raise ScenarioError(f"{where}: header {shown_text(repr(','.join(header)), 200)}: expected 'time,col1,...'")
    told_units, told_types = _sidecar(path, header)
    names, units = _names(header, where, told_units)
    defaults = dict(zip(names, told_types)) if told_types is not None else {}
    chosen = _chosen(names, types, use, where)
    kinds = {n: types.get(n) or defaults.get(n) or "Float64" for n in chosen}
    raw_of = dict(zip(names, raw))
    budget = _Budget()
    try:
        times = csv_floats(path, where, {"time": raw[0]}, raw, names, _line, **budget.limits())["time"]
    except FieldError:
        times = _typed_columns(path, where, {"time": "Float64"}, raw_of, raw, names, budget)["time"]
        if times.ndim > 1:
            raise ScenarioError(f"{where}: column time: {times.shape[1]} values a row; one time a row") from None
    budget.took({"time": times})
    if times.size == 0:
        raise ScenarioError(f"{where}: no rows after the header")
    fast = [n for n in chosen if kinds[n] in ("Float64", "Float32")]
    columns: dict[str, Any] = {}
    while fast:
        try:
            columns = csv_floats(path, where, {n: raw_of[n] for n in fast}, raw, names, _line, times.size,
                                 **budget.limits())
        except FieldError as exc:  # not one number (an array, a typo): read field by field, its message
            if exc.column not in fast:
                raise
            fast.remove(exc.column)
            continue
        # a NaN or an infinity: field by field too, for the message naming the field as written
        fast = [n for n in fast if np.isfinite(columns[n]).all()]
        columns = {n: columns[n] for n in fast}
        break
    budget.took(columns)
    slow = {n: kinds[n] for n in chosen if n not in columns}
    if slow:
        columns.update(_typed_columns(path, where, slow, raw_of, raw, names, budget))
    columns = {n: columns[n] for n in chosen}
    return times, columns, {n: u for n, u in zip(names, units) if n in columns}, kinds


_ARROW_TYPES = {"double": "Float64", "float": "Float32", "halffloat": "Float32", "int8": "Int8",
                "int16": "Int16", "int32": "Int32", "int64": "Int64", "uint8": "UInt8", "uint16": "UInt16",
                "uint32": "UInt32", "uint64": "UInt64", "bool": "Boolean", "string": "String",
                "large_string": "String", "binary": "Binary", "large_binary": "Binary"}


def _parquet_columns(path: Path, where: str, types: dict[str, str],
                     use: Collection[str] | None) -> tuple[np.ndarray, dict, dict, dict]:
    """A Parquet table's time and the columns ``use`` names: bounded by its
    row count and the used columns' data uncompressed (from its footer,
    before any column is read), those columns' chunks alone read, each
    column's Arrow type its signal type (a declared type must be the same),
    units from the names or the field metadata ``unit``; rows counted from 1
    (the Parquet file has no lines)."""
    regular_file(path, "signal table")
    schema, meta = parquet_schema(path, where)
    n_rows = meta.num_rows
    if n_rows > MAX_TABLE_ROWS:
        raise ScenarioError(f"{where}: more than {MAX_TABLE_ROWS} rows ({n_rows}); at most {MAX_TABLE_ROWS} are read")
    if n_rows == 0:
        raise ScenarioError(f"{where}: no rows")
    header = list(schema.names)
    meta_units = [(f.metadata or {}).get(b"unit") for f in schema]
    names, units = _names(header, where, [m.decode("utf-8", "replace") if m else None for m in meta_units])
    if "time" not in names:
        raise ScenarioError(f"{where}: no column 'time'; its columns are: {shown_text(', '.join(names), 300)}")
    chosen = ["time", *_chosen(names, types, use, where)]
    raw_of = dict(zip(names, header))
    kinds: dict[str, str] = {}
    for name in chosen:  # the types from the schema: a column the table cannot hold is refused before any is read
        arrow = schema.field(raw_of[name]).type
        type_ = _ARROW_TYPES.get(str(arrow))
        if type_ is None:
            raise ScenarioError(f"{where}: column {name}: Arrow type {arrow}; a table holds numbers, "
                                f"Booleans, strings and bytes")
        if name == "time" and type_ not in FLOAT_HELD:
            raise ScenarioError(f"{where}: column time: {type_}; expected numbers")
        declared = types.get(name)
        if declared is not None and declared != type_:
            raise ScenarioError(f"{where}: column {name}: {type_} in the file, declared {declared}")
        kinds[name] = type_
    # the data read, from the footer: each column's pages uncompressed, at least a double a row (a page may
    # encode many equal values in a few bytes, which a read spells out)
    flat = meta.num_columns == len(names)  # one leaf a field: chunk j is field j (else every chunk counts)
    read = [j for j in range(meta.num_columns) if not flat or names[j] in kinds]
    data = sum(max(sum(meta.row_group(g).column(j).total_uncompressed_size for g in range(meta.num_row_groups)),
                   8 * n_rows) for j in read)
    if data > MAX_TABLE_DATA:
        raise ScenarioError(f"{where}: {data} bytes of data uncompressed in the columns used; at most "
                            f"{MAX_TABLE_DATA} are read")
    table = parquet_read(path, where, [raw_of[n] for n in chosen])
    columns: dict[str, Any] = {}
    times = None
    for name in chosen:
        array, type_ = table.column(raw_of[name]), kinds[name]
        if array.null_count:
            i = int(np.flatnonzero(np.asarray(array.is_null()))[0])
            raise ScenarioError(f"{where}: row {i + 1}, column {name}: no value (null)")
        if name == "time":
            times = np.asarray(array.to_numpy(zero_copy_only=False), dtype=float)
        elif type_ in FLOAT_HELD:
            values = np.asarray(array.to_numpy(zero_copy_only=False), dtype=float)
            if type_ in ("Float64", "Float32") and not np.isfinite(values).all():
                i = int(np.flatnonzero(~np.isfinite(values))[0])
                raise ScenarioError(f"{where}: row {i + 1}, column {name}: {values[i]!r}: expected finite numbers")
            columns[name] = values
        else:
            columns[name] = array.to_pylist()
    del kinds["time"]
    return times, columns, {n: u for n, u in zip(names, units) if n in columns}, kinds


@dataclass(frozen=True)
class RecordedTable:
    """A table file as read: the times, per column its values (a float64
    array -- rows, or rows x elements -- for the types a double holds
    exactly, else a list), its unit (``None``: none given) and type."""

    path: Path
    times: np.ndarray
    columns: Mapping[str, Any]
    units: Mapping[str, str | None]
    types: Mapping[str, str]


def load_table(path: str | Path, types: Mapping[str, str] | None = None, max_gap: float | None = None,
               steps: bool = True, use: Collection[str] | None = None) -> RecordedTable:
    """The CSV or Parquet table ``path`` (by its suffix): its time and the
    columns ``use`` names (a column, or an element ``u[1]`` of an array
    column; ``None``: every column), no other column read; every field read
    as its column's type (``types``, default Float64 or the results
    sidecar's), the time column checked (:func:`check_times` with
    ``max_gap`` and ``steps``). One-line :class:`ScenarioError` otherwise."""
    path = Path(path)
    where = f"signal table {str(path)!r}"
    types = dict(types or {})  # a column named with no type: checked to exist, its type the default
    parquet = path.suffix.lower() in PARQUET_SUFFIXES
    times, columns, units, kinds = (_parquet_columns if parquet else _csv_columns)(path, where, types, use)
    check_times(times, where, max_gap=max_gap, steps=steps, line_of=(lambda i: f"row {i + 1}") if parquet
                else _line)
    return RecordedTable(path, times, columns, units, kinds)


def read_table(path: str | Path, types: Mapping[str, str] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """``(times, columns)`` of the table ``path`` (:func:`load_table`)."""
    table = load_table(path, types)
    return table.times, dict(table.columns)


@dataclass(frozen=True, eq=False)
class TableData:
    """What the table FMU is built from (:func:`cosim.scenario.registry.register_table_fmu`):
    the column names, their units (``""``: none) and SI definitions
    (:class:`cosim.fmi.units.Unit` as ``<BaseUnit>`` attributes, ``None`` when
    unknown), descriptions, ``linear`` per column, ``refuse_outside``, the
    times and the values (rows x columns)."""

    columns: tuple[str, ...]
    units: tuple[str, ...]
    base_units: tuple[Mapping[str, float] | None, ...]
    descriptions: tuple[str, ...]
    linear: tuple[bool, ...]
    refuse_outside: bool
    times: np.ndarray
    values: np.ndarray


def _base_unit(name: str) -> Mapping[str, float] | None:
    from ..fmi import units

    unit = units.parse(name)
    if unit is None:
        return None
    base: dict[str, float] = {b: e for b, e in zip(units.BASE_UNITS, unit.exponents) if e}
    if unit.factor != 1.0:
        base["factor"] = unit.factor
    if unit.offset != 0.0:
        base["offset"] = unit.offset
    return base


class SignalTable(PythonComponent):
    """A recorded table's columns as outputs (module docstring).

    ``columns`` gives, per column, ``{"type", "unit", "interpolation"}``
    (any may be left out: Float64 or the results sidecar's type, the file's
    unit, the table's ``interpolation``); ``outside``: ``"hold"`` or
    ``"refuse"``; ``max_gap``: the widest gap between rows [s];
    ``duplicates``: ``"step"`` or ``"refuse"`` (two rows at one time);
    ``use``: the columns played (:func:`load_table`; ``None``: every one),
    the only ones read. :meth:`values_at` gives every output's value at a
    time; :meth:`fmu_data` what the table FMU is built from.
    """

    def __init__(self, name: str, file: str | Path, interpolation: str = "hold",
                 columns: Mapping[str, Mapping[str, Any]] | None = None, outside: str = OUTSIDE[0],
                 max_gap: float | None = None, duplicates: str = "step", use: Collection[str] | None = None):
        super().__init__(name)
        self.path = Path(file)
        specs = {k: dict(v) for k, v in (columns or {}).items()}
        for key, value, allowed in (("interpolation", interpolation, INTERPOLATIONS), ("outside", outside, OUTSIDE),
                                    ("duplicates", duplicates, DUPLICATES)):
            if value not in allowed:
                raise ScenarioError(f"{name}.{key} = {value!r}: expected one of {', '.join(allowed)}")
        self.outside = outside
        recorded = load_table(self.path, {k: v.get("type") for k, v in specs.items()}, max_gap,
                              steps=duplicates == "step", use=use)
        self.times = recorded.times
        ports, self._columns = [], []
        for column, data in recorded.columns.items():
            spec = specs.get(column, {})
            type_ = recorded.types[column]
            unit = recorded.units.get(column)
            if spec.get("unit") is not None and unit not in (None, spec["unit"]):
                raise ScenarioError(f"{name}.columns.{column}.unit = {spec['unit']!r}: the file {self.path.name} "
                                    f"gives {unit!r}")
            unit = spec.get("unit") or unit
            how = spec.get("interpolation") or interpolation
            if how == "linear" and type_ not in ("Float64", "Float32"):
                raise ScenarioError(f"{name}.columns.{column}.interpolation = 'linear': a {type_} column is held "
                                    f"('hold'); only Float32 and Float64 columns interpolate")
            first = data[0]
            shape = (len(first),) if isinstance(first, (list, np.ndarray)) and np.ndim(first) == 1 else ()
            ports.append(Port(column, unit, type_, f"column {column} of {self.path.name}", shape=shape))
            self._columns.append((data, how, type_, shape))
        self.outputs = tuple(ports)
        self._typed = any(p.type != "Float64" for p in self.outputs)
        self._n = len(element_ports(self.outputs))
        self._y = np.zeros(self._n)

    @property
    def fmu_form(self) -> bool:
        """Whether the table FMU can play it: every column a Float64 scalar."""
        return all(p.type == "Float64" and not p.shape for p in self.outputs)

    def check_span(self, t0: float, t_end: float) -> None:
        """With ``outside = "refuse"``: a one-line :class:`ScenarioError`,
        naming the table, its file, its first and last times and the run's
        span, if ``[t0, t_end]`` leaves the recorded times (within 1e-9 relative)."""
        first, last = float(self.times[0]), float(self.times[-1])
        early = t0 < first and not math.isclose(t0, first, rel_tol=TOLERANCE)
        late = t_end > last and not math.isclose(t_end, last, rel_tol=TOLERANCE)
        if self.outside == "refuse" and (early or late):
            raise ScenarioError(f"{self.name}: the run from t = {_num(t0)} to {_num(t_end)} s leaves signal table "
                                f"{str(self.path)!r}, whose rows run from t = {_num(first)} to {_num(last)} s "
                                f"(outside = 'refuse'; outside = 'hold' holds its first and last rows there)")

    def start(self, t0: float, h: float, n_steps: int, seed: int) -> None:
        self.check_span(t0, t0 + n_steps * h)

    def _row(self, t: float) -> int:
        """The last row whose time is ``<= t`` (within 1e-9 relative), -1 before the first."""
        times = self.times
        i = int(np.searchsorted(times, t, side="right")) - 1
        while i + 1 < len(times) and math.isclose(times[i + 1], t, rel_tol=TOLERANCE):
            i += 1
        return i

    def values_at(self, t: float) -> list:
        """Every output's value at ``t``, an array's elements in order."""
        i, times, out = self._row(t), self.times, []
        last = len(times) - 1
        for data, how, type_, shape in self._columns:
            if i < 0 or i == last or how == "hold":
                row = data[max(i, 0)]
            else:
                t0, t1 = times[i], times[i + 1]
                w = max(0.0, (t - t0) / (t1 - t0))  # t within 1e-9 below row i's time: that row
                row = data[i] + w * (data[i + 1] - data[i])
            if shape:
                out.extend(row.tolist() if isinstance(row, np.ndarray) else row)
            elif type_ in FLOAT_HELD:
                value = float(row)
                out.append(value if type_ in ("Float64", "Float32") else bool(value) if type_ == "Boolean"
                           else int(value))
            else:
                out.append(row)
        return out

    def step(self, n: int, t: float, u) -> np.ndarray | list:
        values = self.values_at(t)
        if self._typed:
            return values
        self._y[:] = values
        return self._y

    def fmu_data(self) -> TableData:
        """What the table FMU of this table is built from (Float64 scalar columns only)."""
        if not self.fmu_form:
            typed = next(p for p in self.outputs if p.type != "Float64" or p.shape)
            what = f"an array column ({typed.name})" if typed.shape else f"a {typed.type} column ({typed.name})"
            raise ScenarioError(f"components.{self.name}.form = 'fmu': {what}; the table FMU plays Float64 "
                                f"scalar columns only (form = 'python' plays any)")
        units = tuple(p.unit or "" for p in self.outputs)
        return TableData(tuple(p.name for p in self.outputs), units, tuple(_base_unit(u) if u else None for u in units),
                         tuple(p.description for p in self.outputs),
                         tuple(how == "linear" for _, how, _, _ in self._columns), self.outside == "refuse",
                         self.times,  # float64 arrays as read: not copied again (a column may be millions of rows)
                         np.column_stack([data for data, _, _, _ in self._columns]))


def played(name: str, context) -> set[str] | None:
    """The outputs of the table ``name`` its scenario uses: the sources of
    its connections, its signals recorded or bounded (``[envelope]``);
    ``None`` (every column) without a scenario or where it records every
    output (no ``record.signals``)."""
    scenario = getattr(context, "scenario", None)
    if scenario is None or getattr(scenario, "record", None) is None:
        return None
    from ..loop.connection import parse_connections
    from ..names import split_endpoint

    # the instances as the context holds them: iterating the scenario's [fmus] would count as reading each entry
    instances = (*getattr(context, "fmus", {}), *scenario.components)
    used = {c.source.variable for c in parse_connections(scenario.connections, instances)
            if c.source.component == name}
    for signal in (*scenario.record, *scenario.envelope):
        split = split_endpoint(signal, instances)
        if split is not None and split[0] == name:
            used.add(split[1])
    return used


def _table(name: str, params: Mapping[str, Any], context) -> SignalTable:
    path = Path(params["file"])
    source = getattr(getattr(context, "scenario", None), "source", None)
    if not path.is_absolute() and source is not None:
        path = Path(source).parent / path
    return SignalTable(name, path, params.get("interpolation", "hold"),
                       {k: dict(v) for k, v in (params.get("columns") or {}).items()},
                       params.get("outside", OUTSIDE[0]), params.get("max_gap"), params.get("duplicates", "step"),
                       use=played(name, context))


def _fmu_path(table: SignalTable, params: Mapping[str, Any], builder) -> Path | None:
    """The table FMU of ``table`` if its form is one (``None``: the Python
    component); ``builder``: the registered one (:func:`cosim.scenario.registry.table_fmu`)."""
    form = params.get("form", "auto")
    if form == "python" or (form == "auto" and (builder is None or not table.fmu_form)):
        return None
    if builder is None:
        raise ScenarioError(f"components.{table.name}.form = 'fmu': no table FMU builder is registered "
                            f"(cosim.scenario.registry.register_table_fmu); form = 'python' runs it in process")
    return Path(builder(table.fmu_data(), int(params.get("fmi_version", 2))))


def table_component(name: str, params: Mapping[str, Any], context=None, builder=None):
    """The component of a ``kind = "signal_table"`` table ``params``: the
    table FMU (an :class:`~cosim.fmi.fmu.FmuComponent`, made by
    ``builder``: :func:`cosim.scenario.registry.table_fmu`'s) or the
    :class:`SignalTable` itself, per its ``form``; ``file`` relative to the
    scenario file. With ``outside = "refuse"`` a scenario whose run leaves
    the table's times is refused here, before anything runs."""
    table = _table(name, params, context)
    scenario = getattr(context, "scenario", None)
    if scenario is not None and getattr(scenario, "duration", None) is not None:
        t0 = float(getattr(scenario, "start_time", 0.0) or 0.0)
        table.check_span(t0, t0 + float(scenario.duration))
    path = _fmu_path(table, params, builder)
    if path is None:
        return table
    from ..fmi.fmu import FmuComponent

    return FmuComponent(name, path)


def fmu_entry(name: str, params: Mapping[str, Any], context=None, builder=None) -> dict[str, Any]:
    """The ``[fmus]`` entry a table runs as in an all-FMU scenario (an SSP
    archive): its table FMU (made by ``builder``), FMI 2.0 unless it says
    otherwise (libcosim runs 2.0), the table inside it."""
    table = _table(name, params, context)
    path = _fmu_path(table, {**params, "form": "fmu"}, builder)
    return {"path": str(path)}


build = table_component  # the registered kind's factory (cosim.scenario.registry passes its builder)
