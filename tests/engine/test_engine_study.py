"""Studies (cosim.study) on the toy loop, in this process: the plan (grid,
random draws, seeds), refusals naming the study key, failed runs as rows,
and resuming a killed study."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from cosim.errors import ScenarioError
from cosim.study import load_study, parse_study, plan, read_runs, run_study, summarize_runs

pytestmark = pytest.mark.usefixtures("toys")  # tests/engine/conftest.py

SCENARIO = """
name = "toy_loop"
connections = ["source.out -> ctrl.r", "Lag.y -> ctrl.y", "ctrl.u -> Lag.u"]

[simulation]
duration = 1.0
step = 0.1

[fmus.Lag]
model = "toy_FirstOrderLag"

[toy_source]
kind = "toy_constant"
value = 1.0

[toy_controller]
kp = 1.5

[toy_lag]
fmu = "Lag"
time_constant = 0.25

[record]
signals = ["Lag.y"]

[envelope]
"Lag.y" = [-10.0, 10.0]
"""


def final_y(scenario, result):
    """A toy metric (module level: it would travel to a Dask worker by name)."""
    return {"final_y": float(result["Lag.y"][-1]) if len(result.time) else None}


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "toy.toml").write_text(SCENARIO)
    return tmp_path


def study_file(folder, body: str, name: str = "study.toml"):
    path = folder / name
    path.write_text('scenario = "toy.toml"\n' + body)
    return path


GRID_AND_RANDOM = """
[sweep]
seeds = [3, 5]
[sweep.grid]
"toy_controller.kp" = [0.5, 1.5]
"toy_source.value" = [1.0, 2.0, 3.0]
[sweep.random]
samples = 4
seed = 7
"toy_lag.time_constant" = { uniform = [0.2, 0.4] }
"toy_lag.gain" = { choice = [1.0, 2.0] }
"""


def test_plan_is_grid_x_samples_x_seeds_with_draws_from_the_base_seed(folder):
    study = load_study(study_file(folder, GRID_AND_RANDOM))
    runs = plan(study)
    assert len(runs) == 2 * 3 * 4 * 2
    assert study.keys == ["toy_controller.kp", "toy_source.value", "toy_lag.time_constant", "toy_lag.gain"]
    assert [r.index for r in runs] == list(range(len(runs)))
    assert {(r.values["toy_controller.kp"], r.values["toy_source.value"]) for r in runs} == \
        {(a, b) for a in (0.5, 1.5) for b in (1.0, 2.0, 3.0)}
    assert [r.seed for r in runs[:4]] == [3, 5, 3, 5]
    # the draws: numpy's Generator from the base seed, keys in file order, the same for every grid point
    rng = np.random.default_rng(7)
    expected = []
    for _ in range(4):
        tau = float(rng.uniform(0.2, 0.4))
        gain = [1.0, 2.0][int(rng.integers(2))]
        expected.append((tau, gain))
    first_point = [r for r in runs if r.grid_point == (0.5, 1.0) and r.seed == 3]
    assert [(r.values["toy_lag.time_constant"], r.values["toy_lag.gain"]) for r in first_point] == expected
    assert [r.sample for r in first_point] == [0, 1, 2, 3]
    assert plan(load_study(study_file(folder, GRID_AND_RANDOM, "again.toml"))) == runs  # reproducible


def test_without_seeds_every_point_runs_the_scenarios_seed(folder):
    study = load_study(study_file(folder, '[sweep.grid]\n"toy_controller.kp" = [1.0, 2.0]\n'))
    assert [(r.seed, r.sample) for r in plan(study)] == [(0, None), (0, None)]
    study = load_study(study_file(folder, "[sweep]\nseeds = 3\n"))
    assert [r.seed for r in plan(study)] == [0, 1, 2]


@pytest.mark.parametrize("body, message", [
    ("bogus = 1\n", "bogus: unknown key"),
    ("[sweep]\nrepeats = 2\n", "sweep.repeats: unknown key"),
    ("[sweep]\nseeds = 0\n", "sweep.seeds = 0: must be positive"),
    ('[sweep.grid]\n"toy_controller.kp" = 2.0\n', 'sweep.grid."toy_controller.kp" = 2.0: expected a non-empty list'),
    ('[sweep.grid]\n"toy_controller.kq" = [1.0]\n', 'sweep.grid."toy_controller.kq": toy_controller.kq: unknown key'),
    ('[sweep.grid]\n"toy_controller.kp" = [1.0, "x"]\n', 'sweep.grid."toy_controller.kp": toy_controller.kp'),
    ('[sweep.grid]\n"simulation.seed" = [1]\n', 'sweep.grid."simulation.seed": sweep seeds with sweep.seeds'),
    ('[sweep.random]\n"toy_source.value" = { uniform = [1.0, 2.0] }\n', "sweep.random.samples: required"),
    ('[sweep.random]\nsamples = 2\n"toy_source.value" = { uniform = [2.0, 1.0] }\n',
     'sweep.random."toy_source.value".uniform = [2.0, 1.0]: expected [low, high] with low < high'),
    ('[sweep.random]\nsamples = 2\n"toy_source.value" = { normal = [1.0, -1.0] }\n',
     'sweep.random."toy_source.value".normal = [1.0, -1.0]: expected [mean, std] with std >= 0'),
    ('[sweep.random]\nsamples = 2\n"toy_source.value" = { beta = [1.0, 2.0] }\n',
     'sweep.random."toy_source.value" = '),
    ('[sweep.random]\nsamples = 2\n"toy_source.value" = { choice = [] }\n',
     'sweep.random."toy_source.value".choice = []: expected a non-empty list'),
    ('[sweep.random]\nsamples = 2\n"toy_lag.tau" = { choice = [1.0] }\n',
     'sweep.random."toy_lag.tau": toy_lag.tau: unknown key'),
    ('[set]\n"toy_controller.kp" = "high"\n', "set: toy_controller.kp"),
])
def test_a_bad_study_is_refused_in_one_line_naming_the_key(folder, body, message):
    with pytest.raises(ScenarioError) as info:
        load_study(study_file(folder, body))
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_an_unknown_scenario_is_refused_naming_the_key(folder):
    with pytest.raises(ScenarioError, match=r"^scenario = 'nowhere.toml': "):
        parse_study({"scenario": "nowhere.toml"}, source=folder / "s.toml")


FAILING = """
[set]
"simulation.duration" = 2.0
[sweep]
seeds = 2
[sweep.grid]
"toy_controller.kp" = [1.0, 60.0]   # 60: the sampled loop is unstable and leaves the envelope
[sweep.random]
samples = 3
seed = 3
"toy_lag.time_constant" = { normal = [0.25, 0.3] }   # some draws are below the FMU's minimum
"""


def test_failed_and_diverged_runs_are_rows_and_the_summary_counts_them(folder, tmp_path):
    study = load_study(study_file(folder, FAILING))
    taus = [r.values["toy_lag.time_constant"] for r in plan(study)[:6:2]]
    assert any(t < 1e-3 for t in taus) and any(t > 1e-3 for t in taus)  # the seed gives both kinds
    out = tmp_path / "out"
    result = run_study(study, out, metrics=final_y, metric_names=["final_y"], plots=False)
    rows = read_runs(out / "runs.csv")
    assert len(rows) == len(plan(study)) == result.total
    by_status = {s: [r for r in rows if r["status"] == s] for s in ("ok", "diverged", "failed")}
    assert all(r["error"].startswith("invalid scenario: toy_lag")
               for r in by_status["failed"])
    assert all(float(r["toy_lag.time_constant"]) < 1e-3 for r in by_status["failed"])
    assert by_status["diverged"] and all(r["toy_controller.kp"] == "60.0" and "Lag.y" in r["error"]
                                         for r in by_status["diverged"])
    assert by_status["ok"] and all(r["error"] == "" and math.isfinite(float(r["final_y"])) for r in by_status["ok"])
    summary = {r["toy_controller.kp"]: r for r in csv.DictReader(open(out / "summary.csv"))}
    assert set(summary) == {"1.0", "60.0"}
    good = summary["1.0"]
    assert int(good["runs"]) == 6 and int(good["ok"]) + int(good["failed"]) == 6
    assert int(summary["60.0"]["ok"]) == 0 and summary["60.0"]["final_y_mean"] == ""
    import pyarrow.parquet as pq

    table = pq.read_table(out / "runs.parquet")
    assert table.num_rows == len(rows) and "final_y" in table.column_names


def test_the_summary_is_a_t_interval_over_the_ok_runs():
    rows = [{"g": "a", "status": "ok", "m": str(v)} for v in (1.0, 2.0, 4.0)] + \
           [{"g": "a", "status": "diverged", "m": "100.0"}, {"g": "b", "status": "ok", "m": "3.0"}]
    a, b = summarize_runs(rows, ["g"], ["m"])
    x = np.array([1.0, 2.0, 4.0])
    half = 4.302652729911275 * x.std(ddof=1) / math.sqrt(3)  # t(0.975, 2)
    assert (a["runs"], a["ok"], a["diverged"], a["m_n"]) == (4, 3, 1, 3)
    assert a["m_mean"] == pytest.approx(x.mean()) and a["m_std"] == pytest.approx(x.std(ddof=1))
    assert (a["m_ci95_low"], a["m_ci95_high"]) == pytest.approx((x.mean() - half, x.mean() + half))
    assert (b["m_n"], b["m_mean"], b["m_std"], b["m_ci95_low"]) == (1, 3.0, None, None)


RESUME = """
[sweep]
seeds = 3
[sweep.grid]
"toy_controller.kp" = [0.5, 1.0, 2.0]
[sweep.random]
samples = 2
"toy_source.value" = { uniform = [0.5, 1.5] }
"""


def test_a_killed_study_keeps_its_rows_and_runs_only_the_missing_ones(folder, tmp_path):
    study = load_study(study_file(folder, RESUME))
    out = tmp_path / "out"
    full = run_study(study, out, metrics=final_y, metric_names=["final_y"], plots=False)
    assert (full.total, full.skipped) == (18, 0)
    reference = {r["run"]: r for r in read_runs(out / "runs.csv")}

    # as if killed mid-way: 7 rows written, the 8th half-written
    lines = (out / "runs.csv").read_text().splitlines(keepends=True)
    (out / "runs.csv").write_text("".join(lines[:8]) + lines[8][:12])
    again = run_study(study, out, metrics=final_y, metric_names=["final_y"], plots=False)
    assert (again.total, again.skipped) == (11, 7)
    rows = read_runs(out / "runs.csv")
    assert sorted(int(r["run"]) for r in rows) == list(range(18))  # each run once
    for r in rows:
        assert r == {**reference[r["run"]], "wall_time_s": r["wall_time_s"]}

    done = run_study(study, out, metrics=final_y, metric_names=["final_y"], plots=False)
    assert (done.total, done.skipped) == (0, 18)
    assert len(read_runs(out / "runs.csv")) == 18


def test_resuming_into_the_folder_of_another_study_is_refused(folder, tmp_path):
    out = tmp_path / "out"
    run_study(load_study(study_file(folder, "[sweep]\nseeds = 1\n")), out, plots=False)
    other = load_study(study_file(folder, RESUME, "other.toml"))
    with pytest.raises(ScenarioError, match="another study"):
        run_study(other, out, plots=False)


def test_the_summary_follows_the_plan_whatever_order_the_runs_finished_in():
    """A resumed study appends a grid point's rows after later ones: the
    summary is still in plan order."""
    rows = [{"run": str(i), "k": str(k), "status": "ok", "m": str(float(i))} for i, k in ((2, 3), (0, 1), (3, 3), (1, 1))]
    records = summarize_runs(rows, ["k"], ["m"])
    assert [r["k"] for r in records] == ["1", "3"]
    assert [r["m_mean"] for r in records] == [0.5, 2.5]
