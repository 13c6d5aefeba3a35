"""The runner of studies (cosim.study.runner) at the loop's cost, on the toy
loop: batches of runs give the records of runs flown one by one; a worker's
master serves other values of the FMU parameters no component read (the
FMUs reset, then set), to the same bits as a new master, and a master whose
component read them is not reused; a value refused on a reused master is
refused in the words of a new build; the overrides of a set of runs are
parsed once, a refused one every time in the same words; a batch whose
worker died is flown again run by run, so the run that killed it fails alone
and every other run is a row, once. No clock is read: how fast is
benchmarks/study_efficiency.py's to say."""
from __future__ import annotations

import contextlib
import re
import tomllib
from pathlib import Path
from typing import Any

import pytest

import toy_models
from cosim.study import runner as dask_runner
from cosim.scenario import registry
from cosim.study.runner import MasterCache, batch_size, execute, execute_batch, fly
from cosim.scenario.registry import BuildContext
from cosim.scenario.definition import apply_overrides, parse_scenario
from cosim.study.definition import Run

pytestmark = pytest.mark.usefixtures("toys")  # tests/engine/conftest.py

SCENARIO = toy_models.LOOP + """[record]
signals = ["Lag.y", "ctrl.u"]
"""


def trace(scenario, result) -> dict[str, Any]:
    """Every recorded value of the run, to compare bit for bit."""
    return {"data": result.data.tolist()}


@pytest.fixture
def base(tmp_path):
    return parse_scenario(tomllib.loads(SCENARIO), source=tmp_path / "toy.toml")


def _run(index: int, overrides: dict[str, Any], seed: int = 3) -> Run:
    return Run(index, None, (), None, seed, {}, overrides)


def _fresh(base, run: Run, metrics=trace) -> dict[str, Any]:
    cache = MasterCache()
    try:
        return execute(base.raw, str(base.source), run, metrics, cache)
    finally:
        cache.close()


def _same_record(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """The same record but for the wall time, the process and the folder a cache extracted the FMU to."""
    def keep(r):
        error = re.sub(r"cosim-worker-fmus-\w+", "<extracted>", r["error"]) if r["error"] else r["error"]
        return {**{k: v for k, v in r.items() if k not in ("wall_time_s", "pid")}, "error": error}
    return keep(a) == keep(b)


# ---- the batch size ------------------------------------------------------------------------------

def test_the_batch_size_aims_at_a_second_of_work_and_shrinks_toward_the_end():
    assert batch_size(1000, 2, None) == 1  # nothing timed yet: one run
    assert batch_size(None, 2, 0.01, seconds=1.0) == 100  # a second of 10 ms runs
    assert batch_size(10_000, 2, 0.01, seconds=1.0) == 100
    assert batch_size(80, 2, 0.01, seconds=1.0) == 10  # a 1 / (4 x 2) share of what is left
    assert batch_size(3, 2, 0.01) == 1
    assert batch_size(0, 2, 0.01) == 1
    assert batch_size(1000, 2, 60.0) == 1  # long runs: one a task, as before


def test_a_batch_gives_the_records_of_its_runs_flown_one_by_one(base):
    runs = [_run(i, {"toy_controller.kp": kp}, seed) for i, (kp, seed) in
            enumerate([(0.5, 1), (0.5, 2), (1.5, 1), (-1.0, 1)])]
    cache = MasterCache()
    try:
        records, seconds = execute_batch(base.raw, str(base.source), runs, trace, cache)
    finally:
        cache.close()
    assert seconds >= 0 and [r["key"] for r in records] == [0, 1, 2, 3]
    assert all(_same_record(r, _fresh(base, run)) for r, run in zip(records, runs))


# ---- a worker's masters -------------------------------------------------------------------------

def test_a_master_serves_other_values_of_fmu_parameters_no_component_read_to_the_same_bits(base):
    runs = [_run(i, {"toy_lag.time_constant": tau, "toy_lag.gain": k})
            for i, (tau, k) in enumerate([(0.2, 2.0), (0.4, 3.0), (0.2, 2.0), (0.3, 1.0)])]
    cache = MasterCache()
    try:
        records = [execute(base.raw, str(base.source), run, trace, cache) for run in runs]
        assert len(cache.masters) == 1  # the lag's values are set at each start, after its reset
    finally:
        cache.close()
    assert [r["status"] for r in records] == ["ok"] * 4
    assert records[0]["metrics"] != records[1]["metrics"]
    assert all(_same_record(r, _fresh(base, run)) for r, run in zip(records, runs))


def _reading_controller(name: str, params, context: BuildContext):
    """A P controller whose gain is the lag's static gain (read when built, as
    a controller takes its nominal model from the plant's parameters)."""
    k = context.scenario.fmus["Lag"]["parameters"].get("k", toy_models.LAG_K)
    return toy_models.PController(name, kp=float(params.get("kp", 1.0)) / float(k))


def test_a_master_whose_component_read_the_fmu_values_is_not_reused_for_others(base):
    with registry.scoped():
        registry.register_component_kind(registry.ComponentKind(
            "toy_reading_controller", _reading_controller, lambda: toy_models._numbers_only(toy_models.PController),
            "a P controller that reads the lag's gain"))
        raw = apply_overrides(base.raw, {"components.ctrl": {"kind": "toy_reading_controller", "kp": 1.5}})
        del raw["toy_controller"]
        reading = parse_scenario(raw, source=base.source)
        runs = [_run(i, {"toy_lag.gain": k}) for i, k in enumerate([2.0, 4.0, 2.0])]
        cache = MasterCache()
        try:
            records = [execute(reading.raw, str(reading.source), run, trace, cache) for run in runs]
            assert len(cache.masters) == 2  # one per gain: the controller was built from it
        finally:
            cache.close()
        assert all(_same_record(r, _fresh(reading, run)) for r, run in zip(records, runs))
        assert records[0]["metrics"] != records[1]["metrics"]


def test_a_value_refused_on_a_reused_master_is_refused_in_the_words_of_a_new_build(tmp_path):
    by_path = parse_scenario(tomllib.loads(toy_models.LOOP_BY_PATH.format(lag=toy_models.lag_fmu_path(2))),
                             source=tmp_path / "toy.toml")
    bad = _run(1, {"fmus.Lag.parameters.tau": 1e-4})  # below the file's declared minimum, 1e-3
    new = _fresh(by_path, bad)
    assert new["status"] == "failed" and new["error"].startswith("could not build: fmus.Lag.parameters.tau = 0.0001: "
                                                                  "outside the range [0.001, inf]")
    cache = MasterCache()
    try:
        assert execute(by_path.raw, str(by_path.source), _run(0, {"fmus.Lag.parameters.tau": 0.3}), trace,
                       cache)["status"] == "ok"
        assert _same_record(execute(by_path.raw, str(by_path.source), bad, trace, cache), new)
        again = _run(2, {"fmus.Lag.parameters.tau": 0.4})  # the master still serves the good values
        assert _same_record(execute(by_path.raw, str(by_path.source), again, trace, cache), _fresh(by_path, again))
    finally:
        cache.close()


# ---- parsing a run's scenario ----------------------------------------------------------------

def test_the_overrides_of_a_set_of_runs_are_parsed_once_and_a_refused_one_every_time(base, monkeypatch):
    parsed = []
    real = dask_runner.parse_scenario
    monkeypatch.setattr(dask_runner, "parse_scenario", lambda *a, **k: parsed.append(1) or real(*a, **k))
    good = {"toy_controller.kp": 0.5}
    bad = {"toy_controller.kp": "fast"}
    with pytest.raises(Exception) as direct:
        real(apply_overrides(base.raw, bad), source=base.source)
    cache = MasterCache()
    try:
        raw = base.raw
        records = [execute(raw, str(base.source), _run(i, o, seed), None, cache)
                   for i, (o, seed) in enumerate([(good, 1), (good, 2), (bad, 1), (bad, 2)])]
    finally:
        cache.close()
    assert [r["status"] for r in records] == ["ok", "ok", "failed", "failed"]
    assert records[2]["error"] == records[3]["error"] == f"invalid scenario: {direct.value}"
    assert len(parsed) == 3  # the good overrides once, the refused ones each time


# ---- a worker that dies --------------------------------------------------------------------------

class _Died(Exception):
    pass


class _Future:
    def __init__(self, key: int, batch: list[Run], outcome):
        self.key, self.batch, self._outcome = key, batch, outcome

    def result(self):
        if isinstance(self._outcome, Exception):
            raise self._outcome
        return self._outcome

    def release(self) -> None:
        pass


class _Cluster:
    """A client whose worker dies on any batch holding the run ``killer``
    (as Dask reports it: the task's error); the others run here."""

    def __init__(self, killer: int):
        self.killer, self.tasks = killer, []

    def nthreads(self) -> dict[str, int]:
        return {"worker": 1}

    def submit(self, fn, raw, source, batch, metrics, pure=False):
        self.tasks.append([run.index for run in batch])
        died = any(run.index == self.killer for run in batch)
        return _Future(len(self.tasks), batch, _Died("KilledWorker: the worker died") if died else
                       fn(raw, source, batch, metrics, MasterCache()))

    def close(self) -> None:
        pass


def test_a_batch_whose_worker_died_is_flown_again_run_by_run_and_only_its_killer_fails(base, monkeypatch):
    cluster = _Cluster(killer=2)

    @contextlib.contextmanager
    def client(workers, scheduler):  # cosim.executor's Dask client, here the cluster above
        yield cluster

    monkeypatch.setattr("cosim.executor._dask", client)
    monkeypatch.setattr("dask.distributed.wait", lambda futures, timeout, return_when: (set(futures), set()))
    monkeypatch.setattr(dask_runner, "batch_size", lambda left, threads, per_run: 5)
    runs = [_run(i, {"toy_controller.kp": 0.5 + i}) for i in range(7)]
    records = list(fly(base, runs, workers=2, metrics=trace, total=len(runs)))
    assert sorted(r["key"] for r in records) == list(range(7))  # every run once
    assert {r["key"]: r["status"] for r in records} == {**{i: "ok" for i in range(7)}, 2: "failed"}
    assert next(r for r in records if r["key"] == 2)["error"] == "worker: _Died: KilledWorker: the worker died"
    assert cluster.tasks[:2] == [[0, 1, 2, 3, 4], [5, 6]]
    assert sorted(cluster.tasks[2:]) == [[0], [1], [2], [3], [4]]  # the dead batch, run by run
    assert all(_same_record(r, _fresh(base, runs[r["key"]])) for r in records if r["key"] != 2)


# ---- threads --------------------------------------------------------------------------------------

def test_fmus_instantiated_by_two_threads_at_once_leave_the_working_directory_as_it_was(monkeypatch, tmp_path):
    """fmpy loads a library from inside its folder (chdir there and back):
    two threads doing it at once, as the threads of a local cluster do,
    left the process in one FMU's extracted folder, later removed; each
    FMU is loaded alone (chdir slowed here so that the threads overlap)."""
    import os
    import threading
    import time

    from cosim.fmi.fmu import FmuComponent

    real = os.chdir

    def slow(path):
        real(path)
        time.sleep(0.05)

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(os, "chdir", slow)
    here = os.getcwd()
    start = threading.Barrier(2)
    fmus, errors = [], []

    def load():
        try:
            fmu = FmuComponent("Lag", toy_models.lag_fmu_path(2))
            start.wait()
            fmu.instantiate()
            fmus.append(fmu)
        except Exception as exc:  # reported below, with the thread's reason
            errors.append(exc)

    threads = [threading.Thread(target=load) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    monkeypatch.setattr(os, "chdir", real)
    try:
        assert not errors and len(fmus) == 2
        assert os.getcwd() == here
    finally:
        for fmu in fmus:
            fmu.close()


# ---- Dask's threaded scheduler -------------------------------------------------------------------

def _case_runs(cases: list[tuple[str, int]]) -> list[Run]:
    runs = []
    for case, n in cases:
        runs += [Run(len(runs), case, (), None, seed, {}, {}) for seed in range(n)]
    return runs


def test_the_tasks_of_a_threaded_study_are_consecutive_runs_of_one_case_shrinking_toward_the_end():
    runs = _case_runs([("a", 30), ("b", 30), ("c", 9), ("d", 9)])
    tasks = list(dask_runner.pieces(runs, 2))
    assert [run for task in tasks for run in task] == runs  # every run once, in plan order
    assert all(len({run.case for run in task}) == 1 for task in tasks)
    # a case whole while it is at most half of the runs left (a: 30 of 78), else cut (b: 24 of 48, then 6)
    assert [len(t) for t in tasks] == [30, 24, 6, 9, 5, 2, 1, 1]
    left = len(runs)
    for task in tasks:  # guided self-scheduling: never more than 1 / threads of the runs not yet in a task
        assert len(task) <= -(-left // 2)
        left -= len(task)
    assert [len(t) for t in dask_runner.pieces(_case_runs([(None, 8)]), 4)] == [2, 2, 1, 1, 1, 1]
    assert list(dask_runner.pieces([], 2)) == []


def test_a_master_is_taken_out_by_one_run_at_a_time_and_serves_the_next_once_given_back(base):
    cache = MasterCache()
    try:
        scenario = cache.scenario(base.raw, str(base.source), {})
        first = cache.get(scenario)
        second = cache.get(scenario)  # the first is flying: another is built
        assert second is not first and not cache.masters
        cache.release(first)
        assert cache.get(scenario) is first  # given back: the next run of its structure takes it
        cache.release(first)
        cache.release(second)
        assert len(cache.masters) == 2
    finally:
        cache.close()
    assert not cache.masters and not cache._busy


def test_the_masters_of_a_cache_load_an_fmu_of_the_tools_cache_from_its_one_extracted_folder(base):
    """Masters of two structures (a gain of the Python controller) both run
    the toy FMU, a file of the tool's cache: both load it from the one
    folder the cache extracted it to, the cache extracts nothing of its own
    and closing its masters removes nothing (a study's end waited for one
    folder removed per master and FMU), and the runs give the bits of new
    masters."""
    runs = [_run(0, {}), _run(1, {"toy_controller.kp": 0.5})]
    cache = MasterCache()
    try:
        records = [execute(base.raw, str(base.source), run, trace, cache) for run in runs]
        masters = [built.master for built in cache.masters.values()]
        assert len(masters) == 2
        lags = [master.components["Lag"] for master in masters]
        assert lags[0]._unzipdir == lags[1]._unzipdir and not any(lag._owns_unzipdir for lag in lags)
        assert cache._tmp is None
    finally:
        cache.close()
    assert lags[0]._unzipdir is None or Path(lags[0]._unzipdir).is_dir()
    assert all(_same_record(record, _fresh(base, run)) for record, run in zip(records, runs))


def test_a_threaded_study_flies_every_run_once_to_the_bits_of_this_process_without_distributed(base, monkeypatch):
    """Dask's threaded scheduler (``fly(threads=True)``): the records of
    the runs flown here one by one, each once; ``dask.distributed`` is not
    imported (made unimportable here)."""
    import sys

    monkeypatch.setitem(sys.modules, "distributed", None)
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    runs = [Run(i, f"kp{i // 4}", (), None, i % 4, {}, {"toy_controller.kp": 0.5 + i // 4}) for i in range(12)]
    records = list(fly(base, runs, workers=2, metrics=trace, threads=True, total=len(runs)))
    assert sorted(r["key"] for r in records) == list(range(12))
    assert all(_same_record(r, _fresh(base, runs[r["key"]])) for r in records)


def test_the_scenarios_of_a_few_runs_are_made_before_they_fly_and_a_refused_one_fails_its_run_only(base, monkeypatch):
    """:func:`cosim.study.runner.flown`: the scenarios of ``AHEAD`` runs are
    made together, then those runs fly; a refused scenario is its run's
    record, in the words of the run flown alone."""
    order = []
    real_scenarios, real_execute = dask_runner.scenarios, dask_runner.execute
    monkeypatch.setattr(dask_runner, "scenarios", lambda raw, source, group, cache: (
        order.append(("made", [r.index for r in group])) or real_scenarios(raw, source, group, cache)))
    monkeypatch.setattr(dask_runner, "execute", lambda raw, source, run, *args: (
        order.append(("flown", run.index)) or real_execute(raw, source, run, *args)))
    runs = [_run(i, {"toy_controller.kp": "fast" if i == 3 else 0.5 + i}) for i in range(dask_runner.AHEAD + 2)]
    records = list(fly(base, runs, metrics=trace))
    ahead = dask_runner.AHEAD
    assert order == [("made", list(range(ahead))), *(("flown", i) for i in range(ahead)),
                     ("made", [ahead, ahead + 1]), ("flown", ahead), ("flown", ahead + 1)]
    assert all(_same_record(r, _fresh(base, run)) for r, run in zip(records, runs))
    assert records[3]["error"].startswith("invalid scenario: toy_controller.kp = 'fast'")


def test_a_run_that_breaks_the_runner_on_threads_fails_alone_and_its_task_flies_on(base, monkeypatch):
    real = dask_runner.execute

    def broken(raw, source, run, *args):
        if run.index == 1:
            raise RuntimeError("a bug")
        return real(raw, source, run, *args)

    monkeypatch.setattr(dask_runner, "execute", broken)
    runs = [Run(i, "one", (), None, i, {}, {}) for i in range(6)]  # one case: tasks of consecutive runs
    records = {r["key"]: r for r in fly(base, runs, workers=2, metrics=trace, threads=True, total=len(runs))}
    assert sorted(records) == list(range(6))
    assert records[1]["status"] == "failed" and records[1]["error"] == "worker: RuntimeError: a bug"
    assert all(records[i]["status"] == "ok" for i in (0, 2, 3, 4, 5))


def test_a_threaded_study_stopped_by_its_reader_starts_no_other_run_and_frees_its_masters(base, monkeypatch):
    """A reader that stops (a driver interrupted mid-study) ends the flight:
    the runs in flight finish, no other starts, the study's masters are
    closed and its files removed."""
    import threading

    made = []

    class Spied(MasterCache):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(dask_runner, "MasterCache", Spied)
    gate, calls = threading.Event(), []

    def held(scenario, result):  # every run but the first waits until the reader has stopped
        calls.append(1)
        if len(calls) > 1:
            gate.wait()
        return trace(scenario, result)

    runs = [_run(i, {}) for i in range(200)]
    records = fly(base, runs, workers=2, metrics=held, threads=True, total=len(runs))
    first = next(records)
    gate.set()
    records.close()  # as a driver stopped mid-study
    assert first["status"] == "ok"
    assert len(calls) < len(runs)
    assert made and all(c.closed and not c.masters and not c._busy and c._tmp is None for c in made)
