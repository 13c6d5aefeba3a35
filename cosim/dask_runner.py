"""Many runs of one scenario, in this process or on a Dask cluster.

It runs :class:`~cosim.study.Run` s, the one record of a run: its index in
a study's plan, its dotted scenario overrides (applied to the base
scenario's document and validated, as ``--set`` does) and its seed. :func:`fly` yields one
small record (a dict) per run, in the order the runs finish:

    {"key": run.index, "status": "ok" | "diverged" | "failed", "error": str | None,
     "seed": int, "wall_time_s": float, "metrics": {...}, "pid": int}

A metric is called as ``metrics(scenario, result)``. One with an attribute
``snapshot_times(scenario) -> times`` gets the run's FMU states at those
times in ``result.snapshots`` (:class:`~cosim.master.Snapshot`), e.g. to
linearize the loop along the flight.

A run that diverges, fails, or cannot even be built (a sampled value the
scenario refuses, an FMU that refuses a parameter, a worker that died) is a
record with its status and message, never an exception.

Engines: ``workers = 1`` and no ``scheduler`` runs every run in this
process, one after the other (no Dask at all). Otherwise a
``dask.distributed`` client: a ``LocalCluster`` of ``workers`` processes
with one thread each, or the running cluster at ``scheduler`` (an address
such as ``tcp://127.0.0.1:8786``). Runs are submitted in a bounded window
(a few per worker thread) and collected as they finish, so memory
stays flat however many runs a study has.

Each worker process keeps a small cache of built masters (:class:`MasterCache`),
keyed by everything in the scenario a build depends on (FMUs and their
parameters, components, connections, record, envelope, step, ordering), i.e.
all but the seed, the duration and the start time, which are run-level. A
run whose scenario differs from a cached one only in those reuses its master
(FMUs extracted and instantiated once); any other difference builds a new
master (the components may read FMU parameters when built, e.g. a
controller's nominal model from the plant's). FMU archives are extracted
once per worker process and shared by its masters.
"""
from __future__ import annotations

import atexit
import json
import logging
import os
import shutil
import tempfile
import threading
import time
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping

from .errors import CosimError, ScenarioError, one_line
from .limits import WORKER_TIMEOUT
from .scenario import Scenario, apply_overrides, build_master, fmu_file, parse_scenario
from .study import Run

__all__ = ["MasterCache", "fly", "execute", "structure_key"]

Metrics = Callable[[Scenario, Any], Mapping[str, Any]]


def structure_key(scenario: Scenario) -> str:
    """What a built master depends on: the scenario but its seed, duration and start time."""
    fmus = {name: {k: (str(v) if isinstance(v, Path) else v) for k, v in spec.items()}
            for name, spec in scenario.fmus.items()}
    return json.dumps({"fmus": fmus, "components": scenario.components, "connections": scenario.connections,
                       "record": scenario.record, "envelope": scenario.envelope, "step": scenario.step,
                       "ordering": scenario.ordering, "source": str(scenario.source)},
                      sort_keys=True, default=repr)


class MasterCache:
    """Built masters by :func:`structure_key` (least recently used dropped
    beyond ``size``), with FMU archives extracted once."""

    def __init__(self, size: int = 8):
        self.size = size
        self.masters: OrderedDict[str, Any] = OrderedDict()
        self._extracted: dict[str, Path] = {}
        self._tmp: Path | None = None

    def _fmu_dirs(self, scenario: Scenario) -> dict[str, Path]:
        from .files import extract_zip

        dirs = {}
        for name, spec in scenario.fmus.items():
            archive = str(fmu_file(spec))
            if archive not in self._extracted:
                if Path(archive).is_dir():
                    self._extracted[archive] = Path(archive)
                else:
                    if self._tmp is None:
                        self._tmp = Path(tempfile.mkdtemp(prefix="cosim-worker-fmus-"))
                    target = self._tmp / str(len(self._extracted))
                    try:
                        extract_zip(archive, target, f"FMU {archive}")
                    except ScenarioError:  # the build says why, in the scenario's words
                        continue
                    self._extracted[archive] = target
            if archive in self._extracted:
                dirs[name] = self._extracted[archive]
        return dirs

    def get(self, scenario: Scenario):
        key = structure_key(scenario)
        master = self.masters.get(key)
        if master is None:
            master = build_master(scenario, self._fmu_dirs(scenario))
            self.masters[key] = master
            while len(self.masters) > self.size:
                self.masters.popitem(last=False)[1].close()
        self.masters.move_to_end(key)
        return master

    def drop(self, scenario: Scenario) -> None:
        master = self.masters.pop(structure_key(scenario), None)
        if master is not None:
            master.close()

    def close(self) -> None:
        while self.masters:
            self.masters.popitem()[1].close()
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
        self._extracted.clear()


LOG_LENGTH = 100  # entries of the local scheduler's diagnostic logs (see _client)
POLL = 1.0  # s between looks at the cluster while no run finishes

_LOCAL = threading.local()  # a worker's cache, one per thread (a master is not thread-safe)


def _worker_cache() -> MasterCache:
    cache = getattr(_LOCAL, "cache", None)
    if cache is None:
        cache = _LOCAL.cache = MasterCache()
        atexit.register(cache.close)
    return cache


def _message(exc: BaseException) -> str:
    text = str(exc) if isinstance(exc, CosimError) else f"{type(exc).__name__}: {exc}"
    return one_line(text)


def execute(raw: Mapping[str, Any], source: str | None, run: Run, metrics: Metrics | None = None,
            cache: MasterCache | None = None) -> dict[str, Any]:
    """Fly one run (in a worker, or here); always returns its record."""
    record = _failed(run, None, os.getpid())
    cache = cache or _worker_cache()
    try:
        scenario = parse_scenario(apply_overrides(dict(raw), run.overrides),
                                  source=Path(source) if source else None)
    except Exception as exc:  # a value the scenario refuses: this run's failure, not the study's
        record["error"] = f"invalid scenario: {_message(exc)}"
        return record
    seed = scenario.seed if run.seed is None else int(run.seed)
    record["seed"] = seed
    try:
        master = cache.get(scenario)
    except Exception as exc:
        record["error"] = f"could not build: {_message(exc)}"
        return record
    try:
        # a metric may ask for the run's FMU states at chosen times (cosim.master.Snapshot)
        wanted = getattr(metrics, "snapshot_times", None)
        result = master.run(scenario.duration, seed=seed, t0=scenario.start_time, raise_on_error=False,
                            snapshots=wanted(scenario) if wanted is not None else ())
    except Exception as exc:  # could not start, or a component raised mid-run
        cache.drop(scenario)
        record["error"] = _message(exc)
        return record
    record.update(status=result.status, error=result.error, wall_time_s=result.wall_time)
    if metrics is not None:
        try:
            record["metrics"] = dict(metrics(scenario, result))
        except Exception as exc:
            record.update(status="failed", error=f"metrics: {_message(exc)}")
    return record


def _failed(run: Run, error: str | None, pid: int | None = None) -> dict[str, Any]:
    """A run's record as it stands when it failed (or before it flew): the one record layout."""
    return {"key": run.index, "status": "failed", "error": error, "seed": run.seed, "wall_time_s": None,
            "metrics": {}, "pid": pid}


def fly(scenario: Scenario, runs: Iterable[Run], workers: int = 1, scheduler: str | None = None,
        metrics: Metrics | None = None, window: int = 4,
        worker_timeout: float | None = WORKER_TIMEOUT) -> Iterator[dict[str, Any]]:
    """Fly every run of ``scenario`` (its document and file); yield each
    record as its run finishes. ``workers = 1`` without ``scheduler``: in
    this process; else on Dask (see the module's docstring). On Dask, when
    the cluster has had no worker for ``worker_timeout`` seconds (``None``:
    wait for ever), a :class:`~cosim.errors.CosimError` says so and the
    flight stops (the records yielded so far are kept by the caller)."""
    raw, source = scenario.raw, str(scenario.source) if scenario.source else None
    if scheduler is None and workers <= 1:
        cache = MasterCache()
        try:
            for run in runs:
                yield execute(raw, source, run, metrics, cache)
        finally:
            cache.close()
        return
    yield from _run_dask(raw, source, runs, workers, scheduler, metrics, window, worker_timeout)


def _client(workers: int, scheduler: str | None):
    import logging

    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            return Client(scheduler, timeout=30), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise CosimError(f"--scheduler {scheduler}: no Dask scheduler answers there ({_message(exc)})") from None
    # The local scheduler lives in this process. Its diagnostic logs keep
    # about 19 kB per task up to 10 000 entries (measured by
    # benchmarks/study_efficiency.py): short logs keep the driver's memory
    # flat as a study grows. A cluster given by address keeps its own settings.
    with dask.config.set({"distributed.admin.log-length": LOG_LENGTH,
                          "distributed.admin.low-level-log-length": LOG_LENGTH}):
        cluster = LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
        return Client(cluster), cluster


def _run_dask(raw, source, runs, workers, scheduler, metrics, window,
              worker_timeout: float | None) -> Iterator[dict[str, Any]]:
    from dask.distributed import wait

    client, cluster = _client(workers, scheduler)
    try:
        slots = max(1, sum(client.nthreads().values())) * max(1, window)
        pending = iter(runs)
        raw = dict(raw)
        submitted: dict[Any, Run] = {}

        def submit(run: Run):
            # pure=False: two runs are never the same task to Dask, even if equal
            fut = client.submit(execute, raw, source, run, metrics, pure=False)
            submitted[fut.key] = run
            return fut

        flying = {submit(t) for _, t in zip(range(slots), pending)}
        alone_since = None  # when the cluster was last seen without a worker
        while flying:
            try:
                done, flying = wait(flying, timeout=POLL, return_when="FIRST_COMPLETED")
            except TimeoutError:  # nothing finished within POLL: look at the cluster
                done = set()
            for fut in done:
                run = submitted.pop(fut.key)
                try:
                    record = fut.result()
                except Exception as exc:  # the worker died (e.g. a crash inside an FMU) or the task was lost
                    record = _failed(run, f"worker: {_message(exc)}")
                fut.release()
                yield record
                nxt = next(pending, None)
                if nxt is not None:
                    flying.add(submit(nxt))
            if done or client.nthreads():
                alone_since = None
                continue
            now = time.monotonic()
            if alone_since is None:  # said once per wait, on stderr by logging's last resort
                logging.getLogger(__name__).warning(
                    f"fnn-cosim: waiting: the Dask cluster ({scheduler or 'local'}) has no worker; the study stops "
                    + (f"if none comes within {worker_timeout:g} s" if worker_timeout is not None else "never"))
            alone_since = alone_since or now
            if worker_timeout is not None and now - alone_since >= worker_timeout:
                raise CosimError(f"no Dask worker for {worker_timeout:g} s ({scheduler or 'the local cluster'} lost "
                                 f"them all): the study stops with {len(submitted)} runs in flight; its table keeps "
                                 f"every run that finished, and running it again resumes it")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
