"""Many runs of one scenario, in this process or on a Dask cluster.

It runs :class:`~cosim.study.definition.Run` s, the one record of a run: its index in
a study's plan, its dotted scenario overrides (applied to the base
scenario's document and validated, as ``--set`` does) and its seed. :func:`fly` yields one
small record (a dict) per run, in the order the runs finish:

    {"key": run.index, "status": "ok" | "diverged" | "failed", "error": str | None,
     "seed": int, "wall_time_s": float, "metrics": {...}, "pid": int}

A metric is called as ``metrics(scenario, result)``. One with an attribute
``observe(scenario) -> observer`` has the run's rows streamed to that
observer (``Master.run(observers=...)``, in ``result.observers``) and keeps
none in memory. One with an attribute
``snapshot_times(scenario) -> times`` gets the run's FMU states at those
times in ``result.snapshots`` (:class:`~cosim.loop.master.Snapshot`), e.g. to
linearize the loop along the flight.

A run that diverges, fails, or cannot even be built (a sampled value the
scenario refuses, an FMU that refuses a parameter, a worker that died) is a
record with its status and message, never an exception.

Every engine flies its runs through :func:`flown`: the scenarios of
:data:`AHEAD` consecutive runs are made together (:func:`scenarios`), then
those runs fly one after the other (:func:`execute`). A scenario made right
after a run's compiled loop, whose FMUs had filled the processor's caches,
took about two and a half times the CPU of one made after another.

Engines: ``workers = 1`` and no ``scheduler`` runs every run in this
process, one after the other (no Dask at all). With ``threads`` and no
``scheduler``: Dask's threaded scheduler (``dask.threaded``, no
``distributed`` imported, no cluster started) on ``workers`` threads of
this process, a task a few consecutive runs of one case (:func:`pieces`),
each record yielded as its run ends, the threads sharing one
:class:`MasterCache` (:func:`_run_threaded`; no worker process to start, nothing imported
twice, no record serialized; for runs whose loop is C that releases the
GIL and whose every FMU is known reentrant, which the caller vouches for:
an FMU that crashes takes this process with it). Otherwise a
``dask.distributed`` client: a ``LocalCluster`` of ``workers`` processes
with one thread each, or the running cluster at ``scheduler`` (an address
such as ``tcp://127.0.0.1:8786``). On ``distributed`` a Dask task flies a **batch** of
consecutive runs of the plan (:func:`execute_batch`) and returns their
records together; its size adapts (:func:`batch_size`): about
:data:`BATCH_SECONDS` of work, a share of the runs left that shrinks toward
the end so that no worker idles while another finishes a long batch, and
one run while nothing has been timed yet (or when runs are long: a study of
long runs is flown run by run, as before). A few batches per worker thread
are in flight, collected as they finish, so memory stays flat however many
runs a study has. A batch whose worker died is flown again run by run, so
the run that killed it fails alone.

Each worker process keeps a small cache of built masters (:class:`MasterCache`),
keyed by everything in the scenario a build depends on (FMUs, components,
connections, record, envelope, step, ordering): not the seed, the duration
and the start time, which are run-level, nor the parameters and start
values of an FMU no component read while it was built (a wind speed,
a plant parameter the controller does not take as its nominal model),
which the master sets at the start of the run, after the FMU's reset, as a
new master would. A run whose scenario differs from a cached one only in
those reuses its master (FMUs extracted and instantiated once); any other
difference builds a new master (the components may read FMU parameters when
built, e.g. a controller's nominal model from the plant's:
:func:`~cosim.scenario.assembly.build_master` notes which). FMU archives are
extracted once per worker process and shared by its masters (an FMU this
tool built: the one folder its cache extracted it to, for every instance
of every master, :func:`~cosim.fmi.description_cache.shared_extraction`), and a worker
parses the scenario of a set of overrides once (the seeds of one cell share
it).
"""
from __future__ import annotations

import contextlib
import itertools
import json
import logging
import os
import shutil
import tempfile
import threading
import time
import zipfile
from collections import OrderedDict
from multiprocessing.util import Finalize
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping

from ..errors import CosimError, ScenarioError, one_line
from ..executor import kind_for, parallel
from ..limits import WORKER_TIMEOUT
from ..scenario.definition import Scenario, apply_overrides, parse_scenario
from ..scenario.assembly import build_master, check_fmu_file, fmu_file, fmu_values
from ..loop.kernel import off_turn, python_turn
from .definition import Run

__all__ = ["MasterCache", "fly", "flown", "execute", "execute_batch", "scenarios", "batch_size", "pieces", "structure_key",
           "BATCH_SECONDS", "AHEAD"]

Metrics = Callable[[Scenario, Any], Mapping[str, Any]]


def structure_key(scenario: Scenario) -> str:
    """What a built master depends on: the scenario but its seed, duration
    and start time, and its FMUs' parameters and start values (a master
    keeps those of the FMUs its components read: :class:`MasterCache`)."""
    fmus = {name: {k: (str(v) if isinstance(v, Path) else v) for k, v in spec.items()
                   if k not in ("parameters", "start")}
            for name, spec in scenario.fmus.items()}
    return json.dumps({"fmus": fmus, "components": scenario.components, "connections": scenario.connections,
                       "record": scenario.record, "envelope": scenario.envelope, "step": scenario.step,
                       "ordering": scenario.ordering, "coupling": scenario.coupling, "source": str(scenario.source)},
                      sort_keys=True, default=repr)


class _Built:
    """A cached master, the ``[fmus]`` instances its components read when it
    was built and their values then (it serves another scenario of its
    structure whose values of those are the same)."""

    def __init__(self, master, reads: set[str], values: dict[str, dict[str, Any]]):
        self.master, self.reads = master, frozenset(reads)
        self.values = {name: values[name] for name in self.reads if name in values}

    def serves(self, values: Mapping[str, Mapping[str, Any]]) -> bool:
        return all(_same(values.get(name), value) for name, value in self.values.items())


def _same(a: Any, b: Any) -> bool:
    """Equal as a scenario means them: same keys in the same order, same values of the same types."""
    return json.dumps(a, default=repr) == json.dumps(b, default=repr)


class MasterCache:
    """Built masters by :func:`structure_key` (least recently used dropped
    beyond ``size``), with FMU archives extracted once and parsed scenarios
    by their overrides (least recently used dropped beyond ``scenarios``).

    :meth:`get` takes out a master ready for a scenario: an idle one built
    for it, or built for a scenario of the same structure whose components
    read the same FMU values; its FMUs' values
    (:func:`~cosim.scenario.assembly.fmu_values`) become the scenario's, checked
    against the FMU files as a build checks them. The next run resets the
    FMUs and sets them, as on a new master. :meth:`release` gives it back
    after its run (:meth:`drop` when the run could not start on it). A
    master is never handed to two runs at once, so threads may share one
    cache (Dask's threaded scheduler, :func:`_run_threaded`): a master
    serves whichever thread flies the next run of its structure, and is
    built once, not once per thread; the threads then also share the FMU
    files extracted once per cache (their instances load one copy of each
    library, which keeps no writable global state: ``docs/studies.md``)."""

    def __init__(self, size: int = 8, scenarios: int = 16):
        self.size = size
        self.masters: OrderedDict[tuple[str, int], _Built] = OrderedDict()  # the idle ones
        self._busy: dict[int, tuple[tuple[str, int], _Built]] = {}  # taken out by get, by id(master)
        self._lock = threading.RLock()
        self._extracted: dict[str, Path] = {}
        self._tmp: Path | None = None
        self._scenarios: OrderedDict[str, Scenario] = OrderedDict()  # of the base document last seen
        self._scenario_size = scenarios
        self._raw: Any = None
        self._raw_text: str | None = None
        self._serial = 0
        self.closed = False

    def scenario(self, raw: Mapping[str, Any], source: str | None, overrides: Mapping[str, Any]) -> Scenario:
        """The base document ``raw`` with ``overrides`` applied, validated
        (:func:`~cosim.scenario.definition.parse_scenario`): once per document and
        overrides; a refusal is raised every time."""
        with self._lock:
            return self._scenario(raw, source, overrides)

    def _scenario(self, raw: Mapping[str, Any], source: str | None, overrides: Mapping[str, Any]) -> Scenario:
        if raw is not self._raw:  # a new task's copy: compared once, as JSON (1 and 1.0 are two documents)
            text = json.dumps([source, raw], sort_keys=True, default=repr)
            if text != self._raw_text:
                self._scenarios.clear()
                self._raw_text = text
            self._raw = raw
        key = json.dumps(list(overrides.items()), default=repr)  # in order: a later key may set into an earlier
        scenario = self._scenarios.get(key)
        if scenario is None:
            scenario = parse_scenario(apply_overrides(dict(raw), overrides), source=Path(source) if source else None)
            self._scenarios[key] = scenario
            while len(self._scenarios) > self._scenario_size:
                self._scenarios.popitem(last=False)
        self._scenarios.move_to_end(key)
        return scenario

    def _fmu_dirs(self, scenario: Scenario) -> dict[str, Path]:
        """The folders the ``[fmus]`` archives of ``scenario`` are extracted
        to, once per cache; not an FMU this tool built, which every master
        loads from the one folder its cache extracted it to (built within
        :func:`~cosim.fmi.description_cache.shared_extraction`: :meth:`get`)."""
        from ..fmi.description_cache import in_cache_folder
        from ..files import extract_zip, run_time_entries

        dirs = {}
        for name, spec in scenario.fmus.items():
            archive = str(fmu_file(spec))
            if in_cache_folder(Path(archive)):
                continue
            if archive not in self._extracted:
                if Path(archive).is_dir():
                    self._extracted[archive] = Path(archive)
                else:
                    if self._tmp is None:
                        self._tmp = Path(tempfile.mkdtemp(prefix="cosim-worker-fmus-"))
                    target = self._tmp / str(len(self._extracted))
                    try:
                        with zipfile.ZipFile(archive) as zf:
                            runs = run_time_entries(zf.namelist())
                        extract_zip(archive, target, f"FMU {archive}", only=runs)
                    except (ScenarioError, OSError, zipfile.BadZipFile):  # the build says why, in the scenario's words
                        continue
                    self._extracted[archive] = target
            if archive in self._extracted:
                dirs[name] = self._extracted[archive]
        return dirs

    def _find(self, structure: str, values: Mapping[str, Any]) -> tuple[str, int] | None:
        for key, built in self.masters.items():
            if key[0] == structure and built.serves(values):
                return key
        return None

    def get(self, scenario: Scenario):
        """A master for ``scenario``, taken out of the cache until :meth:`release` or :meth:`drop`."""
        structure, values = structure_key(scenario), fmu_values(scenario)
        with self._lock:
            key = self._find(structure, values)
            built = self.masters.pop(key) if key is not None else None
            if built is None:
                dirs = self._fmu_dirs(scenario)
                self._serial += 1
                key = (structure, self._serial)
        if built is None:  # built outside the lock: another thread's run goes on meanwhile
            from ..fmi.description_cache import shared_extraction

            reads: set[str] = set()
            with off_turn(), shared_extraction():  # the FMUs this tool built: one extracted folder for every master
                built = _Built(build_master(scenario, dirs, reads=reads), reads, values)
        master = built.master
        with self._lock:
            self._busy[id(master)] = (key, built)
        try:
            if not _same(master.fmu_parameters, values):
                for name in scenario.fmus:  # what a build checks of the values (ranges, the period)
                    check_fmu_file(scenario, master.components[name])
                master.fmu_parameters = values
        except BaseException:
            self.release(master)
            raise
        return master

    def release(self, master) -> None:
        """Give ``master`` back after its run: the next run of its structure may take it."""
        with self._lock:
            key, built = self._busy.pop(id(master))
            self.masters[key] = built  # the most recently used last
            dropped = [self.masters.popitem(last=False)[1].master for _ in range(len(self.masters) - self.size)]
        for old in dropped:
            old.close()

    def drop(self, master) -> None:
        """Close ``master`` and forget it (a run could not start on it)."""
        with self._lock:
            self._busy.pop(id(master), None)
            for key, built in list(self.masters.items()):
                if built.master is master:
                    del self.masters[key]
        master.close()

    def close(self) -> None:
        self.closed = True
        while self.masters:
            self.masters.popitem()[1].master.close()
        while self._busy:  # none once every run has ended; a run cut short leaves its master here
            self._busy.popitem()[1][1].master.close()
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
        self._extracted.clear()
        self._scenarios.clear()
        self._raw = self._raw_text = None


POLL = 1.0  # s between looks at the cluster while no run finishes

_LOCAL = threading.local()  # a Dask worker's cache, one per thread of the worker (each takes its masters alone)


def _worker_cache() -> MasterCache:
    cache = getattr(_LOCAL, "cache", None)
    if cache is None or cache.closed:
        cache = _LOCAL.cache = MasterCache()
        # not atexit: a Dask worker is a multiprocessing child, which leaves by os._exit after
        # running multiprocessing's finalizers only (its extracted FMUs stayed in /tmp)
        Finalize(cache, cache.close, exitpriority=10)
    return cache


def _message(exc: BaseException) -> str:
    text = str(exc) if isinstance(exc, CosimError) else f"{type(exc).__name__}: {exc}"
    return one_line(text)


def execute(raw: Mapping[str, Any], source: str | None, run: Run, metrics: Metrics | None = None,
            cache: MasterCache | None = None, scenario: Scenario | Exception | None = None) -> dict[str, Any]:
    """Fly one run (in a worker, or here); always returns its record.
    ``scenario``: the run's, or its refusal, made before (:func:`scenarios`)."""
    record = _failed(run, None, os.getpid())
    cache = cache or _worker_cache()
    try:
        if scenario is None:
            scenario = cache.scenario(raw, source, run.overrides)
        elif isinstance(scenario, Exception):
            raise scenario
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
        # a metric may ask for the run's FMU states at chosen times (cosim.loop.master.Snapshot)
        wanted = getattr(metrics, "snapshot_times", None)
        # a metric taken as the rows stream (``metrics.observe(scenario)``, an observer of the run) keeps no
        # row in memory: a run's memory does not grow with its duration; other metrics read the kept rows
        observe = getattr(metrics, "observe", None)
        result = master.run(scenario.duration, seed=seed, t0=scenario.start_time, raise_on_error=False,
                            snapshots=wanted(scenario) if wanted is not None else (),
                            keep=0 if observe is not None else None,
                            observers=[observe(scenario)] if observe is not None else ())
    except Exception as exc:  # could not start, or a component raised mid-run
        cache.drop(master)
        record["error"] = _message(exc)
        return record
    cache.release(master)
    record.update(status=result.status, error=result.error, wall_time_s=result.wall_time)
    if metrics is not None:
        try:
            record["metrics"] = dict(metrics(scenario, result))
        except Exception as exc:
            record.update(status="failed", error=f"metrics: {_message(exc)}")
    return record


AHEAD = 8  # runs whose scenarios are made together before they fly (scenarios)


def scenarios(raw: Mapping[str, Any], source: str | None, runs: list[Run],
              cache: MasterCache) -> list[Scenario | Exception]:
    """The scenarios of ``runs`` (each, or the exception that refused it),
    made one after the other before any of them flies: after a run's
    compiled loop the processor's caches hold the FMUs', and a scenario
    made then took 1.3 ms of CPU for the circles, against 0.5 ms made right
    after another; made together, the first pays for the others."""
    out: list[Scenario | Exception] = []
    for run in runs:
        try:
            out.append(cache.scenario(raw, source, run.overrides))
        except Exception as exc:
            out.append(exc)
    return out


def flown(raw: Mapping[str, Any], source: str | None, runs: Iterable[Run], metrics: Metrics | None,
          cache: MasterCache, turn: threading.Lock | None = None,
          stop: threading.Event | None = None) -> Iterator[dict[str, Any]]:
    """Fly ``runs`` one after the other, each record yielded as its run
    ends: the scenarios of :data:`AHEAD` runs made together
    (:func:`scenarios`), then those runs flown (:func:`execute`); every way
    a study flies its runs (in this process, a Dask task's batch, a thread
    of this process) flies them so. ``turn``: each part runs holding this
    thread's turn at Python (:func:`~cosim.loop.kernel.python_turn`);
    ``stop``: no run starts once it is set."""
    held = (lambda: python_turn(turn)) if turn is not None else contextlib.nullcontext
    pending = iter(runs)
    while group := list(itertools.islice(pending, AHEAD)):
        with held():
            made = scenarios(raw, source, group, cache)
        for run, scenario in zip(group, made):
            if stop is not None and stop.is_set():
                return
            with held():
                record = execute(raw, source, run, metrics, cache, scenario)
            yield record


def execute_batch(raw: Mapping[str, Any], source: str | None, runs: list[Run], metrics: Metrics | None = None,
                  cache: MasterCache | None = None) -> tuple[list[dict[str, Any]], float]:
    """Fly ``runs`` (:func:`flown`, a Dask task's work): their records, in
    order, and the seconds the batch took."""
    started = time.perf_counter()
    records = list(flown(raw, source, runs, metrics, cache or _worker_cache()))
    return records, time.perf_counter() - started


def _failed(run: Run, error: str | None, pid: int | None = None) -> dict[str, Any]:
    """A run's record as it stands when it failed (or before it flew): the one record layout."""
    return {"key": run.index, "status": "failed", "error": error, "seed": run.seed, "wall_time_s": None,
            "metrics": {}, "pid": pid}


BATCH_SECONDS = 1.0  # s of runs a batch aims at (batch_size)
SHARE = 4  # a batch takes at most 1 / (SHARE x worker threads) of the runs not yet submitted


def batch_size(left: int | None, threads: int, per_run: float | None, seconds: float = BATCH_SECONDS) -> int:
    """How many runs the next Dask task flies: about ``seconds`` of work at
    ``per_run`` s a run (the last batch's, a worker's builds included: a
    worker's first batch, which imports and loads, is soon forgotten; one
    run while nothing has been timed), and at most a ``1 / (SHARE x
    threads)`` share of the ``left`` runs not yet submitted (when known),
    so the batches shrink toward the end of a study (guided
    self-scheduling) and the workers finish together. A batch's records
    come back when it ends: a driver stopped mid-study loses the batches in
    flight, a few seconds of work per worker thread, which a resumed study
    flies again."""
    if per_run is None:
        return 1
    n = max(1, int(seconds / max(per_run, 1e-9)))
    if left is not None:
        n = min(n, -(-left // (SHARE * max(1, threads))))
    return max(1, n)


def fly(scenario: Scenario, runs: Iterable[Run], workers: int = 1, scheduler: str | None = None,
        metrics: Metrics | None = None, window: int = 2,
        worker_timeout: float | None = WORKER_TIMEOUT, total: int | None = None,
        threads: bool = False) -> Iterator[dict[str, Any]]:
    """Fly every run of ``scenario`` (its document and file); yield each
    record as its run (in this process) or its batch (on Dask) finishes.
    ``workers = 1`` without ``scheduler``: in this process; else on Dask
    (see the module's docstring), ``window`` batches in flight per worker
    thread; ``total``, the number of ``runs`` if known, lets the batches
    shrink toward the end (:func:`batch_size`). ``threads``: without
    ``scheduler``, the runs fly on Dask's threaded scheduler, ``workers``
    threads of this process, not on a cluster of processes (the module's
    docstring says when that is safe). On a cluster, when it
    has had no worker for ``worker_timeout`` seconds (``None``: wait for
    ever), a :class:`~cosim.errors.CosimError` says so and the flight stops
    (the records yielded so far are kept by the caller)."""
    raw, source = scenario.raw, str(scenario.source) if scenario.source else None
    if scheduler is None and workers <= 1:
        cache = MasterCache()
        try:
            yield from flown(raw, source, runs, metrics, cache)
        finally:
            cache.close()
        return
    if kind_for(scheduler, gil_free=threads) == "threads":
        yield from _run_threaded(raw, source, runs, workers, metrics)
        return
    # processes: a Dask LocalCluster (not a concurrent.futures pool, which a dying worker breaks for good),
    # whose workers are replaced and whose dead batches are flown again (_run_dask)
    yield from _run_dask(raw, source, runs, workers, scheduler, metrics, window, worker_timeout, total)


CHUNK = 1000  # runs per graph of Dask's threaded scheduler (_run_threaded): the driver's memory stays flat
_END = object()  # the driver thread's last word


def pieces(chunk: list[Run], threads: int) -> Iterator[list[Run]]:
    """The tasks of ``chunk`` (consecutive runs of a plan) on Dask's threaded
    scheduler: consecutive runs of one case, at most ``ceil(left /
    threads)`` of the ``left`` runs of the chunk not yet in a task (guided
    self-scheduling: the tasks shrink toward the end, so the threads finish
    together). A case's runs mostly share a master (the plan's seeds and
    points inside a case), and a master serves one run at a time: a case
    flown by one thread at a time is built once, where consecutive runs
    given to every thread built it once per thread."""
    start = 0
    while start < len(chunk):
        cap = -(-(len(chunk) - start) // max(1, threads))
        end = start + 1
        while end < len(chunk) and end - start < cap and chunk[end].case == chunk[start].case:
            end += 1
        yield chunk[start:end]
        start = end


def _run_threaded(raw, source, runs, workers: int, metrics) -> Iterator[dict[str, Any]]:
    """Fly ``runs`` on Dask's threaded scheduler (``dask.threaded``, no
    ``distributed``, no cluster), ``workers`` threads of this process; yield
    each record as its run finishes.

    A driver thread takes the plan :data:`CHUNK` runs at a time (it is
    never listed whole) and computes a graph of its :func:`pieces`; each
    run's record is put on a queue as the run ends, which this generator
    empties, so the rows stream run by run (a stopped study loses only the
    runs in flight). The threads share one :class:`MasterCache` (a master
    built once per structure, handed to one run at a time). The threads
    are an executor made for this study (Dask's ``pool=``) and shut down
    when it ends, and the cache is closed then (its FMUs freed, its files
    removed): a pool Dask keeps per calling thread would outlive the study."""
    import queue
    from functools import partial

    import dask.threaded

    records: queue.Queue = queue.Queue()
    stop = threading.Event()  # the consumer is gone: the runs not yet started are not flown
    threads = max(1, workers)
    threaded = contextlib.ExitStack()
    pool = threaded.enter_context(parallel("threads", threads, name="cosim-run")).pool
    cache = MasterCache(size=max(8, 2 * threads))

    turn = threading.Lock()  # the threads' Python around their loops, one at a time (kernel.python_turn)

    def fly_piece(piece: list[Run]) -> None:
        while piece:
            done = 0
            try:
                for record in flown(raw, source, piece, metrics, cache, turn, stop):
                    records.put(record)
                    done += 1
                return
            except BaseException as exc:  # execute keeps a run's failures in its record: this is a bug
                records.put(_failed(piece[done], f"worker: {_message(exc)}", os.getpid()))
                piece = piece[done + 1:]  # the rest of the piece flies on

    def drive() -> None:
        try:
            pending = iter(runs)
            while not stop.is_set():
                chunk = list(itertools.islice(pending, CHUNK))
                if not chunk:
                    break
                tasks = list(pieces(chunk, threads))
                # names that Dask's ordering of independent tasks (by name, the last first) runs in plan order
                n = len(tasks)
                graph = {f"runs-{n - 1 - i:012d}": (partial(fly_piece, piece),) for i, piece in enumerate(tasks)}
                dask.threaded.get(graph, list(graph), pool=pool)
        except BaseException as exc:  # the plan itself raised: the study's error, raised in the consumer
            records.put(exc)
        finally:
            records.put(_END)

    driver = threading.Thread(target=drive, name="cosim-study-driver", daemon=True)
    driver.start()
    try:
        while True:
            item = records.get()
            if item is _END:
                break
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()  # the runs in flight finish (a master is never freed under its loop), no other starts
        driver.join()
        threaded.close()
        cache.close()


def _run_dask(raw, source, runs, workers, scheduler, metrics, window,
              worker_timeout: float | None, total: int | None) -> Iterator[dict[str, Any]]:
    from dask.distributed import wait

    cluster = contextlib.ExitStack()
    client = cluster.enter_context(parallel("dask", workers, scheduler=scheduler)).pool
    try:
        pending = iter(runs)
        again: list[Run] = []  # the runs of a batch whose worker died: flown again one by one
        raw = dict(raw)
        submitted: dict[Any, list[Run]] = {}
        taken = 0  # runs taken from the plan so far
        per_run: float | None = None  # s a run of the batch that finished last took (its builds included)

        def threads() -> int:
            return max(1, sum(client.nthreads().values()))

        def top_up(flying: set) -> None:
            """Submit batches until ``window`` per worker thread are in flight (or no run is left)."""
            nonlocal taken
            n = threads()
            while len(flying) < n * max(1, window):
                if again:
                    batch = [again.pop(0)]
                else:
                    left = None if total is None else max(0, total - taken)
                    batch = list(itertools.islice(pending, batch_size(left, n, per_run)))
                    taken += len(batch)
                if not batch:
                    return
                # pure=False: two batches are never the same task to Dask, even if equal
                fut = client.submit(execute_batch, raw, source, batch, metrics, pure=False)
                submitted[fut.key] = batch
                flying.add(fut)

        flying: set = set()
        top_up(flying)
        alone_since = None  # when the cluster was last seen without a worker
        while flying:
            try:
                done, flying = wait(flying, timeout=POLL, return_when="FIRST_COMPLETED")
            except TimeoutError:  # nothing finished within POLL: look at the cluster
                done = set()
            for fut in done:
                batch = submitted.pop(fut.key)
                try:
                    records, seconds = fut.result()
                    per_run = seconds / len(records)
                except Exception as exc:  # the worker died (e.g. a crash inside an FMU) or the task was lost
                    if len(batch) > 1:  # which run killed it is unknown: each alone, the others get their rows
                        again.extend(batch)
                        records = []
                    else:
                        records = [_failed(batch[0], f"worker: {_message(exc)}")]
                fut.release()
                yield from records
            top_up(flying)
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
                in_flight = sum(len(b) for b in submitted.values())
                raise CosimError(f"no Dask worker for {worker_timeout:g} s ({scheduler or 'the local cluster'} lost "
                                 f"them all): the study stops with {in_flight} runs in flight; its table keeps "
                                 f"every run that finished, and running it again resumes it")
    finally:
        cluster.close()
