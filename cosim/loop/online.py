"""Statistics taken as a run's rows stream, in memory that does not grow
with the run, to the same bits as numpy over the whole array.

A run's metrics are reductions over its rows (a mean, a maximum, the last
value). Taken as the rows arrive (:mod:`cosim.loop.recorder` hands them over in
blocks), they need no copy of the rows; taken in numpy's own order, they
give the numbers a reduction over the whole array gives, bit for bit, so a
summary streamed during the run equals the one recomputed from its results
file, and the shipped numbers do not move:

* :class:`Sum` -- ``np.sum`` of a 1-D array, which numpy reduces by pairwise
  summation over the whole array (its split points depend on the length,
  unknown while a run may still end early): the values are held until
  :data:`HELD` of them have come (512 KiB), so every sum of up to
  :data:`HELD` values (a run of up to 655 s at 10 ms) is ``np.sum``'s;
  beyond, each full block of :data:`HELD` values is summed by ``np.sum``
  and the block sums are added pairwise (a binary counter: as accurate as
  pairwise summation, O(log n) error growth, in O(log n) memory);
* :class:`ColumnSum` -- ``np.sum(rows, axis=0)`` of a 2-D array, which numpy
  adds row after row: the same order, one running row;
* :class:`Maximum` -- ``np.max`` (order-free; a NaN wins, as in numpy);
* :class:`Last` -- the last value.

Each has ``add(values)`` for the next values in order, and a result that is
``None`` while nothing was added (a mean of no rows is undefined: JSON
``null``, never NaN).
"""
from __future__ import annotations

import numpy as np

__all__ = ["Sum", "ColumnSum", "Maximum", "Last", "HELD", "finite"]

HELD = 2 ** 16  # values a Sum holds before it sums them by blocks: 512 KiB each


def finite(value: float | None) -> float | None:
    """``value`` as a float if it is a finite number, else ``None`` (JSON has no NaN)."""
    if value is None:
        return None
    value = float(value)
    return value if np.isfinite(value) else None


class Sum:
    """The sum of the values added so far, as ``np.sum`` of them all gives it
    (to the bit while at most :data:`HELD` were added; see the module)."""

    def __init__(self) -> None:
        self._held = np.empty(HELD)
        self._n_held = 0
        self.count = 0
        self._levels: list[tuple[int, float]] = []  # (blocks summed, their sum), pairwise like a binary counter

    def add(self, values: np.ndarray) -> None:
        values = np.asarray(values, dtype=float).ravel()
        while values.size:
            if self._n_held == HELD:  # a full block, and more to come: sum it
                self._push(float(np.sum(self._held)))
            take = min(values.size, HELD - self._n_held)
            self._held[self._n_held:self._n_held + take] = values[:take]
            self._n_held += take
            self.count += take
            values = values[take:]

    def _push(self, block: float) -> None:
        size = 1
        while self._levels and self._levels[-1][0] == size:  # two sums of equal size: one of twice the size
            _, left = self._levels.pop()
            block, size = left + block, 2 * size
        self._levels.append((size, block))
        self._n_held = 0

    @property
    def total(self) -> float | None:
        """The sum (``None`` while nothing was added)."""
        if self.count == 0:
            return None
        total = float(np.sum(self._held[:self._n_held]))
        if not self._levels:
            return total
        for _, left in reversed(self._levels):  # the blocks in order, the partial one last
            total = left + total
        return total

    def mean(self) -> float | None:
        """``np.mean`` of the values (``None`` while nothing was added)."""
        total = self.total
        return None if total is None else total / self.count


class ColumnSum:
    """The column sums of the rows added so far, as ``np.sum(rows, axis=0)``
    of them all gives them (numpy adds a C-ordered array row after row)."""

    def __init__(self) -> None:
        self._total: np.ndarray | None = None
        self.count = 0

    def add(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=float)
        if not len(rows):
            return
        if self._total is not None:  # the running row first: the same additions in the same order
            rows = np.concatenate([self._total[None, :], rows])
        self._total = np.sum(rows, axis=0)
        self.count += len(rows) - (self.count > 0)

    def mean(self) -> np.ndarray | None:
        """``np.mean(rows, axis=0)`` (``None`` while nothing was added)."""
        return None if self._total is None else self._total / self.count


class Maximum:
    """``np.max`` of the values added so far (NaN if any was NaN)."""

    def __init__(self) -> None:
        self.value: float | None = None

    def add(self, values: np.ndarray) -> None:
        values = np.asarray(values, dtype=float)
        if values.size:
            block = float(np.max(values))
            self.value = block if self.value is None else float(np.max([self.value, block]))


class Last:
    """The last value added (``None`` while nothing was added)."""

    def __init__(self) -> None:
        self.value: float | None = None

    def add(self, values: np.ndarray) -> None:
        values = np.asarray(values, dtype=float)
        if values.size:
            self.value = float(values.reshape(-1)[-1])
