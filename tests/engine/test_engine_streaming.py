"""A run's rows as they stream (issue 28): the online statistics give
numpy's bits whatever the blocks, and the recorder hands every row over in
order while it keeps none, all, or an evenly thinned few."""
from __future__ import annotations

import json

import numpy as np
import pytest

from cosim.loop.online import HELD, ColumnSum, Last, Maximum, Sum, finite
from cosim.loop.recorder import CHUNK_ROWS, Recorder, iter_results, read_results, sidecar_path


def fed(accumulator, values, rng, largest=5000):
    """``accumulator`` fed ``values`` in blocks of random sizes."""
    i = 0
    while i < len(values):
        size = int(rng.integers(1, largest))
        accumulator.add(values[i:i + size])
        i += size
    return accumulator


@pytest.mark.parametrize("n", [1, 2, 7, 8, 9, 127, 128, 129, 5001, 8193, HELD])
def test_a_sum_is_numpys_to_the_bit_whatever_the_blocks(n):
    rng = np.random.default_rng(n)
    x = rng.random(n) * rng.normal(size=n) ** 3
    for _ in range(3):
        s = fed(Sum(), x, rng)
        assert s.count == n and s.total == np.sum(x) and s.mean() == np.mean(x)


def test_a_sum_beyond_what_it_holds_is_the_same_whatever_the_blocks_and_as_accurate():
    rng = np.random.default_rng(1)
    x = rng.random(3 * HELD + 17)
    totals = {fed(Sum(), x, rng, largest).total for largest in (300, 1000, 10 * HELD)}
    assert len(totals) == 1  # the blocks of HELD values are the run's, not the caller's
    assert totals.pop() == pytest.approx(np.sum(x), rel=1e-14)


def test_nothing_added_is_undefined_not_nan():
    assert Sum().total is None and Sum().mean() is None and ColumnSum().mean() is None
    assert Maximum().value is None and Last().value is None
    s = Sum()
    s.add(np.zeros(0))
    assert s.mean() is None
    assert finite(float("nan")) is None and finite(float("inf")) is None and finite(2.5) == 2.5


def test_column_sums_are_numpys_row_after_row_order():
    rng = np.random.default_rng(2)
    rows = rng.normal(size=(20_000, 3)) * 10.0 ** rng.integers(-8, 8, size=(20_000, 3))
    c = fed(ColumnSum(), rows, rng, 700)
    assert c.count == len(rows) and np.array_equal(c.mean(), np.mean(rows, axis=0))


def test_the_maximum_and_the_last_value():
    m, last = Maximum(), Last()
    for block in ([1.0, 5.0], [], [3.0]):
        m.add(block)
        last.add(block)
    assert (m.value, last.value) == (5.0, 3.0)
    m.add([np.nan, 1.0])
    assert np.isnan(m.value)  # as np.max: a NaN is the maximum


class Collect:
    """An observer keeping what it is handed (a test's view of the stream)."""

    def __init__(self):
        self.blocks = []

    def add(self, rows):
        self.blocks.append((rows.first, rows.data.copy(), rows["a"].copy()))


def record(n: int, keep, every: int = 1, path=None, block_rows: int = 10):
    observer = Collect()
    rec = Recorder(["time", "a"], ["s", "m"], n, path, block_rows=block_rows, keep=keep, observers=[observer],
                   every=every)
    for k in range(n):
        rec.row(k)[:] = (0.5 * k, float(k * k))
        if (k + 1) % rec.block_rows == 0:
            rec.commit(k + 1)
    rec.n_rows = n
    rec.close("ok")
    return rec, observer


def test_observers_get_every_row_in_order_in_chunks_and_nothing_is_kept_with_keep_0():
    n = 3 * CHUNK_ROWS + 5
    rec, observer = record(n, keep=0)
    chunk = rec.chunk  # whole blocks of 10 rows
    assert CHUNK_ROWS <= chunk < CHUNK_ROWS + 10 and rec.data.shape == (chunk, 2)  # the rows in memory
    firsts = [first for first, _, _ in observer.blocks]
    assert firsts == list(range(0, n, chunk))
    data = np.concatenate([d for _, d, _ in observer.blocks])
    assert np.array_equal(data[:, 1], np.arange(n) ** 2.0)
    assert np.array_equal(observer.blocks[1][2], data[chunk:2 * chunk, 1])
    kept, stride = rec.kept()
    assert kept.shape == (0, 2) and rec.span == (0.0, 0.5 * (n - 1))


def test_keep_none_keeps_every_row():
    rec, _ = record(2 * CHUNK_ROWS + 1, keep=None)
    kept, stride = rec.kept()
    assert stride == 1 and np.array_equal(kept[:, 1], np.arange(2 * CHUNK_ROWS + 1) ** 2.0)


@pytest.mark.parametrize("n", [5, 99, 100, 101, 1000, 3 * CHUNK_ROWS + 7])
def test_a_bounded_keep_thins_evenly_and_keeps_the_last_row(n):
    rec, _ = record(n, keep=100)
    kept, stride = rec.kept()
    rows = np.sqrt(kept[:, 1]).astype(int)  # the row each kept one is
    evenly = np.arange(0, n, stride)
    assert len(evenly) <= 100 and (stride == 1 or len(evenly) > 50)  # at most the bound, at least half of it
    assert list(rows[:len(evenly)]) == list(evenly)
    assert rows[-1] == n - 1 and len(rows) == len(evenly) + ((n - 1) % stride > 0)


def test_every_kth_row_is_written_and_read_back_in_blocks(tmp_path):
    path = tmp_path / "r.csv"
    rec, observer = record(1003, keep=0, every=7, path=path)
    columns, data = read_results(path)
    assert np.array_equal(data[:, 1], (np.arange(0, 1003, 7) ** 2).astype(float))
    info = json.loads(sidecar_path(path).read_text())
    assert info["record_every"] == 7 and info["rows"] == len(data)
    blocks = list(iter_results(path, block_rows=10))
    assert [b.first for b in blocks] == list(range(0, len(data), 10))
    assert np.array_equal(np.concatenate([b.data for b in blocks]), data) and blocks[0]["a"][1] == 49.0
