"""Long missions in constant memory (issue 28): a run's metrics taken as
its rows stream, its memory flat in its duration, its summary the one its
results file gives, an undefined metric null (strict JSON), and disk, the
only thing a run's length costs, said and checked before the run."""
from __future__ import annotations

import tracemalloc
import warnings

import numpy as np
import pytest

from cosim.loop.recorder import read_results
from cosim.scenario.definition import load_scenario
from cosim.scenario.assembly import build_master
from quadrotor_paper.cli import EXIT_BAD_INPUT, main
from quadrotor_paper.experiments import run_once
from quadrotor_paper.run_metrics import RunMetrics, from_results
from tests.strict_json import read_summary


def peak_bytes(master, duration: float, out, profile: bool, keep: int | None = 100) -> int:
    """Peak of Python's allocations (numpy's arrays among them) during one run of circles."""
    scenario = load_scenario("circles", {"simulation.duration": duration})
    tracemalloc.start()
    try:
        run_once(scenario, out, master=master, keep=keep, profile=profile)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("profile", [False, True], ids=["compiled loop", "Python loop"])
def test_a_runs_peak_memory_is_flat_in_its_duration(tmp_path, profile):
    """2 s and 20 s of circles, results CSV, metrics and a bounded keep: the
    same peak within 50 KB, where holding the 18 s more of rows would take
    1800 rows x 23 columns x 8 bytes = 331 KB (as keeping every row does)."""
    with build_master(load_scenario("circles", {"simulation.duration": 2.0})) as master:
        peak_bytes(master, 2.0, tmp_path / "warm", profile)  # caches, first-call allocations
        short = peak_bytes(master, 2.0, tmp_path / "short", profile)
        long = peak_bytes(master, 20.0, tmp_path / "long", profile)
        held = peak_bytes(master, 20.0, tmp_path / "held", profile, keep=None) - peak_bytes(
            master, 2.0, tmp_path / "held", profile, keep=None)
    assert abs(long - short) < 50_000, (short, long)
    assert held > 300_000  # what the test would see if rows were held


def test_the_streamed_summary_equals_the_one_recomputed_from_the_csv(tmp_path):
    """Every metric (tracking and the estimate's), to the bit, whatever the
    blocks the file is read in; and as from every row held in memory."""
    scenario = load_scenario("circles_estimated", {"simulation.duration": 12.0})
    result, summary = run_once(scenario, tmp_path, keep=None)
    streamed = {k: summary[k] for k in summary
                if k.startswith(("rmse", "max_", "final_", "nees", "nis", "est_", "outliers_", "resets_"))}
    assert len(streamed) == 21 and all(v is not None for v in streamed.values()), streamed
    for block_rows in (7, 4096):
        assert from_results(scenario, tmp_path / "results.csv", block_rows) == streamed
    held = RunMetrics(scenario)
    held.add(result)  # every row at once, as before streaming
    assert held.values() == streamed


def test_a_run_shorter_than_the_settle_time_warns_nothing_and_writes_null(tmp_path, capsys):
    """The estimate is judged after 5 s: a 2 s run has no such row; its
    means are undefined (null), and numpy warns about no empty mean."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code = main(["run", "circles_estimated", "--set", "simulation.duration=2", "--out", str(tmp_path),
                     "--quiet", "--no-plots"])
    assert code == 0
    summary = read_summary(tmp_path / "summary.json")
    assert summary["nees_position"] is None and summary["nis_fix"] is None and summary["est_rmse_wind_mps"] is None
    assert summary["rmse_m"] > 0 and summary["rmse_seen_m"] > 0  # over every row: defined
    assert "Warning" not in capsys.readouterr().err


def test_a_results_file_its_folder_cannot_hold_is_refused_before_the_run(tmp_path, capsys, monkeypatch):
    import shutil
    from collections import namedtuple

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10 ** 9, 10 ** 9 - 10 ** 6, 10 ** 6))
    out = tmp_path / "out"
    code = main(["run", "circles", "--set", "simulation.duration=100", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == EXIT_BAD_INPUT and len(err.splitlines()) == 1
    assert err.startswith("fnn-cosim: error: results.csv: 10001 rows of 23 columns: up to 5.8 MB; the file system "
                          f"of {out} has 1.0 MB free (write every K-th row: --record-every K")
    assert not (out / "results.csv").exists()
    code = main(["run", "circles", "--set", "simulation.duration=100", "--out", str(out), "--quiet", "--no-plots",
                 "--record-every", "10"])  # 1001 rows: 0.6 MB
    assert code == 0 and len(read_results(out / "results.csv")[1]) == 1001


def test_record_every_thins_the_file_not_the_metrics(tmp_path):
    every = load_scenario("circles", {"simulation.duration": 3.0})
    _, thinned = run_once(every, tmp_path / "thinned", record_every=10)
    _, whole = run_once(every, tmp_path / "whole")
    columns, data = read_results(tmp_path / "thinned" / "results.csv")
    assert np.array_equal(data, read_results(tmp_path / "whole" / "results.csv")[1][::10])
    assert thinned["rmse_m"] == whole["rmse_m"] and thinned["rows"] == whole["rows"] == 301


@pytest.mark.parametrize("bad", ["0", "-3", "x", "1" * 5000])
def test_record_every_takes_a_whole_number_from_1(bad, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        main(["run", "circles", "--record-every", bad, "--out", str(tmp_path)])
    assert exc.value.code == 2 and "expected a whole number from 1" in capsys.readouterr().err


def test_a_run_keeping_a_few_rows_keeps_them_evenly_and_the_last(tmp_path):
    scenario = load_scenario("circles", {"simulation.duration": 20.0})
    result, summary = run_once(scenario, None, keep=100)
    assert result.rows == summary["rows"] == 2001 and len(result.time) <= 101 and result.stride == 32
    assert result.time[-1] == 20.0 and np.allclose(np.diff(result.time[:-1]), 0.32)


def test_an_estimate_never_judged_on_a_steady_wind_says_undefined(tmp_path):
    """Turbulence changes the true wind every step: the wind is never steady
    for 5 s, so its NEES and settled RMSE are undefined (null), the rest is
    not, and summary.md says so instead of failing to format a number."""
    code = main(["run", "circles_estimated", "--set", "simulation.duration=6", "--set", "wind.turbulence=0.5",
                 "--out", str(tmp_path), "--quiet", "--no-plots"])
    assert code == 0
    summary = read_summary(tmp_path / "summary.json")
    assert summary["nees_wind"] is None and summary["est_rmse_wind_settled_mps"] is None
    assert summary["nees_position"] > 0 and summary["est_rmse_wind_mps"] > 0
    text = (tmp_path / "summary.md").read_text()
    assert "wind undefined (3 each when consistent)" in text and "wind once steady undefined m/s" in text


def test_the_streamed_largest_and_final_error_are_the_norm_of_every_row_to_the_bit(tmp_path):
    """The tracking metrics take |e| from the squares they sum (one pass):
    the same bits as np.linalg.norm of p* - p row by row over the rows
    held (quadrotor_paper.metrics.euclidean_error), and the RMSE its rows'."""
    from quadrotor_paper.metrics import euclidean_error, rmse
    from quadrotor_paper.sections import metric_signals

    scenario = load_scenario("circles", {"simulation.duration": 3.0, "wind.speed": 5.0})
    result, summary = run_once(scenario, tmp_path, keep=None)
    position, reference = metric_signals(scenario)
    norm = euclidean_error(result, position, reference)
    assert len(norm) == 301 and len(set(norm.tolist())) > 100
    assert summary["max_error_m"] == float(np.max(norm)) and summary["final_error_m"] == float(norm[-1])
    assert summary["rmse_m"] == rmse(result, position, reference)
