"""``fnn-cosim sweep``: a small study on the circles, in this process, on a
local Dask cluster, and on a scheduler and two workers started as separate
processes; the rows agree with single runs and with each other."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cosim.scenario.definition import load_scenario
from cosim.study.definition import load_study, plan
from cosim.study.run import read_runs
from quadrotor_paper.cli import main
from quadrotor_paper.experiments import run_once
from tests.strict_json import read_summary

STUDY = """
scenario = "circles"
name = "small"
[set]
"simulation.duration" = 2.0
[sweep]
seeds = 2
[sweep.grid]
"controller.variant" = ["pd", "pd+lm"]
"wind.speed" = [1.0, 5.0]
[sweep.random]
samples = 2
seed = 0
"fmus.Quadrotor.parameters.m" = { uniform = [0.856, 1.284] }
"""
N_RUNS = 2 * 2 * 2 * 2
METRICS = ("rmse_m", "max_error_m", "final_error_m")


@pytest.fixture
def study(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text(STUDY)
    return path


def _by_run(out: Path) -> dict[int, dict[str, str]]:
    return {int(r["run"]): r for r in read_runs(out / "runs.csv")}


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """The study run once in this process (--workers 1), shared by the tests."""
    folder = tmp_path_factory.mktemp("sweep")
    (folder / "small.toml").write_text(STUDY)
    out = folder / "out"
    assert main(["sweep", str(folder / "small.toml"), "--workers", "1", "--out", str(out), "--quiet"]) == 0
    return out


def test_every_run_is_a_row_with_the_metrics_of_a_single_run(in_process):
    rows = _by_run(in_process)
    assert sorted(rows) == list(range(N_RUNS))
    assert all(r["status"] == "ok" and r["error"] == "" for r in rows.values())
    run = plan(load_study(in_process.parent / "small.toml"))[5]
    row = rows[5]
    assert (row["controller.variant"], float(row["wind.speed"]), int(row["seed"])) == \
        (run.values["controller.variant"], run.values["wind.speed"], run.seed)
    assert float(row["fmus.Quadrotor.parameters.m"]) == run.values["fmus.Quadrotor.parameters.m"]
    single = load_scenario("circles", {"simulation.duration": 2.0, **run.values})
    _, summary = run_once(single, seed=run.seed)
    for m in METRICS:
        assert float(row[m]) == pytest.approx(summary[m], abs=1e-12)


def test_the_summary_parquet_and_plots(in_process):
    summary = read_summary(in_process / "summary.json")
    assert [(c["values"]["controller.variant"], c["values"]["wind.speed"]) for c in summary["cells"]] == \
        [("pd", 1.0), ("pd", 5.0), ("pd+lm", 1.0), ("pd+lm", 5.0)]
    for c in summary["cells"]:
        assert (c["runs"], c["ok"], c["metrics"]["rmse_m"]["n"]) == (4, 4, 4)
        rmse = c["metrics"]["rmse_m"]
        assert rmse["ci95"][0] <= rmse["mean"] <= rmse["ci95"][1]
    import pyarrow.parquet as pq

    table = pq.read_table(in_process / "runs.parquet")
    assert table.num_rows == N_RUNS and set(METRICS) <= set(table.column_names)
    assert (in_process / "box_rmse_m.png").stat().st_size > 0
    assert (in_process / "line_rmse_m.png").stat().st_size > 0


def test_a_rerun_on_the_same_folder_runs_nothing(in_process, capsys):
    before = (in_process / "runs.csv").read_text()
    assert main(["sweep", str(in_process.parent / "small.toml"), "--workers", "1", "--out", str(in_process),
                 "--quiet", "--no-plots"]) == 0
    assert f"{N_RUNS} runs ({N_RUNS} already done); this time: nothing to run" in capsys.readouterr().out
    assert (in_process / "runs.csv").read_text() == before


def _same_rows(a: Path, b: Path) -> None:
    ra, rb = _by_run(a), _by_run(b)
    assert sorted(ra) == sorted(rb)
    for k in ra:
        assert {c: v for c, v in ra[k].items() if c != "wall_time_s"} == \
            {c: v for c, v in rb[k].items() if c != "wall_time_s"}


def test_a_local_dask_cluster_gives_the_same_rows(in_process, study, tmp_path):
    out = tmp_path / "dask"
    assert main(["sweep", str(study), "--workers", "2", "--out", str(out), "--quiet", "--no-plots"]) == 0
    _same_rows(in_process, out)


def test_studies_of_our_registered_fmus_fly_on_threads_others_on_worker_processes(study, tmp_path):
    """threads_safe: a study of registered models in Co-Simulation, measured
    by study_metrics, flies on threads; an FMU file of someone's, Model
    Exchange or an analysis's own metrics keep worker processes."""
    from quadrotor_paper.experiments import study_metrics, threads_safe
    from quadrotor_paper.report import table_study

    assert threads_safe(load_study(study)) and threads_safe(table_study(2)) and threads_safe(table_study(3))
    assert not threads_safe(load_study(study), metrics=lambda scenario, result: {})
    from cosim.scenario.assembly import fmu_file

    plant = fmu_file(load_scenario("circles").fmus["Quadrotor"])
    for extra in (f'[set]\n"fmus.Quadrotor" = {{ path = "{plant}", parameters = {{ z_0 = -15.0 }} }}\n',
                  '[sweep.grid]\n"fmus.Quadrotor.fmi_version" = [2, 3]\n',
                  '[set]\n"fmus.Quadrotor.interface" = "ModelExchange"\n'):
        other = tmp_path / "other.toml"
        other.write_text('scenario = "circles"\n' + extra)
        assert not threads_safe(load_study(other)), extra


def _dask(*args: str) -> list[str]:
    script = Path(sys.executable).with_name("dask")
    return [str(script), *args] if script.exists() else [sys.executable, "-m", "dask", *args]


def _wait_for(path: Path, procs, timeout: float = 60.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists():
            try:
                return json.loads(path.read_text())
            except json.JSONDecodeError:  # being written
                pass
        for p in procs:
            if p.poll() is not None:
                raise RuntimeError(f"{p.args} exited with {p.returncode}")
        time.sleep(0.05)
    raise TimeoutError(f"no scheduler file {path}")


def test_a_running_scheduler_and_two_workers_by_address(in_process, study, tmp_path):
    from dask.distributed import Client

    info = tmp_path / "scheduler.json"
    # what the processes do beside the study, off: each worker's statistical profiler (a thread that
    # samples its stack every 10 ms) and every process's system monitor (every 0.5 s); they serve
    # the dashboard, which none of them has
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False",
           "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL": "1h"}
    logs = open(tmp_path / "dask.log", "w")
    procs = [subprocess.Popen(_dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                    "--scheduler-file", str(info)), stdout=logs, stderr=logs, env=env, cwd=tmp_path)]
    try:
        address = _wait_for(info, procs)["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen(_dask("worker", address, "--nthreads", "1", "--host", "127.0.0.1",
                                                "--no-dashboard", "--no-nanny"),
                                          stdout=logs, stderr=logs, env=env, cwd=tmp_path))
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=60)
        out = tmp_path / "remote"
        assert main(["sweep", str(study), "--scheduler", address, "--out", str(out), "--quiet", "--no-plots"]) == 0
        _same_rows(in_process, out)
    finally:
        # SIGINT: the dask CLI's clean shutdown (SIGTERM can leave a worker
        # hanging). The workers first, each waited for while the scheduler is
        # still up: a worker closing while the scheduler closes under it can
        # hang until the timeout (seen: 20 s of a loaded run).
        for p in reversed(procs):
            p.send_signal(signal.SIGINT)
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        logs.close()


@pytest.mark.parametrize("path", sorted((Path(__file__).parents[2] / "quadrotor_paper" / "studies").glob("*.toml")),
                         ids=lambda p: p.stem)
def test_every_shipped_study_loads_and_plans(path):
    """A shipped study names only keys and values its scenario takes (checked
    by load_study against the scenario and its FMUs' variables)."""
    study = load_study(path)
    runs = plan(study)
    assert runs and len({(r.case, tuple(sorted(r.values.items())), r.seed) for r in runs}) == len(runs)
