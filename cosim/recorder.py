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
would need (``docs/security.md``).
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import ScenarioError
from .limits import MAX_RECORD_BYTES

__all__ = ["Recorder", "read_results", "sidecar_path", "record_bytes"]

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
                 digits: int | None = None):
        if block_rows < 1:
            raise ValueError(f"block_rows = {block_rows} must be at least 1")
        self.columns, self.units = tuple(columns), tuple(units)
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
        self._fmt = ",".join(["%r" if digits is None else f"%.{digits}g"] * len(self.columns)) + "\n"
        self._file = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w", encoding="utf-8", newline="")
            self._file.write(",".join(self.columns) + "\n")
            self._file.flush()
            self._write_sidecar("running", None)

    def _write_sidecar(self, status: str, error: str | None) -> None:
        info = {"columns": list(self.columns), "units": list(self.units), "rows": self._flushed,
                "status": status, "error": error, **self.meta}
        sidecar_path(self.path).write_text(json.dumps(info, indent=1))

    def commit(self, n_rows: int) -> None:
        """Row ``n_rows - 1`` is complete; flush a block when one is full."""
        self.n_rows = n_rows
        if self._file is not None and n_rows - self._flushed >= self.block_rows:
            self.flush()

    def flush(self) -> None:
        if self._file is None or self.n_rows <= self._flushed:
            self._flushed = max(self._flushed, self.n_rows)
            return
        fmt = self._fmt
        block = self.data[self._flushed:self.n_rows].tolist()
        self._file.write("".join(fmt % tuple(row) for row in block))
        self._file.flush()
        self._flushed = self.n_rows
        now = time.monotonic()
        if now - self._told >= SIDECAR_EVERY:  # what is on disk, said while the run goes on (a kill loses no count)
            self._told = now
            self._write_sidecar("running", None)

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
    """Columns and rows of a results CSV, complete or cut short.

    A last line cut by a killed process is dropped (every row is written
    with its newline, so a last line without one is cut, even if it has all
    its fields); everything before it is returned.
    """
    text = Path(path).read_text(encoding="utf-8")
    lines = text.splitlines()
    if lines and not text.endswith("\n"):
        lines = lines[:-1] if len(lines) > 1 else lines
    if not lines:
        raise ValueError(f"{path}: empty results file (no header)")
    columns = lines[0].split(",")
    rows = []
    for line in lines[1:]:
        fields = line.split(",")
        if len(fields) != len(columns):
            break
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            break
    data = np.array(rows, dtype=float).reshape(len(rows), len(columns))
    return columns, data
