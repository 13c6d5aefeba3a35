"""Studies (cosim.study.definition, cosim.study.run) on the toy loop: the plan (cases,
grid, random draws, seeds; generated lazily), refusals naming the study key,
failed runs as rows, the one summary, resuming a killed study, the folder's
lock, and the same rows from a local Dask cluster as in this process."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

import toy_models
from cosim.scenario import registry
from cosim.errors import ScenarioError
from cosim.limits import MAX_RUNS
from cosim.study.definition import count, load_study, parse_study, plan, runs
from cosim.study.run import LOCK, read_runs, run_study
from cosim.study.summary import summarize
from tests.strict_json import read_summary

pytestmark = pytest.mark.usefixtures("toys")  # tests/engine/conftest.py

SCENARIO = toy_models.LOOP + """[record]
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
    assert len(runs) == 2 * 3 * 4 * 2 == count(study)
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
    first_point = [r for r in runs if r.point == (0.5, 1.0) and r.seed == 3]
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
    cells = {c["values"]["toy_controller.kp"]: c for c in read_summary(out / "summary.json")["cells"]}
    assert set(cells) == {1.0, 60.0}
    good = cells[1.0]
    assert good["runs"] == 6 and good["ok"] + good["failed"] == 6 and good["ok"] > 0
    assert good["metrics"]["final_y"]["n"] == good["ok"]
    assert cells[60.0]["ok"] == 0 and cells[60.0]["metrics"]["final_y"]["mean"] is None
    assert result.summary["cells"] == read_summary(out / "summary.json")["cells"]
    import pyarrow.parquet as pq

    table = pq.read_table(out / "runs.parquet")
    assert table.num_rows == len(rows) and "final_y" in table.column_names


TWO_CASES = """
[cases.a]
set = { "toy_controller.kp" = 1.0 }
seeds = 4
[cases.b]
set = { "toy_controller.kp" = 2.0 }
seeds = 1
"""


def test_the_summary_is_a_t_interval_over_the_ok_runs(folder):
    study = load_study(study_file(folder, TWO_CASES))
    rows = [{"run": str(i), "status": s, "m": str(v)} for i, (s, v) in enumerate(
        [("ok", 1.0), ("ok", 2.0), ("ok", 4.0), ("diverged", 100.0), ("ok", 3.0)])]
    a, b = summarize(study, rows, ["m"])
    x = np.array([1.0, 2.0, 4.0])
    half = 4.302652729911275 * x.std(ddof=1) / math.sqrt(3)  # t(0.975, 2)
    assert (a["case"], a["runs"], a["ok"], a["diverged"], a["metrics"]["m"]["n"]) == ("a", 4, 3, 1, 3)
    assert a["metrics"]["m"]["mean"] == pytest.approx(x.mean()) and a["metrics"]["m"]["std"] == pytest.approx(x.std(ddof=1))
    assert a["metrics"]["m"]["ci95"] == pytest.approx([x.mean() - half, x.mean() + half])
    assert (b["metrics"]["m"]["n"], b["metrics"]["m"]["mean"], b["metrics"]["m"]["std"], b["metrics"]["m"]["ci95"]) \
        == (1, 3.0, None, None)


def test_the_t_quantiles_are_scipys_to_the_bit_and_kept_so_a_later_summary_imports_no_scipy(tmp_path):
    """The summary's t(0.975, dof) is scipy.special.stdtrit's double; once
    computed it is kept in the cache folder, and a later process reads it
    there without importing SciPy (about 170 modules)."""
    import subprocess
    import sys
    import textwrap

    from scipy.special import stdtrit

    code = textwrap.dedent(f"""
        import sys
        from pathlib import Path
        from cosim import cache
        from cosim.study import summary
        cache.register_cache(lambda: Path({str(tmp_path)!r}))
        print(repr([summary.t975(d) for d in (1, 2, 9, 19)]), "scipy.special" in sys.modules)
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    first, second = (subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                                    env=env).stdout.split() for _ in range(2))
    expected = repr([float(stdtrit(d, 0.975)) for d in (1, 2, 9, 19)]).split()
    assert first[:-1] == second[:-1] == expected
    assert (first[-1], second[-1]) == ("True", "False")
    assert len(list((tmp_path / "quantiles").glob("*.json"))) == 1


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
    assert (again.total, again.skipped, sum(again.counts.values())) == (18, 7, 11)
    rows = read_runs(out / "runs.csv")
    assert sorted(int(r["run"]) for r in rows) == list(range(18))  # each run once
    for r in rows:
        assert r == {**reference[r["run"]], "wall_time_s": r["wall_time_s"]}

    done = run_study(study, out, metrics=final_y, metric_names=["final_y"], plots=False)
    assert (done.total, done.skipped, done.counts) == (18, 18, {})
    assert len(read_runs(out / "runs.csv")) == 18


def test_resuming_into_the_folder_of_another_study_is_refused(folder, tmp_path):
    out = tmp_path / "out"
    run_study(load_study(study_file(folder, "[sweep]\nseeds = 1\n")), out, plots=False)
    other = load_study(study_file(folder, RESUME, "other.toml"))
    with pytest.raises(ScenarioError, match="another study"):
        run_study(other, out, plots=False)


def test_the_summary_follows_the_plan_whatever_order_the_runs_finished_in(folder):
    """A resumed study's rows come in any order: the summary is in plan order,
    each cell's values in plan order too (the mean of floats depends on it),
    and its errors the first ones of the plan."""
    study = load_study(study_file(folder, '[sweep]\nseeds = 3\n[sweep.grid]\n"toy_controller.kp" = [1.0, 3.0]\n'))
    values = [1e16, 1.0, -1e16, 0.5, 0.25, 0.125]  # the first cell's sum is 0 in plan order, 1 in arrival order
    arrival = (4, 0, 2, 5, 1, 3)
    assert sum(values[i] for i in (0, 2, 1)) == 1.0 and sum(values[:3]) == 0.0
    rows = [{"run": i, "status": "ok", "m": values[i], "error": f"note {i}"} for i in arrival]
    records = summarize(study, rows, ["m"])
    assert [r["values"] for r in records] == [{"toy_controller.kp": 1.0}, {"toy_controller.kp": 3.0}]
    assert [r["metrics"]["m"]["mean"] for r in records] == [0.0, np.mean([0.5, 0.25, 0.125])]
    assert [r["errors"] for r in records] == [["note 0", "note 1", "note 2"], ["note 3", "note 4", "note 5"]]


# ---- cases -----------------------------------------------------------------------------------------

CASES = """
[cases.soft]
label = "soft controller"
set = { "toy_controller.kp" = 0.5 }
[cases.stiff]
set = { "toy_controller.kp" = 1.0 }
seeds = [7]
[sweep]
seeds = 2
[sweep.grid]
"toy_source.value" = [1.0, 2.0]
"""


def test_cases_are_rows_with_their_own_overrides_and_seeds(folder):
    study = load_study(study_file(folder, CASES))
    runs_ = plan(study)
    assert [(r.case, r.point, r.seed) for r in runs_] == [
        ("soft", (1.0,), 0), ("soft", (1.0,), 1), ("soft", (2.0,), 0), ("soft", (2.0,), 1),
        ("stiff", (1.0,), 7), ("stiff", (2.0,), 7)]
    assert runs_[0].overrides == {"toy_controller.kp": 0.5, "toy_source.value": 1.0}
    assert runs_[5].overrides == {"toy_controller.kp": 1.0, "toy_source.value": 2.0}
    result = run_study(study, metrics=final_y, metric_names=["final_y"], plots=False)
    assert [r["case"] for r in result.rows] == [r.case for r in runs_] and result.out_dir is None
    by_case = {(c["case"], c["values"]["toy_source.value"]): c for c in result.summary["cells"]}
    assert by_case[("soft", 1.0)]["label"] == "soft controller" and by_case[("stiff", 2.0)]["runs"] == 1
    # a stiffer proportional loop settles nearer its setpoint; the loop is linear in it
    y = {key: c["metrics"]["final_y"]["mean"] for key, c in by_case.items()}
    assert y[("stiff", 1.0)] > y[("soft", 1.0)] and y[("soft", 2.0)] == pytest.approx(2 * y[("soft", 1.0)])


def test_a_registered_case_is_named_and_may_take_seeds(folder):
    with registry.scoped():
        registry.register_case(registry.Case("gentle", {"toy_controller.kp": 0.25}, label="gentle"))
        study = load_study(study_file(folder, "[cases.gentle]\nseeds = 2\n"))
        assert study.cases == (registry.Case("gentle", {"toy_controller.kp": 0.25}, label="gentle", seeds=(0, 1)),)
        with pytest.raises(ScenarioError, match=r"cases.gentle.set: 'gentle' is a registered case"):
            load_study(study_file(folder, '[cases.gentle]\nset = { "toy_controller.kp" = 1.0 }\n'))


@pytest.mark.parametrize("body, message", [
    ("[cases.nope]\n", "cases.nope: not a registered case"),
    ("[cases.a]\nset = { \"toy_controller.kq\" = 1.0 }\n", "cases.a: toy_controller.kq: unknown key"),
    ("[cases.a]\nset = { \"toy_controller.kp\" = 1.0 }\ncolour = 1\n", "cases.a.colour: unknown key"),
    ("[cases.a]\nset = { \"toy_controller.kp\" = 1.0 }\n[sweep.grid]\n\"toy_controller.kp\" = [1.0]\n",
     'sweep.grid."toy_controller.kp": also set by case \'a\''),
    ("[sweep]\nseeds = 100000000\n", f"sweep.seeds = 100000000: at most {MAX_RUNS} runs a study"),
    ("[sweep.grid]\n\"toy_source.value\" = [1.0, 2.0, 3.0, 4.0]\n[sweep.random]\nsamples = 500000\n"
     "\"toy_controller.kp\" = { uniform = [1.0, 2.0] }\n", f"2000000 runs; at most {MAX_RUNS} a study"),
])
def test_bad_cases_and_oversized_studies_are_refused_in_one_line(folder, body, message):
    with pytest.raises(ScenarioError) as info:
        load_study(study_file(folder, body))
    assert message in str(info.value) and "\n" not in str(info.value)


def test_the_plan_is_generated_lazily_and_resumes_from_any_index(folder):
    study = load_study(study_file(folder, GRID_AND_RANDOM))
    whole = plan(study)
    assert list(runs(study, start=17)) == whole[17:]
    big = load_study(study_file(folder, "[sweep]\nseeds = 1000000\n", "big.toml"))
    assert count(big) == 1_000_000
    it = runs(big, start=999_998)  # skipping through the plan builds no list
    assert [r.index for r in it] == [999_998, 999_999]


# ---- the folder ---------------------------------------------------------------------------------

def test_a_folder_being_written_by_another_driver_is_refused(folder, tmp_path):
    import fcntl

    out = tmp_path / "out"
    out.mkdir()
    with open(out / LOCK, "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        with pytest.raises(ScenarioError, match="another study is being written into this folder now"):
            run_study(load_study(study_file(folder, "[sweep]\nseeds = 1\n")), out, plots=False)
    assert not (out / "runs.csv").exists()


def test_the_sidecar_says_what_the_folder_holds(folder, tmp_path):
    study = load_study(study_file(folder, RESUME))
    out = tmp_path / "out"
    run_study(study, out, metrics=final_y, metric_names=["final_y"], plots=False)
    sidecar = json.loads((out / "study.json").read_text())
    assert (sidecar["study"], sidecar["fingerprint"], sidecar["runs"], sidecar["rows"], sidecar["status"]) == \
        ("study", study.fingerprint, 18, 18, "done")


def test_an_unwritable_or_file_out_is_refused_before_any_run(folder, tmp_path):
    study = load_study(study_file(folder, "[sweep]\nseeds = 1\n"))
    (tmp_path / "f").write_text("x")
    with pytest.raises(ScenarioError, match=r"--out .*f: not a folder"):
        run_study(study, tmp_path / "f", plots=False)


# ---- Dask ---------------------------------------------------------------------------------------

def _same_rows(a: Path, b: Path) -> None:
    """The studies written into folders ``a`` and ``b`` have the same runs,
    each with the same row to the bit but for its wall time."""
    ra = {r["run"]: r for r in read_runs(a / "runs.csv")}
    rb = {r["run"]: r for r in read_runs(b / "runs.csv")}
    assert ra.keys() == rb.keys()
    for k in ra:
        assert {c: v for c, v in ra[k].items() if c != "wall_time_s"} == {c: v for c, v in rb[k].items()
                                                                           if c != "wall_time_s"}


def _flown_here_for_workers(folder, tmp_path, monkeypatch):
    """The toy study of models by path, flown in this process (``here``);
    worker processes then find the toy components by their factory on
    PYTHONPATH and the FMU by path."""
    (folder / "toy_by_path.toml").write_text(toy_models.LOOP_BY_PATH.format(lag=toy_models.lag_fmu_path(2)))
    body = ('scenario = "toy_by_path.toml"\n[sweep]\nseeds = 2\n[sweep.grid]\n"components.ctrl.kp" = [0.5, 1.5]\n'
            '[sweep.random]\nsamples = 2\n"fmus.Lag.parameters.tau" = { uniform = [0.2, 0.4] }\n')
    (folder / "dask.toml").write_text(body)
    study = load_study(folder / "dask.toml")
    here = run_study(study, tmp_path / "here", metrics=final_y, metric_names=["final_y"], plots=False)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(Path(toy_models.__file__).parent),
                                                      os.environ.get("PYTHONPATH", "")]))
    return study, here


def test_a_local_dask_cluster_gives_the_rows_of_this_process(folder, tmp_path, monkeypatch):
    """The engine's Dask path on toy models: the workers (separate processes)
    find the toy components by their factory on PYTHONPATH and the FMU by path."""
    study, here = _flown_here_for_workers(folder, tmp_path, monkeypatch)
    there = run_study(study, tmp_path / "dask", workers=2, metrics=final_y, metric_names=["final_y"], plots=False)
    assert (here.total, there.total, there.counts) == (8, 8, {"ok": 8})
    _same_rows(tmp_path / "here", tmp_path / "dask")
    assert here.summary["cells"] == there.summary["cells"]


@pytest.mark.slow  # a cluster's start and its distributed import: about 9 s of CPU in this process
def test_a_cluster_of_two_worker_processes_given_by_address_gives_the_summary_of_this_process(folder, tmp_path,
                                                                                                monkeypatch):
    """``--scheduler ADDRESS``: a running cluster (here a LocalCluster of two
    worker processes, one thread each, given by its address as ``dask
    worker tcp://...`` processes would be) flies the study's runs, to the
    rows and the summary flown here."""
    from dask.distributed import LocalCluster

    study, here = _flown_here_for_workers(folder, tmp_path, monkeypatch)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                      local_directory=tmp_path / "scratch") as cluster:
        there = run_study(study, tmp_path / "there", scheduler=cluster.scheduler_address, metrics=final_y,
                          metric_names=["final_y"], plots=False)
    assert (there.total, there.counts) == (8, {"ok": 8})
    _same_rows(tmp_path / "here", tmp_path / "there")
    assert here.summary["cells"] == there.summary["cells"]


def test_a_local_cluster_of_threads_gives_the_rows_of_this_process_and_frees_its_masters(folder, tmp_path,
                                                                                          monkeypatch):
    """``threads``: the runs fly on threads of this process (Dask's threaded
    scheduler; the threads share the study's masters, one run at a time on
    each), to the same bits as one after the other here; the cache is closed
    when the study ends (its FMUs freed, its extracted files removed), and
    no ``distributed`` cluster was started."""
    from cosim.study import runner as dask_runner

    (folder / "toy_by_path.toml").write_text(toy_models.LOOP_BY_PATH.format(lag=toy_models.lag_fmu_path(2)))
    body = ('scenario = "toy_by_path.toml"\n[sweep]\nseeds = 3\n[sweep.grid]\n"components.ctrl.kp" = [0.5, 1.5]\n'
            '[sweep.random]\nsamples = 2\n"fmus.Lag.parameters.tau" = { uniform = [0.2, 0.4] }\n')
    (folder / "threads.toml").write_text(body)
    study = load_study(folder / "threads.toml")
    made = []

    class Spied(dask_runner.MasterCache):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(dask_runner, "MasterCache", Spied)
    monkeypatch.setattr("cosim.executor._dask", lambda *args, **kwargs: pytest.fail("a distributed client"))
    here = run_study(study, tmp_path / "here", metrics=final_y, metric_names=["final_y"], plots=False)
    there = run_study(study, tmp_path / "threads", workers=2, threads=True, metrics=final_y,
                      metric_names=["final_y"], plots=False)
    assert (here.total, there.total, there.counts) == (12, 12, {"ok": 12})
    _same_rows(tmp_path / "here", tmp_path / "threads")
    assert here.summary["cells"] == there.summary["cells"]
    assert made and all(cache.closed and not cache.masters and not cache._busy and cache._tmp is None
                        for cache in made)


def test_a_cluster_without_a_worker_stops_the_study_in_one_line(folder, tmp_path):
    """The driver does not wait for ever: a cluster that has no worker for the
    stated time stops the study, saying so (what ran is kept; nothing ran here)."""
    from dask.distributed import LocalCluster

    from cosim.errors import CosimError

    study = load_study(study_file(folder, "[sweep]\nseeds = 2\n"))
    with LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as cluster:
        with pytest.raises(CosimError, match=r"^no Dask worker for 0\.5 s \(\w+://.* lost them all\): the study "
                                             r"stops with 2 runs in flight; .* running it again resumes it$"):
            run_study(study, tmp_path / "out", scheduler=cluster.scheduler_address, worker_timeout=0.5, plots=False)
    assert read_runs(tmp_path / "out" / "runs.csv") == []
