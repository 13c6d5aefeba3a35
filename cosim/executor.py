"""Every parallel job of the engine and its users, one way: threads, processes or a Dask cluster.

:func:`parallel` is a context manager that yields an :class:`Executor`:
``submit(fn, *args)`` (a future), ``map(fn, *iterables)`` (the results, in
order), ``as_completed(futures)`` (each future as it finishes) and
``result(future)``. Three implementations, each the library's own:

- ``"threads"``: :class:`concurrent.futures.ThreadPoolExecutor` (the
  submitter's context variables carried to the worker thread, as Dask's
  ``ContextAwareThreadPoolExecutor`` does, so the pool also serves
  ``dask.threaded.get(pool=...)``);
- ``"processes"``: :class:`concurrent.futures.ProcessPoolExecutor` whose
  workers start by ``forkserver`` where the platform has it, else by
  ``spawn``; never by ``fork``: a fork copies one thread of a process that
  may hold others (a Dask scheduler, a thread pool, a BLAS pool) with their
  locks held, and the child can deadlock on them (Python 3.12 warns). The
  work and what it needs reach the workers by pickling; what every task
  shares goes once per worker through ``initializer``;
- ``"dask"``: a ``dask.distributed`` client, of the cluster at
  ``scheduler`` (an address such as ``tcp://127.0.0.1:8786``) or of a
  ``LocalCluster`` of ``workers`` processes with one thread each (started
  by forkserver or spawn too, in a scratch folder removed at the end).
  Dask is imported only here and only then.

A worker's exception reaches the caller as the engine's error: an engine
error (:class:`~cosim.errors.CosimError`, pickled whole from a worker
process) as itself, anything else, or a worker that died, as a
:class:`WorkerError` naming it (the original as its ``__cause__``).

The choice rule, the one place it is made (:func:`kind_for`): Dask where a
scheduler is given; threads for work that is our compiled FMUs
(:func:`compiled_ours`: the compiled loop releases the GIL, and their C
keeps no global state); processes for anything else (someone's FMU may keep
globals or crash; a Python FMU or component holds the GIL).

A foundation module: it imports only the standard library and
:mod:`cosim.errors`.
"""
from __future__ import annotations

import concurrent.futures as cf
import contextvars
import logging
import multiprocessing
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

from .errors import CosimError, ScenarioError, one_line

__all__ = ["Executor", "WorkerError", "parallel", "kind_for", "compiled_ours", "start_method", "KINDS"]

KINDS = ("threads", "processes", "dask")
LOG_LENGTH = 100  # entries of a local Dask scheduler's diagnostic logs (_dask)
OWN_FMU_VALUES = ("parameters", "start")  # what may change of an [fmus] entry and leave it our compiled FMU


class WorkerError(CosimError):
    """A worker's work raised something other than an engine error, or the worker died."""


def start_method() -> str:
    """How worker processes start: ``forkserver`` where there is one (POSIX),
    else ``spawn`` (module docstring: never ``fork``). Forked from a server
    process that runs no threads, forkserver's workers start in about half
    the time of spawn's fresh interpreters and close in a tenth (a study of 6
    short runs on 2 workers: 3.9-5.0 s against 5.1-7.2 s)."""
    return "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"


def compiled_ours(fmus: Mapping[str, Mapping[str, Any]], changed: Iterable[Sequence[str]] = ()) -> bool:
    """Whether runs of a scenario with these ``[fmus]`` entries are only our
    compiled C: every entry a registered model of this project (its
    ``model`` key) in Co-Simulation (its C keeps no global state and is
    reentrant, checked on every built binary; a Model Exchange FMU is
    integrated in Python), and no ``changed`` key (a dotted key split into
    its parts, as a study's cases, grid and draws give them) gives an entry
    another file or interface: only its parameters or start values."""
    for spec in fmus.values():
        if "model" not in spec or spec.get("interface", "CoSimulation") != "CoSimulation":
            return False
    for parts in changed:
        if parts[0] == "fmus" and (len(parts) < 3 or parts[2] not in OWN_FMU_VALUES):
            return False
    return True


def kind_for(scheduler: str | None, gil_free: bool) -> str:
    """The executor for a job (the module's choice rule): ``"dask"`` where a
    ``scheduler`` address is given; ``"threads"`` when the work is
    ``gil_free`` (our compiled FMUs, :func:`compiled_ours`, and no Python
    per task that the GIL would serialize); else ``"processes"``."""
    if scheduler is not None:
        return "dask"
    return "threads" if gil_free else "processes"


class _Threads(cf.ThreadPoolExecutor):
    """A thread pool whose tasks run in the submitter's context (its context variables)."""

    def submit(self, fn, /, *args, **kwargs):
        return super().submit(contextvars.copy_context().run, fn, *args, **kwargs)


class Executor:
    """What :func:`parallel` yields. ``kind``: one of :data:`KINDS`;
    ``pool``: the library's object underneath (a :mod:`concurrent.futures`
    executor, a ``distributed.Client``) for a caller that needs its own API
    (Dask's threaded scheduler, a study's watch over a cluster's workers)."""

    def __init__(self, kind: str, pool: Any, workers: int):
        self.kind, self.pool, self._workers = kind, pool, workers

    @property
    def workers(self) -> int:
        """Worker threads or processes now (a cluster's may come and go)."""
        if self.kind == "dask":
            return sum(self.pool.nthreads().values())
        return self._workers

    def submit(self, fn: Callable, /, *args, **kwargs):
        """``fn(*args, **kwargs)`` on a worker: its future (two equal calls are two tasks, also on Dask)."""
        if self.kind == "dask":
            return self.pool.submit(fn, *args, pure=False, **kwargs)
        return self.pool.submit(fn, *args, **kwargs)

    def result(self, future, timeout: float | None = None) -> Any:
        """The future's result; a worker's exception as the engine's error (module docstring)."""
        try:
            return future.result(timeout)
        except CosimError:
            raise
        except Exception as exc:
            raise WorkerError(f"a {self.kind} worker failed: {type(exc).__name__}: {one_line(exc)}") from exc

    def map(self, fn: Callable, *iterables: Iterable) -> list:
        """``fn`` over the items of ``iterables`` (zipped), side by side: the
        results in order. The first failure (:meth:`result`) is raised once
        every other task is done or cancelled, so none runs on behind the
        caller (on a cluster, those not started are cancelled)."""
        futures = [self.submit(fn, *args) for args in zip(*iterables)]
        try:
            return [self.result(f) for f in futures]
        except BaseException:
            for f in futures:
                f.cancel()
            if self.kind != "dask":  # a cluster's task runs on or not as its worker decides; its result is dropped
                cf.wait(futures)
            raise

    def as_completed(self, futures: Iterable) -> Iterator:
        """Each of ``futures`` as it finishes (its result by :meth:`result`)."""
        if self.kind == "dask":
            from distributed import as_completed

            return iter(as_completed(list(futures)))
        return cf.as_completed(list(futures))


@contextmanager
def parallel(kind: str, workers: int = 1, *, scheduler: str | None = None, initializer: Callable | None = None,
             initargs: tuple = (), name: str = "cosim") -> Iterator[Executor]:
    """An :class:`Executor` of ``kind`` (:data:`KINDS`, module docstring)
    with ``workers`` threads or processes (at least one; for ``"dask"``
    without ``scheduler``: a local cluster of that many processes).
    ``initializer(*initargs)`` runs once in each worker before its first
    task (threads and processes: what every task shares, pickled once per
    process); ``name``: the threads' name prefix. Leaving the block waits
    for the tasks in flight, cancels the others and stops the workers (a
    cluster given by address keeps its own)."""
    n = max(1, int(workers))
    if kind in ("threads", "processes"):
        if kind == "threads":
            pool = _Threads(n, thread_name_prefix=name, initializer=initializer, initargs=initargs)
        else:
            pool = cf.ProcessPoolExecutor(n, mp_context=multiprocessing.get_context(start_method()),
                                          initializer=initializer, initargs=initargs)
        try:
            yield Executor(kind, pool, n)
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    elif kind == "dask":
        if initializer is not None:
            raise ValueError("parallel('dask'): no initializer (a cluster's workers come and go)")
        with _dask(n, scheduler) as client:
            yield Executor(kind, client, n)
    else:
        raise ValueError(f"parallel: kind {kind!r} is not one of {', '.join(KINDS)}")


@contextmanager
def _dask(workers: int, scheduler: str | None):
    """A ``distributed.Client``: of the cluster at ``scheduler``, or of a
    local cluster of ``workers`` processes whose scratch space (Dask's
    ``dask-scratch-space``: the workers' folders, its locks) is a folder
    made here and removed at the end (it was left in the system's temporary
    folder after every study)."""
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=30)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ScenarioError(f"--scheduler {scheduler}: no Dask scheduler answers there "
                                f"({type(exc).__name__}: {one_line(exc)})") from None
        try:
            yield client
        finally:
            client.close()
        return
    scratch = Path(tempfile.mkdtemp(prefix="cosim-dask-"))
    try:
        # The local scheduler lives in this process. Its diagnostic logs keep
        # about 19 kB per task up to 10 000 entries (measured by
        # benchmarks/study_efficiency.py): short logs keep the driver's memory
        # flat as a study grows. Its workers start by start_method(). A cluster
        # given by address keeps its own settings.
        with dask.config.set({"temporary-directory": str(scratch),
                              "distributed.admin.log-length": LOG_LENGTH,
                              "distributed.admin.low-level-log-length": LOG_LENGTH,
                              "distributed.worker.multiprocessing-method": start_method()}):
            # no dashboard; the scheduler's HTTP server (which dashboard_address=None put on 8787, with a
            # warning on stderr when another cluster held that port) on a free port
            quiet = {"dashboard_address": ":0", "scheduler_kwargs": {"dashboard": False},
                     "silence_logs": logging.ERROR, "local_directory": scratch}
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, **quiet)
            try:
                client = Client(cluster)
            except BaseException:
                cluster.close()
                raise
        try:
            yield client
        finally:
            client.close()
            cluster.close()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
