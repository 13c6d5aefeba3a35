"""The signal table: a CSV file played as outputs (``kind = "signal_table"``).

The engine's one table component (it knows no model): a file with a header
``time,col1,col2,...`` and one row per instant, as the Reference FMUs'
``<Model>_in.csv`` input tables, becomes a source whose outputs are the
columns (docs/cosim.md, "The signal table"):

* **types** per column, declared in the scenario (default ``Float64``): any
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
  event). Before the first row the first value holds, after the last row
  the last;
* **units** per column (optional), checked on connections like any port's.

The file is data from anyone: read whole, it is bounded
(:data:`~cosim.limits.MAX_TABLE_BYTES`, :data:`~cosim.limits.MAX_TABLE_ROWS`),
every field checked against its column's type, in one line naming the file,
the row and the column (``docs/security.md``).
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from pydantic import Field

from .component import FLOAT_HELD, TYPES, Port, PythonComponent, element_ports, typed_value
from .errors import ScenarioError
from .files import read_text
from .limits import MAX_TABLE_BYTES, MAX_TABLE_ROWS
from .schema import Table, one_of

__all__ = ["SignalTable", "read_table", "KIND", "INTERPOLATIONS"]

KIND = "signal_table"
INTERPOLATIONS = ("hold", "linear")


class ColumnSpec(Table):
    """``[components.<name>.columns.<column>]``: one column's declaration."""

    type: one_of(TYPES) = Field("Float64", description="its signal type (docs/cosim.md, 'Signal types')")
    unit: str = Field(None, description="its unit (checked on connections)")
    interpolation: one_of(INTERPOLATIONS) = Field(None, description="'hold' or 'linear' (default: the table's)")


class TableSpec(Table):
    """``[components.<name>] kind = "signal_table"``: a CSV file played as outputs."""

    file: str = Field(..., description="the CSV file (relative to the scenario file): a header 'time,col1,...', "
                                       "one row per instant")
    interpolation: one_of(INTERPOLATIONS) = Field("hold", description="every column's, unless it says its own: "
                                                                      "'hold' (sample and hold) or 'linear'")
    columns: dict[str, ColumnSpec] = Field(default_factory=dict, description="type, unit, interpolation per "
                                                                             "column (default Float64)")


def _parse(text: str, where: str) -> tuple[list[str], list[list[str]]]:
    """The header and rows of a CSV text, bounded and rectangular."""
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader)
    except StopIteration:
        raise ScenarioError(f"{where}: empty (expected a header 'time,col1,...')") from None
    except csv.Error as exc:
        raise ScenarioError(f"{where}: line 1: {exc}") from None
    header = [h.strip() for h in header]
    if not header or header[0] != "time" or len(header) < 2:
        raise ScenarioError(f"{where}: header {','.join(header)!r}: expected 'time,col1,...'")
    seen = set()
    for name in header[1:]:
        if not name or name in seen or name == "time":
            raise ScenarioError(f"{where}: header: column name {name!r} is empty or repeated")
        seen.add(name)
    rows = []
    try:
        for line, row in enumerate(reader, start=2):
            if not row:
                continue
            if len(rows) >= MAX_TABLE_ROWS:
                raise ScenarioError(f"{where}: more than {MAX_TABLE_ROWS} rows; at most {MAX_TABLE_ROWS} are read")
            if len(row) != len(header):
                raise ScenarioError(f"{where}: line {line}: {len(row)} fields for {len(header)} columns")
            rows.append(row)
    except csv.Error as exc:
        raise ScenarioError(f"{where}: line {reader.line_num}: {exc}") from None
    if not rows:
        raise ScenarioError(f"{where}: no rows after the header")
    return header, rows


def read_table(path: str | Path, types: Mapping[str, str] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """``(times, columns)`` of the CSV signal table ``path``: the time column
    (finite, non-decreasing) and, per column, its values -- a float64 array
    (rows, or rows x elements for an array column) for the types a double
    holds exactly, else a list of Python values (int, str, bytes; a list of
    lists for an array column) -- each field read as its column's type
    (``types``, default Float64). One-line :class:`ScenarioError` otherwise."""
    path = Path(path)
    where = f"signal table {str(path)!r}"
    header, rows = _parse(read_text(path, "signal table", limit=MAX_TABLE_BYTES), where)
    types = dict(types or {})
    unknown = sorted(set(types) - set(header[1:]))
    if unknown:
        raise ScenarioError(f"{where}: no column {unknown[0]!r}; its columns are: {', '.join(header[1:])}")
    times = np.empty(len(rows))
    for i, row in enumerate(rows):
        try:
            times[i] = float(row[0])
        except ValueError:
            raise ScenarioError(f"{where}: line {i + 2}: time = {row[0]!r}: expected a number") from None
    if not np.isfinite(times).all():
        i = int(np.argmin(np.isfinite(times)))
        raise ScenarioError(f"{where}: line {i + 2}: time = {rows[i][0]!r}: expected a finite number")
    back = np.flatnonzero(np.diff(times) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise ScenarioError(f"{where}: line {i + 2}: time = {rows[i][0]} goes back (after {rows[i - 1][0]}); "
                            f"the times must not decrease")
    columns: dict[str, Any] = {}
    for j, name in enumerate(header[1:], start=1):
        type_ = types.get(name, "Float64")
        fields = [row[j] for row in rows]
        # several numbers separated by spaces: an array column (a String keeps its spaces)
        split = type_ != "String" and any(len(f.split()) > 1 for f in fields)
        values = []
        size = None
        for i, field in enumerate(fields):
            parts = field.split() if split else [field]
            if split and size is not None and len(parts) != size:
                raise ScenarioError(f"{where}: line {i + 2}, column {name}: {len(parts)} values; the rows before "
                                    f"have {size}")
            size = len(parts)
            if type_ not in ("String", "Binary") and not all(p.strip() for p in parts):  # b"" is a Binary
                raise ScenarioError(f"{where}: line {i + 2}, column {name}: empty field")
            try:
                parsed = [typed_value(type_, p.strip() if type_ != "String" else p, "value") for p in parts]
            except ValueError as exc:
                raise ScenarioError(f"{where}: line {i + 2}, column {name}: {exc}") from None
            if type_ in ("Float64", "Float32") and not all(math.isfinite(v) for v in parsed):
                raise ScenarioError(f"{where}: line {i + 2}, column {name}: {field!r}: expected finite numbers")
            values.append(parsed if split else parsed[0])
        if type_ in FLOAT_HELD:
            columns[name] = np.array(values, dtype=float)  # Booleans as 0/1
        else:
            columns[name] = values
    return times, columns


class SignalTable(PythonComponent):
    """A CSV signal table's columns as outputs (module docstring).

    ``columns`` gives, per column, ``{"type", "unit", "interpolation"}``
    (any may be left out: Float64, no unit, the table's ``interpolation``).
    """

    def __init__(self, name: str, file: str | Path, interpolation: str = "hold",
                 columns: Mapping[str, Mapping[str, Any]] | None = None):
        super().__init__(name)
        self.path = Path(file)
        specs = {k: dict(v) for k, v in (columns or {}).items()}
        if interpolation not in INTERPOLATIONS:
            raise ScenarioError(f"{name}.interpolation = {interpolation!r}: expected one of "
                                f"{', '.join(INTERPOLATIONS)}")
        self.times, values = read_table(self.path, {k: v.get("type", "Float64") for k, v in specs.items()})
        ports, self._columns = [], []
        for column, data in values.items():
            spec = specs.get(column, {})
            type_ = spec.get("type") or "Float64"
            how = spec.get("interpolation") or interpolation
            if how == "linear" and type_ not in ("Float64", "Float32"):
                raise ScenarioError(f"{name}.columns.{column}.interpolation = 'linear': a {type_} column is held "
                                    f"('hold'); only Float32 and Float64 columns interpolate")
            first = data[0]
            shape = (len(first),) if isinstance(first, (list, np.ndarray)) and np.ndim(first) == 1 else ()
            ports.append(Port(column, spec.get("unit"), type_, f"column {column} of {self.path.name}", shape=shape))
            self._columns.append((data, how, type_, shape))
        self.outputs = tuple(ports)
        self._typed = any(p.type != "Float64" for p in self.outputs)
        self._n = len(element_ports(self.outputs))
        self._y = np.zeros(self._n)

    def _row(self, t: float) -> int:
        """The last row whose time is ``<= t`` (within 1e-9 relative), -1 before the first."""
        times = self.times
        i = int(np.searchsorted(times, t, side="right")) - 1
        while i + 1 < len(times) and math.isclose(times[i + 1], t, rel_tol=1e-9):
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


def build(name: str, params: Mapping[str, Any], context) -> SignalTable:
    """The registered kind's factory: ``file`` relative to the scenario file."""
    path = Path(params["file"])
    source = getattr(context.scenario, "source", None)
    if not path.is_absolute() and source is not None:
        path = Path(source).parent / path
    return SignalTable(name, path, params.get("interpolation", "hold"),
                       {k: dict(v) for k, v in (params.get("columns") or {}).items()})
