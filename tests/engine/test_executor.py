"""The one executor (cosim.executor): each implementation runs work and
brings a worker's exception back as the engine's error; the choice rule;
and no other module starts a pool, a process or a cluster of its own."""
from __future__ import annotations

import ast
import os
from pathlib import Path

import pytest

from cosim.errors import FmuCallError
from cosim.executor import WorkerError, compiled_ours, kind_for, parallel

ROOT = Path(__file__).resolve().parents[2]
_SHARED: list[int] = []  # a worker's initializer's value (processes: each worker's own copy)


def _start(value: int) -> None:
    _SHARED.append(value)


def _scaled(x: int) -> tuple[int, int]:
    return x * (_SHARED[-1] if _SHARED else 1), os.getpid()


def _refused(x: int) -> None:
    raise FmuCallError("Lag", "Lag.fmu", f"fmi2DoStep at t = {x} s", variable="tau", value=-1.0)


def _broken(x: int) -> None:
    raise KeyError(x)


def _dies(x: int) -> None:
    os._exit(3)


@pytest.mark.parametrize("kind", ["threads", "processes"])
def test_threads_and_processes_run_the_work_and_bring_a_workers_exception_back_as_the_engines_error(kind):
    """In order, after their initializer; an engine error whole (pickled from
    a process with its attributes), any other as a WorkerError naming it; a
    worker process that dies is one too, not a hang."""
    with parallel(kind, 2, initializer=_start, initargs=(10,)) as pool:
        done = pool.map(_scaled, range(6))
        firsts = [pool.result(f) for f in pool.as_completed([pool.submit(_scaled, 7)])]
        with pytest.raises(FmuCallError) as refused:
            pool.map(_refused, [1, 2])
        with pytest.raises(WorkerError, match=rf"^a {kind} worker failed: KeyError: 5$"):
            pool.map(_broken, [5])
        if kind == "processes":
            with pytest.raises(WorkerError, match=r"^a processes worker failed: BrokenProcessPool: "):
                pool.map(_dies, [0])
    assert [x for x, _ in done] == [0, 10, 20, 30, 40, 50] and firsts[0][0] == 70
    assert ({pid for _, pid in done} == {os.getpid()}) == (kind == "threads")  # processes: not this one
    e = refused.value
    assert (str(e), e.instance, e.path, e.variable, e.value) == ("Lag (Lag.fmu): fmi2DoStep at t = 1 s", "Lag",
                                                                 "Lag.fmu", "tau", -1.0)


def test_a_dask_cluster_given_by_address_runs_the_work_and_brings_errors_back():
    """The Dask implementation on a cluster given by its address (here one of
    threads in this process: the LocalCluster of processes is the studies')."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0") as cluster:
        with parallel("dask", scheduler=cluster.scheduler_address) as pool:
            assert pool.workers == 2
            assert pool.map(divmod, [7, 9], [2, 4]) == [(3, 1), (2, 1)]
            with pytest.raises(FmuCallError, match=r"^Lag \(Lag\.fmu\): fmi2DoStep at t = 4 s$"):
                pool.map(_refused, [4])
            with pytest.raises(WorkerError, match=r"^a dask worker failed: KeyError: 6$"):
                pool.map(_broken, [6])


def test_the_choice_rule_threads_for_our_compiled_fmus_processes_else_dask_by_address():
    ours = {"Quadrotor": {"model": "Quadrotor"}, "Wind": {"model": "WindGust", "interface": "CoSimulation"}}
    assert compiled_ours(ours, [("fmus", "Quadrotor", "parameters", "m"), ("controller", "kp")])
    assert not compiled_ours(ours, [("fmus", "Quadrotor", "path")])  # another file
    assert not compiled_ours({**ours, "Lag": {"path": "Lag.fmu"}})  # someone's FMU
    assert not compiled_ours({"Quadrotor": {"model": "Quadrotor", "interface": "ModelExchange"}})  # Python's solver
    assert (kind_for(None, True), kind_for(None, False), kind_for("tcp://h:8786", True)) == \
           ("threads", "processes", "dask")
    with pytest.raises(ValueError, match="kind 'fork' is not one of threads, processes, dask"):
        with parallel("fork"):
            pass


# ---- no second way ---------------------------------------------------------------------------------

# what starts parallel work: only cosim/executor.py may call these
FORBIDDEN = {"multiprocessing.Pool", "multiprocessing.Process", "multiprocessing.get_context",
             "multiprocessing.pool.Pool", "multiprocessing.pool.ThreadPool", "multiprocessing.dummy.Pool",
             "concurrent.futures.ThreadPoolExecutor", "concurrent.futures.ProcessPoolExecutor", "os.fork",
             "dask.distributed.LocalCluster", "distributed.LocalCluster",
             "dask.threaded.ContextAwareThreadPoolExecutor"}


def starts_parallel_work(source: str) -> list[str]:
    """The dotted names of :data:`FORBIDDEN` that ``source`` imports or reaches (line: name)."""
    tree = ast.parse(source)
    modules: dict[str, str] = {}  # local name -> the module (or name) it stands for
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                modules[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for a in node.names:
                modules[a.asname or a.name] = f"{node.module}.{a.name}"
                if f"{node.module}.{a.name}" in FORBIDDEN:
                    found.append(f"{node.lineno}: {node.module}.{a.name}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            parts, value = [node.attr], node.value
            while isinstance(value, ast.Attribute):
                parts.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name) and value.id in modules:
                name = ".".join([modules[value.id], *reversed(parts)])
                if name in FORBIDDEN:
                    found.append(f"{node.lineno}: {name}")
    return found


def test_the_scan_finds_each_way_of_starting_a_pool():
    assert starts_parallel_work("import multiprocessing\nmultiprocessing.get_context('fork').Pool(2)") == \
        ["2: multiprocessing.get_context"]
    assert starts_parallel_work("from concurrent.futures import ThreadPoolExecutor as T") == \
        ["1: concurrent.futures.ThreadPoolExecutor"]
    assert starts_parallel_work("import concurrent.futures as cf\ncf.ProcessPoolExecutor()") == \
        ["2: concurrent.futures.ProcessPoolExecutor"]
    assert starts_parallel_work("from dask import distributed\ndistributed.LocalCluster()") == \
        ["2: dask.distributed.LocalCluster"]
    assert starts_parallel_work("from multiprocessing.util import Finalize\nimport os\nos.getpid()") == []


def test_no_module_but_the_executor_starts_a_pool_a_process_or_a_cluster():
    executor = ROOT / "cosim" / "executor.py"
    files = [p for folder in ("cosim", "quadrotor_paper", "fmu_models", "fnn_controller", "benchmarks")
             for p in sorted((ROOT / folder).rglob("*.py")) if p != executor]
    assert len(files) > 100 and executor.exists()
    texts = {p: p.read_text() for p in files}
    parsed = [p for p, text in texts.items() if any(w in text for w in ("multiprocessing", "concurrent", "dask",
                                                                         "distributed", "fork"))]
    found = [f"{p.relative_to(ROOT)}:{hit}" for p in parsed for hit in starts_parallel_work(texts[p])]
    assert found == [], "parallel work started outside cosim/executor.py (use cosim.executor.parallel)"
