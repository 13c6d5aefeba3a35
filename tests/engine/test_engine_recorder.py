"""cosim.loop.recorder on its own: blocks flushed every block_rows rows, the sidecar's
status, and read_results on complete, partial and broken files."""
from __future__ import annotations

import json
import math
from decimal import Decimal

import numpy as np
import pytest

from cosim.loop.recorder import Recorder, read_results, shortest_rows, sidecar_path


def data_lines(path) -> list[str]:
    return path.read_text().splitlines()[1:]


def sidecar(path) -> dict:
    return json.loads(sidecar_path(path).read_text())


def fill(rec: Recorder, n: int) -> None:
    """Row n is (n, 2 n), committed as the master does."""
    rec.row(n)[:] = [n, 2 * n]
    rec.commit(n + 1)


def test_sidecar_path_is_beside_the_csv(tmp_path):
    assert sidecar_path(tmp_path / "results.csv") == tmp_path / "results.csv.json"
    assert sidecar_path("out/run.csv").name == "run.csv.json"


def test_header_and_running_sidecar_are_written_at_once(tmp_path):
    path = tmp_path / "deep" / "dir" / "results.csv"  # parents are made
    rec = Recorder(["time", "a"], ["s", "m"], 5, path, block_rows=2, meta={"step": 0.1, "seed": 4})
    assert path.read_text() == "time,a\n"
    assert sidecar(path) == {"columns": ["time", "a"], "units": ["s", "m"], "types": ["Float64", "Float64"], "rows": 0, "status": "running",
                             "error": None, "step": 0.1, "seed": 4}
    rec.close()


def test_blocks_are_flushed_every_block_rows_rows(tmp_path):
    path = tmp_path / "results.csv"
    rec = Recorder(["time", "a"], ["s", "m"], 25, path, block_rows=10)
    on_disk = []
    for n in range(25):
        fill(rec, n)
        on_disk.append(len(data_lines(path)))
    # nothing until row 9 completes a block of 10, then 10 until row 19, then 20
    assert on_disk == [0] * 9 + [10] * 10 + [20] * 6
    assert rec.n_rows == 25
    rec.close("ok")
    assert len(data_lines(path)) == 25  # the last, partial block on close
    assert data_lines(path)[:3] == ["0.0,0.0", "1.0,2.0", "2.0,4.0"]  # each double as its shortest exact text
    info = sidecar(path)
    assert info["status"] == "ok" and info["error"] is None and info["rows"] == 25


def test_block_of_one_row_flushes_every_row(tmp_path):
    path = tmp_path / "results.csv"
    rec = Recorder(["time", "a"], ["s", None], 3, path, block_rows=1)
    for n in range(3):
        fill(rec, n)
        assert len(data_lines(path)) == n + 1
    rec.close()


def test_block_rows_must_be_positive(tmp_path):
    with pytest.raises(ValueError, match="block_rows = 0 must be at least 1"):
        Recorder(["time"], ["s"], 1, tmp_path / "r.csv", block_rows=0)


@pytest.mark.parametrize("status, error", [("failed", "RuntimeError: boom"), ("diverged", "diverged at t = 1 s")])
def test_close_records_the_status_and_message_and_keeps_every_row(tmp_path, status, error):
    path = tmp_path / "results.csv"
    rec = Recorder(["time", "a"], ["s", "m"], 100, path, block_rows=50)
    for n in range(7):
        fill(rec, n)
    assert data_lines(path) == []
    rec.close(status, error)
    assert len(data_lines(path)) == 7
    info = sidecar(path)
    assert (info["status"], info["error"], info["rows"]) == (status, error, 7)


def test_a_second_close_changes_nothing(tmp_path):
    path = tmp_path / "results.csv"
    rec = Recorder(["time"], ["s"], 2, path)
    rec.close("failed", "first")
    rec.close("ok", None)
    assert (sidecar(path)["status"], sidecar(path)["error"]) == ("failed", "first")


def test_values_are_written_to_the_last_bit(tmp_path):
    """Each double as the shortest text that reads back to it (Python's repr):
    a results file is the run itself."""
    path = tmp_path / "results.csv"
    rec = Recorder(["time", "a", "b"], ["s", "m", "m"], 2, path)
    rec.row(0)[:] = [0.0, 1 / 3, -2.5e-12]
    rec.row(1)[:] = [0.1, math.nan, 123456789012.0]
    rec.commit(2)
    rec.close()
    assert data_lines(path) == ["0.0,0.3333333333333333,-2.5e-12", "0.1,nan,123456789012.0"]
    columns, data = read_results(path)
    assert columns == ["time", "a", "b"]
    assert data[0, 1] == 1 / 3 and math.isnan(data[1, 1]) and data[1, 2] == 123456789012.0


def test_finite_blocks_get_the_digits_repr_chooses_and_read_back_to_the_bit(tmp_path):
    """A block of finite doubles goes through orjson, not repr: the same
    shortest digits (as exact decimals), every value read back to its bits,
    across the whole exponent range and its edges."""
    rng = np.random.default_rng(7)
    values = rng.standard_normal(3000) * 10.0 ** rng.integers(-300, 300, 3000)
    edges = [5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, 1e-5, 1e-7, 1e15, 1e16, -0.0, 0.0, 5.0]
    block = np.concatenate([values, edges, rng.standard_normal(2) * 1e-3]).reshape(-1, 3)
    text = shortest_rows(block)
    lines = text.splitlines()
    assert text.endswith("\n") and len(lines) == len(block)
    for line, row in zip(lines, block.tolist()):
        fields = line.split(",")
        assert [Decimal(f) for f in fields] == [Decimal(repr(v)) for v in row]
        assert [float(f) for f in fields] == row and [math.copysign(1, float(f)) for f in fields] == \
            [math.copysign(1, v) for v in row]
    path = tmp_path / "results.csv"
    rec = Recorder(["time", "a", "b"], ["s", "m", "m"], len(block), path)
    for n, row in enumerate(block):
        rec.row(n)[:] = row
    rec.commit(len(block))
    rec.close()
    assert np.array_equal(read_results(path)[1], block)
    assert shortest_rows(block[:0]) == ""


def test_values_can_be_written_with_fewer_digits(tmp_path):
    path = tmp_path / "results.csv"
    rec = Recorder(["time", "a", "b"], ["s", "m", "m"], 2, path, digits=10)
    rec.row(0)[:] = [0.0, 1 / 3, -2.5e-12]
    rec.row(1)[:] = [0.1, math.nan, 123456789012.0]
    rec.commit(2)
    rec.close()
    assert data_lines(path) == ["0,0.3333333333,-2.5e-12", "0.1,nan,1.23456789e+11"]


def test_column_gives_the_rows_written_so_far():
    rec = Recorder(["time", "a"], ["s", "m"], 10)  # no file: kept in memory only
    for n in range(4):
        fill(rec, n)
    rec.close("ok")  # without a file close hands the rows over
    np.testing.assert_array_equal(rec.column("a"), [0, 2, 4, 6])
    np.testing.assert_array_equal(rec.column("time"), [0, 1, 2, 3])
    with pytest.raises(ValueError):
        rec.column("nope")
    assert rec.path is None


# ---- read_results -----------------------------------------------------------------------------

def test_read_a_complete_file(tmp_path):
    path = tmp_path / "results.csv"
    path.write_text("time,a\n0,1.5\n0.1,2.5\n")
    columns, data = read_results(path)
    assert columns == ["time", "a"]
    np.testing.assert_array_equal(data, [[0.0, 1.5], [0.1, 2.5]])


def test_a_last_line_cut_short_is_dropped(tmp_path):
    path = tmp_path / "results.csv"
    path.write_text("time,a,b\n0,1,2\n0.1,3,4\n0.2,5")
    columns, data = read_results(path)
    assert columns == ["time", "a", "b"]
    np.testing.assert_array_equal(data, [[0, 1, 2], [0.1, 3, 4]])


def test_a_line_that_is_no_number_ends_the_rows(tmp_path):
    path = tmp_path / "results.csv"
    path.write_text("time,a\n0,1\n0.1,1e\n0.2,3\n")
    np.testing.assert_array_equal(read_results(path)[1], [[0, 1]])


def test_header_only_file_gives_no_rows(tmp_path):
    path = tmp_path / "results.csv"
    Recorder(["time", "a", "b"], ["s", "m", "m"], 5, path).close("failed", "could not start")
    columns, data = read_results(path)
    assert columns == ["time", "a", "b"] and data.shape == (0, 3)


def test_empty_file_is_an_error_naming_it(tmp_path):
    path = tmp_path / "results.csv"
    path.write_text("")
    with pytest.raises(ValueError, match="results.csv: empty results file \\(no header\\)"):
        read_results(path)


def test_a_partial_recording_reads_back_the_flushed_blocks(tmp_path):
    """What a killed process leaves: the blocks flushed so far, readable as they are."""
    path = tmp_path / "results.csv"
    rec = Recorder(["time", "a"], ["s", "m"], 30, path, block_rows=8)
    for n in range(21):
        fill(rec, n)
    columns, data = read_results(path)  # without close: two blocks of 8
    np.testing.assert_array_equal(data, [[n, 2 * n] for n in range(16)])
    assert sidecar(path)["status"] == "running"
    rec.close()


def test_a_last_line_cut_inside_its_last_field_is_dropped(tmp_path):
    path = tmp_path / "results.csv"
    path.write_text("time,a\n0,1.25\n0.1,2.5")  # the row was "0.1,2.578125\n"
    np.testing.assert_array_equal(read_results(path)[1], [[0, 1.25]])
