"""Recording of selected signals, streamed to a CSV file as the run goes.

Rows are kept in a preallocated array (the run's result, for plots and
metrics) and appended to the CSV in blocks of ``block_rows`` rows (default
100, i.e. 1 s at dt = 0.01 s), each block written and flushed at once. A run
that fails keeps every row up to the failure (the remaining rows are flushed
on the way out); a process killed from outside loses at most the last
unflushed block. :func:`read_results` reads a complete or partial file.

Beside ``results.csv`` a sidecar ``results.csv.json`` holds the columns,
their units, the step, the rows on disk (brought up to date as blocks are
flushed, at least once a second) and the run's status (``running`` until the
run ends, then ``ok``, ``diverged`` or ``failed`` with the error message).

The rows in memory are the run's result: a run whose recording would need
more than :data:`MAX_RECORD_BYTES` is refused before it starts, with what it
would need (``docs/security.md``); the recorded String and Binary values
count too, as they are recorded (one longer than :data:`MAX_STRING_BYTES`,
or all of them beyond what is left of that bound, stop the run).

Typed columns are written as their type reads (docs/cosim.md, "Signal
types"): floats to the last bit, integers (Int8..UInt64,
Enumeration) as whole numbers, Booleans as ``true``/``false``, Strings
quoted (a quote doubled, RFC 4180), Binary as hexadecimal digits, as the
Reference FMUs' ``_out.csv`` files write them.
"""
from __future__ import annotations

import csv
import io
import json
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import CosimError, ScenarioError
from .limits import MAX_RECORD_BYTES, MAX_STRING_BYTES

__all__ = ["Recorder", "read_results", "sidecar_path", "record_bytes"]

_FLOATS = ("Float64", "Float32")
_TEXTS = ("String", "Binary")


def _quoted(text: str) -> str:
    return '"' + text.replace('"', '""') + '"'

SIDECAR_EVERY = 1.0  # s of wall time between updates of the sidecar's row count


def record_bytes(n_rows: int, n_columns: int) -> int:
    """Memory the rows of a run take (float64)."""
    return 8 * n_rows * n_columns


def sidecar_path(csv_path: str | Path) -> Path:
    return Path(str(csv_path) + ".json")


class Recorder:
    """Rows of ``columns`` (the first is ``time``), kept in :attr:`data` and
    streamed to ``path`` (if given).

    The master writes row ``n`` straight into ``data[n]`` and calls
    :meth:`commit` after each row; :meth:`close` flushes the rest.
    """

    def __init__(self, columns: Sequence[str], units: Sequence[str | None], n_rows: int,
                 path: str | Path | None = None, block_rows: int = 100, meta: dict | None = None,
                 digits: int | None = None, types: Sequence[str] = (), objects: Sequence[tuple[int, int]] = ()):
        if block_rows < 1:
            raise ValueError(f"block_rows = {block_rows} must be at least 1")
        self.columns, self.units = tuple(columns), tuple(units)
        self.types = tuple(types) or ("Float64",) * len(self.columns)
        # columns held as objects (Int64, UInt64, String, Binary): (column, object slot)
        self._object_columns = np.array([k for k, _ in objects], dtype=np.intp)
        self._object_slots = np.array([slot for _, slot in objects], dtype=np.intp)
        self.objects = np.full((n_rows, len(objects)), None, dtype=object)
        self._texts = [j for j, (k, _) in enumerate(objects) if self.types[k] in _TEXTS]
        self._text_bytes = 0
        need = record_bytes(n_rows, len(self.columns))
        if need > MAX_RECORD_BYTES:
            raise ScenarioError(f"simulation.duration: {n_rows} rows of {len(self.columns)} recorded signals need "
                                f"{need / 2 ** 30:.1f} GiB in memory; at most {MAX_RECORD_BYTES / 2 ** 30:.0f} GiB "
                                f"(record fewer signals, or run a shorter mission)")
        self.data = np.full((n_rows, len(self.columns)), np.nan)
        self.n_rows = 0  # rows written into data
        self.path = Path(path) if path is not None else None
        self.block_rows = block_rows
        self.meta = dict(meta or {})
        self._flushed = 0
        self._told = time.monotonic()
        # default: each value as the shortest text that reads back to the same double (Python's repr), so a
        # results file is the run, to the last bit; ``digits``: that many significant digits
        number = "%r" if digits is None else f"%.{digits}g"
        self._fmt = ",".join([number] * len(self.columns)) + "\n"
        self._typed = any(t not in _FLOATS for t in self.types)
        if self._typed:
            self._formats = [(lambda v, f=number: f % float(v)) if t in _FLOATS else
                             (lambda v: "true" if v else "false") if t == "Boolean" else
                             _quoted if t == "String" else bytes.hex if t == "Binary" else
                             (lambda v: str(int(v))) for t in self.types]
        self._file = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w", encoding="utf-8", newline="")
            self._file.write(",".join(self.columns) + "\n")
            self._file.flush()
            self._write_sidecar("running", None)

    def _write_sidecar(self, status: str, error: str | None) -> None:
        info = {"columns": list(self.columns), "units": list(self.units), "types": list(self.types),
                "rows": self._flushed,
                "status": status, "error": error, **self.meta}
        sidecar_path(self.path).write_text(json.dumps(info, indent=1))

    def record_objects(self, n: int, values: np.ndarray) -> None:
        """Row ``n`` of the columns held as objects, from the master's object
        slots ``values``; Strings and Binaries counted against the bound."""
        row = values[self._object_slots]
        for j in self._texts:
            size = len(row[j])
            if size > MAX_STRING_BYTES:
                raise CosimError(f"recording {self.columns[self._object_columns[j]]}: a value of {size} bytes; at "
                                 f"most {MAX_STRING_BYTES} bytes each are recorded")
            self._text_bytes += size
        if self._text_bytes + 8 * self.data.size > MAX_RECORD_BYTES:
            raise CosimError(f"recording: the String and Binary values recorded reach {self._text_bytes} bytes; "
                             f"with the numbers, at most {MAX_RECORD_BYTES} bytes are kept (record fewer signals)")
        self.objects[n] = row
        self.data[n, self._object_columns] = np.nan  # the numbers' array has no value for them

    def object_columns(self) -> dict[str, np.ndarray]:
        """The columns held as objects, by name (rows written so far)."""
        return {self.columns[k]: self.objects[:self.n_rows, j].copy() for j, k in enumerate(self._object_columns)}

    def commit(self, n_rows: int) -> None:
        """Row ``n_rows - 1`` is complete; flush a block when one is full."""
        self.n_rows = n_rows
        if self._file is not None and n_rows - self._flushed >= self.block_rows:
            self.flush()

    def flush(self) -> None:
        if self._file is None or self.n_rows <= self._flushed:
            self._flushed = max(self._flushed, self.n_rows)
            return
        if self._typed:
            self._file.write(self._typed_rows(self._flushed, self.n_rows))
        else:
            fmt = self._fmt
            block = self.data[self._flushed:self.n_rows].tolist()
            self._file.write("".join(fmt % tuple(row) for row in block))
        self._file.flush()
        self._flushed = self.n_rows
        now = time.monotonic()
        if now - self._told >= SIDECAR_EVERY:  # what is on disk, said while the run goes on (a kill loses no count)
            self._told = now
            self._write_sidecar("running", None)

    def _typed_rows(self, first: int, last: int) -> str:
        """Rows ``first`` to ``last`` (excluded), each value written as its type reads."""
        rows = self.data[first:last].astype(object)
        if self._object_columns.size:
            rows[:, self._object_columns] = self.objects[first:last]
        return "".join(",".join(f(v) for f, v in zip(self._formats, row)) + "\n" for row in rows.tolist())

    def close(self, status: str = "ok", error: str | None = None) -> None:
        if self._file is None:
            return
        try:
            self.flush()
        finally:
            self._file.close()
            self._file = None
            self._write_sidecar(status, error)

    def column(self, name: str) -> np.ndarray:
        """The recorded values of one column (rows written so far)."""
        return self.data[:self.n_rows, self.columns.index(name)]


def read_results(path: str | Path) -> tuple[list[str], np.ndarray]:
    """Columns and rows of a results CSV, complete or cut short, as numbers.

    A last line cut by a killed process is dropped (every row is written
    with its newline, so a last line without one is cut, even if it has all
    its fields); everything before it is returned. Booleans read as 1/0;
    the columns the sidecar types String or Binary read as NaN (read the
    file with the csv module for their text); an Int64 beyond 2^53 is
    rounded here, as every number of this array is a double.
    """
    text = Path(path).read_text(encoding="utf-8")
    records = list(csv.reader(io.StringIO(text, newline="")))
    if records and not text.endswith("\n"):
        records = records[:-1] if len(records) > 1 else records
    if not records:
        raise ValueError(f"{path}: empty results file (no header)")
    columns = records[0]
    types = ["Float64"] * len(columns)
    side = sidecar_path(path)
    if side.is_file():
        try:
            told = json.loads(side.read_text(encoding="utf-8")).get("types")
        except (ValueError, OSError):
            told = None
        if isinstance(told, list) and len(told) == len(columns):
            types = told
    words = {"true": 1.0, "false": 0.0}
    rows = []
    for fields in records[1:]:
        if len(fields) != len(columns):
            break
        try:
            rows.append([np.nan if t in _TEXTS else words[f] if f in words else float(f)
                         for f, t in zip(fields, types)])
        except ValueError:
            break
    data = np.array(rows, dtype=float).reshape(len(rows), len(columns))
    return columns, data
