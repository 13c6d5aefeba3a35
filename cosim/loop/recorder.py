"""Recording of selected signals, streamed to a CSV file as the run goes.

The recorder holds at most a chunk of rows in memory (:data:`CHUNK_ROWS`
rounded up to whole blocks; the compiled and the Python loop write row
``n`` into :meth:`Recorder.row`), whatever the run's length:

* the CSV gets them in blocks of ``block_rows`` rows (default 100, i.e. 1 s
  at dt = 0.01 s; at most :data:`CHUNK_ROWS`), each block written and
  flushed at once; with ``every = k`` only every k-th row (rows 0, k, 2k,
  ...) is written. A run that fails keeps every row up to the failure (the
  remaining rows are flushed on the way out); a process killed from
  outside loses at most the last unflushed block. :func:`read_results`
  reads a complete or partial file, :func:`iter_results` reads it in blocks;
* the ``observers`` (anything with ``add(rows)``, e.g. a run's metrics taken
  as the rows stream: :mod:`cosim.loop.online`) get each chunk as :class:`Rows`,
  in order, once it is complete (and the rest when the run ends);
* the rows the run's result keeps (``keep``): all of them (``None``, the
  default: bounded by :data:`MAX_RECORD_BYTES`, refused before the run
  starts with what it would need), none (``0``), or at most ``keep`` rows,
  evenly thinned as the run goes (every ``stride``-th row, the stride
  doubling whenever they would pass ``keep``), and the last row: what a plot
  of any length of run draws, in bounded memory (``docs/security.md``).

Beside ``results.csv`` a sidecar ``results.csv.json`` holds the columns,
their units, the step, the rows on disk (brought up to date as blocks are
flushed, at least once a second) and the run's status (``running`` until the
run ends, then ``ok``, ``diverged`` or ``failed`` with the error message).
A recorded String or Binary value longer than :data:`MAX_STRING_BYTES`
stops the run, and so do those the result keeps beyond what is left of
:data:`MAX_RECORD_BYTES` with the numbers.

Typed columns are written as their type reads (docs/cosim.md, "Signal
types"): floats to the last bit, integers (Int8..UInt64,
Enumeration) as whole numbers, Booleans as ``true``/``false``, Strings
quoted (a quote doubled, RFC 4180), Binary as hexadecimal digits, as the
Reference FMUs' ``_out.csv`` files write them.
"""
from __future__ import annotations

import io
import itertools
import json
import time
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np
import orjson

from ..errors import CosimError, ScenarioError
from ..limits import MAX_RECORD_BYTES, MAX_STRING_BYTES

__all__ = ["Recorder", "Rows", "read_results", "iter_results", "shortest_rows", "sidecar_path", "record_bytes", "csv_bytes",
           "CHUNK_ROWS"]

_FLOATS = ("Float64", "Float32")
_TEXTS = ("String", "Binary")
CHUNK_ROWS = 4096  # rows held in memory while they are recorded (rounded up to whole blocks)
# the longest text of a value of each type as the results file writes it (a double's shortest text: 24 characters)
_WIDTH = {"Float64": 24, "Float32": 24, "Boolean": 5, "String": 2, "Binary": 0}


def _quoted(text: str) -> str:
    return '"' + text.replace('"', '""') + '"'

SIDECAR_EVERY = 1.0  # s of wall time between updates of the sidecar's row count


def record_bytes(n_rows: int, n_columns: int) -> int:
    """Memory the rows of a run take (float64)."""
    return 8 * n_rows * n_columns


def csv_bytes(n_rows: int, columns: Sequence[str], types: Sequence[str] = ()) -> int:
    """At most the bytes of a results file of ``n_rows`` rows of ``columns``
    (a String or Binary value counted empty: their length is the FMU's)."""
    types = tuple(types) or ("Float64",) * len(columns)
    row = sum(_WIDTH.get(t, 20) + 1 for t in types)  # integers up to 20 characters; a comma or the newline
    return len(",".join(columns)) + 1 + n_rows * row


def shortest_rows(block: np.ndarray) -> str:
    """Rows of doubles as CSV lines, each value the shortest text that reads
    back to the same double, as Python's ``repr`` chooses its digits.

    orjson writes them (Ryu: about 10x Python's ``repr``, which spends most of
    a long mission's time on the 17-digit values a flight produces); only the
    exponent's spelling differs from ``repr`` (``1e-7``, not ``1e-07``; small
    values positional: ``0.00001``), and every reader reads both. JSON has
    no NaN or infinity (orjson writes ``null``), so a block holding one is
    written by ``repr`` (``nan``, ``inf``)."""
    if not len(block):
        return ""
    if not np.isfinite(block).all():
        return "".join(",".join(map(repr, row)) + "\n" for row in block.tolist())
    text = orjson.dumps(np.ascontiguousarray(block, dtype=np.float64), option=orjson.OPT_SERIALIZE_NUMPY)
    return text[2:-2].replace(b"],[", b"\n").decode("ascii") + "\n"


def sidecar_path(csv_path: str | Path) -> Path:
    return Path(str(csv_path) + ".json")


class Rows:
    """Consecutive rows of a run, rows ``first`` .. ``first + len(self) - 1``:
    ``data`` (float64, one column per recorded signal, ``time`` first), a
    column by name (``rows["Quadrotor.x"]``), and the Int64, UInt64,
    String and Binary columns as objects (their ``data`` column is NaN)."""

    def __init__(self, index: dict[str, int], data: np.ndarray, first: int,
                 objects: dict[str, np.ndarray] | None = None):
        self._index, self.data, self.first, self._objects = index, data, first, objects or {}

    @property
    def time(self) -> np.ndarray:
        return self.data[:, 0]

    def __len__(self) -> int:
        return len(self.data)

    def __getitem__(self, name: str) -> np.ndarray:
        if name in self._objects:
            return self._objects[name]
        try:
            return self.data[:, self._index[name]]
        except KeyError:
            raise KeyError(f"signal {name!r} was not recorded; recorded: {', '.join(self._index)}") from None


class _Kept:
    """The rows a run's result keeps: row 0, ``stride``, ``2 stride``, ...
    (at most ``capacity``; the stride doubles when one more would not fit,
    unless ``thin`` is off) and the last row seen."""

    def __init__(self, capacity: int, n_columns: int, n_objects: int, texts: Sequence[int], thin: bool,
                 numbers_bytes: int):
        self.capacity, self.thin, self.stride, self.n = capacity, thin, 1, 0
        self.data = np.empty((capacity, n_columns))
        self.objects = np.full((capacity, n_objects), None, dtype=object)
        self.tail: tuple[int, np.ndarray, np.ndarray] | None = None
        self._texts, self._text_bytes, self.numbers = list(texts), 0, numbers_bytes

    def add(self, first: int, data: np.ndarray, objects: np.ndarray) -> None:
        if not len(data):
            return
        self.tail = (first + len(data) - 1, data[-1].copy(), objects[-1].copy())
        if self.capacity == 0:
            return
        while True:
            start = (-first) % self.stride  # the rows at multiples of the stride
            picked, picked_objects = data[start::self.stride], objects[start::self.stride]
            if self.n + len(picked) <= self.capacity:
                break
            if not self.thin:
                raise CosimError(f"recording: more rows than the {self.capacity} planned")
            kept = len(range(0, self.n, 2))  # rows 0, 2 stride, 4 stride, ...: every other one kept
            self.data[:kept], self.objects[:kept] = self.data[:self.n:2], self.objects[:self.n:2]
            self.objects[kept:self.n] = None
            self.n, self.stride = kept, 2 * self.stride
            self._text_bytes = self._bytes(self.objects[:self.n])
        self.data[self.n:self.n + len(picked)] = picked
        self.objects[self.n:self.n + len(picked)] = picked_objects
        self.n += len(picked)
        if self._texts:
            self._text_bytes += self._bytes(picked_objects)

    def _bytes(self, objects: np.ndarray) -> int:
        return sum(len(v) for j in self._texts for v in objects[:, j] if v is not None)

    def rows(self) -> tuple[np.ndarray, np.ndarray]:
        """The kept rows and their objects, the last row of the run last."""
        data, objects = self.data[:self.n], self.objects[:self.n]
        if self.tail is not None and self.capacity and self.tail[0] % self.stride:
            data = np.vstack([data, self.tail[1][None, :]])
            objects = np.vstack([objects, self.tail[2][None, :]])
        return data.copy(), objects.copy()


class Recorder:
    """Rows of ``columns`` (the first is ``time``), ``n_rows`` planned,
    streamed to ``path`` (if given), to ``observers`` and into the rows the
    result keeps (``keep``: the module says how).

    The master writes row ``n`` straight into :meth:`row` (the compiled loop
    into :attr:`data` at ``n - first``) and calls :meth:`commit` at the end
    of each block; :meth:`close` hands over the rest.
    """

    def __init__(self, columns: Sequence[str], units: Sequence[str | None], n_rows: int,
                 path: str | Path | None = None, block_rows: int = 100, meta: dict | None = None,
                 digits: int | None = None, types: Sequence[str] = (), objects: Sequence[tuple[int, int]] = (),
                 keep: int | None = None, observers: Sequence = (), every: int = 1):
        if block_rows < 1:
            raise ValueError(f"block_rows = {block_rows} must be at least 1")
        if every < 1:
            raise ValueError(f"every = {every} must be at least 1")
        self.columns, self.units = tuple(columns), tuple(units)
        self.types = tuple(types) or ("Float64",) * len(self.columns)
        self._index = {c: i for i, c in enumerate(self.columns)}
        # columns held as objects (Int64, UInt64, String, Binary): (column, object slot)
        self._object_columns = np.array([k for k, _ in objects], dtype=np.intp)
        self._object_slots = np.array([slot for _, slot in objects], dtype=np.intp)
        self._texts = [j for j, (k, _) in enumerate(objects) if self.types[k] in _TEXTS]
        if keep is None:  # every row kept: the result's memory grows with the run, so it is bounded
            need = record_bytes(n_rows, len(self.columns))
            if need > MAX_RECORD_BYTES:
                raise ScenarioError(f"simulation.duration: {n_rows} rows of {len(self.columns)} recorded signals "
                                    f"need {need / 2 ** 30:.1f} GiB in memory; at most "
                                    f"{MAX_RECORD_BYTES / 2 ** 30:.0f} GiB are kept (record fewer signals, run a "
                                    f"shorter mission, or keep fewer rows: keep=...)")
        elif keep < 0:
            raise ValueError(f"keep = {keep} must be None (every row), 0 (none) or positive")
        self.block_rows = min(block_rows, CHUNK_ROWS)  # a longer block would hold more rows than a chunk
        self.chunk = -(-CHUNK_ROWS // self.block_rows) * self.block_rows
        self.data = np.full((self.chunk, len(self.columns)), np.nan)  # the chunk being recorded
        self.objects = np.full((self.chunk, len(objects)), None, dtype=object)
        self.first = 0  # the run's row of data[0]
        self.n_rows = 0  # rows recorded so far (the run's)
        self.every = every
        self.observers = tuple(observers)
        self._kept = _Kept(n_rows if keep is None else keep, len(self.columns), len(objects), self._texts,
                           thin=keep is not None, numbers_bytes=record_bytes(n_rows if keep is None else keep, len(self.columns)))
        self.span: tuple[float, float] | None = None  # the first and the last row's time
        self.path = Path(path) if path is not None else None
        self.meta = dict(meta or {})
        if every > 1:
            self.meta["record_every"] = every
        self._flushed = 0  # rows handed to the file (written or skipped by every)
        self._on_disk = 0
        self._told = time.monotonic()
        # default: each value as the shortest text that reads back to the same double (Python's repr), so a
        # results file is the run, to the last bit; ``digits``: that many significant digits
        number = "%r" if digits is None else f"%.{digits}g"
        self._shortest = digits is None
        self._fmt = ",".join([number] * len(self.columns)) + "\n"
        self._typed = any(t not in _FLOATS for t in self.types)
        if self._typed:
            self._formats = [(lambda v, f=number: f % float(v)) if t in _FLOATS else
                             (lambda v: "true" if v else "false") if t == "Boolean" else
                             _quoted if t == "String" else bytes.hex if t == "Binary" else
                             (lambda v: str(int(v))) for t in self.types]
        self._file = None
        self._closed = False
        self._pending_text = 0  # bytes of the String and Binary values in the chunk
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w", encoding="utf-8", newline="")
            self._file.write(",".join(self.columns) + "\n")
            self._file.flush()
            self._write_sidecar("running", None)

    def _write_sidecar(self, status: str, error: str | None) -> None:
        info = {"columns": list(self.columns), "units": list(self.units), "types": list(self.types),
                "rows": self._on_disk,
                "status": status, "error": error, **self.meta}
        sidecar_path(self.path).write_text(json.dumps(info, indent=1))

    def row(self, n: int) -> np.ndarray:
        """Where row ``n`` of the run is written (in the chunk in memory)."""
        return self.data[n - self.first]

    def record_objects(self, n: int, values: np.ndarray) -> None:
        """Row ``n`` of the columns held as objects, from the master's object
        slots ``values``; a String or Binary value beyond its bound refused."""
        row = values[self._object_slots]
        for j in self._texts:
            size = len(row[j])
            if size > MAX_STRING_BYTES:
                raise CosimError(f"recording {self.columns[self._object_columns[j]]}: a value of {size} bytes; at "
                                 f"most {MAX_STRING_BYTES} bytes each are recorded")
            self._pending_text += size
        kept = self._kept._text_bytes + self._pending_text  # at most what the result will keep
        if self._texts and kept + self._kept.numbers > MAX_RECORD_BYTES:
            raise CosimError(f"recording: the String and Binary values recorded reach {kept} bytes; with the "
                             f"numbers, at most {MAX_RECORD_BYTES} bytes are kept (record fewer signals)")
        self.objects[n - self.first] = row
        self.data[n - self.first, self._object_columns] = np.nan  # the numbers' array has no value for them

    def object_columns(self) -> dict[str, np.ndarray]:
        """The columns held as objects, by name (the rows kept)."""
        _, objects = self._kept.rows()
        return {self.columns[k]: objects[:, j] for j, k in enumerate(self._object_columns)}

    def commit(self, n_rows: int) -> None:
        """Rows up to ``n_rows - 1`` are complete; a full block goes to the
        file, a full chunk to the observers and the kept rows."""
        self.n_rows = n_rows
        if n_rows - self._flushed >= self.block_rows:
            self.flush()
        if n_rows - self.first >= self.chunk:
            self._hand_over()

    def _hand_over(self) -> None:
        """The rows of the chunk recorded so far to the observers and the
        kept rows; the chunk starts afresh at the next row."""
        count = self.n_rows - self.first
        if count <= 0:
            return
        data, objects = self.data[:count], self.objects[:count]
        if self.span is None:
            self.span = (float(data[0, 0]), float(data[-1, 0]))
        self.span = (self.span[0], float(data[-1, 0]))
        self._kept.add(self.first, data, objects)
        if self.observers:
            block = Rows(self._index, data, self.first,
                         {self.columns[k]: objects[:, j] for j, k in enumerate(self._object_columns)})
            for observer in self.observers:
                observer.add(block)
        self.first = self.n_rows
        self._pending_text = 0
        self.objects[:] = None  # no reference kept to what was handed over

    def flush(self) -> None:
        """The rows recorded since the last flush to the file (every
        ``every``-th), flushed."""
        if self._file is None or self.n_rows <= self._flushed:
            self._flushed = max(self._flushed, self.n_rows)
            return
        first, last = self._flushed - self.first, self.n_rows - self.first
        skip = (-self._flushed) % self.every  # the next multiple of every
        rows = range(first + skip, last, self.every)
        if self._typed:
            self._file.write(self._typed_rows(rows))
        elif self._shortest:
            self._file.write(shortest_rows(self.data[first + skip:last:self.every]))
        else:
            fmt = self._fmt
            block = self.data[first + skip:last:self.every].tolist()
            self._file.write("".join(fmt % tuple(row) for row in block))
        self._file.flush()
        self._on_disk += len(rows)
        self._flushed = self.n_rows
        now = time.monotonic()
        if now - self._told >= SIDECAR_EVERY:  # what is on disk, said while the run goes on (a kill loses no count)
            self._told = now
            self._write_sidecar("running", None)

    def _typed_rows(self, rows: range) -> str:
        """Rows ``rows`` of the chunk, each value written as its type reads."""
        data = self.data[rows.start:rows.stop:rows.step].astype(object)
        if self._object_columns.size:
            data[:, self._object_columns] = self.objects[rows.start:rows.stop:rows.step]
        return "".join(",".join(f(v) for f, v in zip(self._formats, row)) + "\n" for row in data.tolist())

    def close(self, status: str = "ok", error: str | None = None) -> None:
        """The rest to the file, the observers and the kept rows; the sidecar's
        status. Once; later calls do nothing."""
        if self._closed:
            return
        self._closed = True
        try:
            self.flush()
            self._hand_over()
        finally:
            if self._file is not None:
                self._file.close()
                self._file = None
                self._write_sidecar(status, error)

    def kept(self) -> tuple[np.ndarray, int]:
        """The rows the result keeps (the last row of the run last) and their stride."""
        return self._kept.rows()[0], self._kept.stride

    def column(self, name: str) -> np.ndarray:
        """The kept values of one column (rows handed over so far)."""
        data, _ = self._kept.rows()
        return data[:, self.columns.index(name)]


def read_results(path: str | Path) -> tuple[list[str], np.ndarray]:
    """Columns and rows of a results CSV, complete or cut short, as numbers
    (:func:`iter_results`, every block in one array).

    A last line cut by a killed process is dropped (every row is written
    with its newline, so a last line without one is cut, even if it has all
    its fields); everything before it is returned. Booleans read as 1/0;
    the columns the sidecar types String or Binary read as NaN (read the
    file with the csv module for their text); an Int64 beyond 2^53 is
    rounded here, as every number of this array is a double.
    """
    blocks = list(iter_results(path))
    columns = list(blocks[0]._index) if blocks else _header(path)
    data = np.concatenate([b.data for b in blocks]) if blocks else np.zeros((0, len(columns)))
    return columns, data


def _header(path: str | Path) -> list[str]:
    import csv  # here: reading results back; a run writes them with orjson

    with open(path, encoding="utf-8", newline="") as f:
        header = next(csv.reader(f), None)
    if header is None:
        raise ValueError(f"{path}: empty results file (no header)")
    return header


def iter_results(path: str | Path, block_rows: int = CHUNK_ROWS) -> Iterator[Rows]:
    """The rows of a results CSV as :class:`Rows` of at most ``block_rows``
    rows, in order, read as they are needed (memory bounded by the block);
    what :func:`read_results` returns, block by block (no block for a file
    without rows). A file of numbers only is parsed a block at a time by
    numpy (each number read back to its bits, as ``float`` reads it)."""
    import csv

    path = Path(path)
    with open(path, "rb") as raw:
        raw.seek(0, io.SEEK_END)
        size = raw.tell()
        if size:
            raw.seek(size - 1)
            whole = raw.read(1) == b"\n"  # a last line without its newline was cut by a kill
    if not size:
        raise ValueError(f"{path}: empty results file (no header)")
    with open(path, encoding="utf-8", newline="") as f:
        columns = next(csv.reader([f.readline()]))
        types = ["Float64"] * len(columns)
        side = sidecar_path(path)
        if side.is_file():
            try:
                told = json.loads(side.read_text(encoding="utf-8")).get("types")
            except (ValueError, OSError):
                told = None
            if isinstance(told, list) and len(told) == len(columns):
                types = told
        index = {c: i for i, c in enumerate(columns)}
        if all(t in _FLOATS for t in types):
            blocks = _number_blocks(f, len(columns), block_rows, whole)
        else:
            blocks = _typed_blocks(csv.reader(f), types, block_rows, whole)
        first = 0
        for data in blocks:
            yield Rows(index, data, first)
            first += len(data)


def _number_blocks(f, n_columns: int, block_rows: int, whole: bool) -> Iterator[np.ndarray]:
    """Blocks of rows of a file of numbers: numpy's parser, a block at a time;
    a block it refuses (a line that is no row) read line by line, up to that line."""
    import csv

    while True:
        lines = list(itertools.islice(f, block_rows))
        if not lines:
            return
        cut = not lines[-1].endswith("\n")
        if cut:
            lines.pop()
        try:
            data = np.loadtxt(lines, delimiter=",", dtype=float, ndmin=2, comments=None) if lines else None
            good = data is not None and data.shape[1] == n_columns
        except ValueError:
            good = False
        if not good:
            data = next(_typed_blocks(csv.reader(lines), ["Float64"] * n_columns, len(lines) or 1, True), None)
            if data is not None:
                yield data
            return
        yield data
        if cut or len(data) < block_rows:
            return


def _typed_blocks(records, types: Sequence[str], block_rows: int, whole: bool) -> Iterator[np.ndarray]:
    """Blocks of rows read field by field (Booleans 1/0, String and Binary NaN),
    up to the first line that is no row."""
    n_columns = len(types)
    words = {"true": 1.0, "false": 0.0}
    rows: list[list[float]] = []
    pending = next(records, None)
    while pending is not None:
        fields, pending = pending, next(records, None)
        if pending is None and not whole:
            break
        if len(fields) != n_columns:
            break
        try:
            rows.append([np.nan if t in _TEXTS else words[v] if v in words else float(v)
                         for v, t in zip(fields, types)])
        except ValueError:
            break
        if len(rows) == block_rows:
            yield np.array(rows, dtype=float)
            rows = []
    if rows:
        yield np.array(rows, dtype=float).reshape(len(rows), n_columns)
