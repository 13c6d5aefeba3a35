"""The compiled step loop (``kernel.c``) and its one definition of what
crosses between Python and C.

When every block a plan evaluates at t_n is an FMU (with no signal held
as an object: :attr:`Plan.compiled <cosim.loop.plan.Plan.compiled>`), the master's loop makes nothing but FMI
calls, copies between the signal array and the FMUs, the recording and the
guard: the master hands this loop the plan (:func:`prepare`) and each block
of communication points (:func:`load` compiles ``kernel.c`` once per machine,
content-addressed beside the user's cache, with the C compiler FMUs are built
with). The master still plans the run and raises every error; the compiled
loop only runs what the Python loop would, and gives the same results bit for
bit (tests/engine/test_engine_kernel.py). Without a C compiler the Python
loop runs (``load`` returns ``None``); ``COSIM_PYTHON_LOOP=1`` forces it.

One definition: the structures (:class:`KernelRun`, :class:`KernelStop`,
and the FMU's :class:`~cosim.fmi.c_calls.KernelFmu`), the codes
(:class:`Stop`, :class:`~cosim.fmi.c_calls.Call`) and the prototype of
``cosim_kernel_run`` are declared in Python, here and in
:mod:`cosim.fmi.c_calls`, and
:func:`header` writes them as the C header ``kernel.c`` is compiled with; the
compiled library is addressed by the hash of both, so the two sides cannot
drift apart (a prototype that does not match is a compile error).
"""
from __future__ import annotations

import ctypes
import enum
import os
import threading
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..fmi.c_calls import FMU_FIELDS, Call, KernelFmu
from ..native import F64, F64P, I64, I64P, c_header, compiled_library

__all__ = ["KernelRun", "KernelStop", "Stop", "header", "load", "prepare", "restarted", "python_turn", "off_turn"]

_SOURCE = Path(__file__).with_name("kernel.c")
_HEADER = "kernel_abi.h"


class Stop(enum.IntEnum):
    """Why ``cosim_kernel_run`` returned."""

    OK = 0  # the block of points ran
    GUARD = 1  # a guarded signal left its envelope (or is not finite)
    FMU = 2  # an FMI call failed (KernelStop says which FMU, which call, which status)
    TERMINATE = 3  # an FMI 3.0 FMU's doStep asked to terminate the simulation (KernelStop says which, when)


_RUN_FIELDS = (
    ("fmus", ctypes.POINTER(KernelFmu), "every FMU, in stepping order"),
    ("n_fmus", I64, "how many"),
    ("order", I64P, "the FMUs evaluated at t_n, in order (indices into fmus)"),
    ("n_order", I64, "how many"),
    ("signals", F64P, "the signal array (slot 0 is the time)"),
    ("t0", F64, "start time (s)"),
    ("h", F64, "communication step (s)"),
    ("n_steps", I64, "steps of the run: points 0 .. n_steps"),
    ("data", F64P, "the recorder's rows in memory, n_columns each"),
    ("data_first", I64, "the point whose row is data[0] (the recorder's chunk)"),
    ("n_columns", I64, "recorded columns"),
    ("record_idx", I64P, "their slots"),
    ("n_guard", I64, "guarded signals"),
    ("guard_idx", I64P, "their slots"),
    ("low", F64P, "their inclusive bounds (finite)"),
    ("high", F64P, ""),
    ("n_derived", I64, "converted inputs recorded or bounded (Plan.derived)"),
    ("derived_slot", I64P, "their own slots"),
    ("derived_source", I64P, "the slots of their sources"),
    ("derived_factor", F64P, "slot = factor * source + offset, before each row is recorded"),
    ("derived_offset", F64P, ""),
)


class KernelRun(ctypes.Structure):
    """A whole run: the plan's arrays and the run's time grid."""

    _fields_ = [(name, kind) for name, kind, _ in _RUN_FIELDS]


_STOP_FIELDS = (
    ("n", I64, "the communication point it stopped at"),
    ("fmu", I64, "Stop.FMU: which FMU (index into fmus)"),
    ("call", I64, "Stop.FMU: which Call"),
    ("status", I64, "Stop.FMU: the FMI status"),
    ("recorded", I64, "the row of point n was recorded before it stopped"),
)


class KernelStop(ctypes.Structure):
    """Where and why a block of points stopped early."""

    _fields_ = [(name, kind) for name, kind, _ in _STOP_FIELDS]


# the compiled entry point: runs points first .. last of the run, returns a Stop
_RUN_ARGS = (("run", ctypes.POINTER(KernelRun)), ("first", I64), ("last", I64),
             ("stop", ctypes.POINTER(KernelStop)))


def header() -> str:
    """The C header of this module's definitions, as ``kernel.c`` includes it."""
    return c_header("COSIM_KERNEL_ABI_H", "cosim/loop/kernel.py", (("KERNEL", Stop), ("CALL", Call)),
                    ((KernelFmu, FMU_FIELDS), (KernelRun, _RUN_FIELDS), (KernelStop, _STOP_FIELDS)),
                    (("cosim_kernel_run", _RUN_ARGS),))


@lru_cache(maxsize=None)
def load():
    """The compiled ``cosim_kernel_run``, or ``None`` (no C compiler, or the
    Python loop asked for); a source that does not compile raises."""
    if os.environ.get("COSIM_PYTHON_LOOP"):
        return None
    # -ffp-contract=off: u = factor * v + offset rounds twice, as numpy does in the Python loop
    target = compiled_library(_SOURCE.read_bytes(), "cosim_kernel",
                              ("-O2", "-std=c99", "-ffp-contract=off", "-Wall", "-Werror"),
                              {_HEADER: header().encode()})
    if target is None:
        return None
    run = ctypes.CDLL(str(target)).cosim_kernel_run
    run.argtypes = [kind for _, kind in _RUN_ARGS]
    run.restype = ctypes.c_int
    return run


def _array(values, dtype) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=dtype)


def prepare(plan, fmus, signals: np.ndarray, data: np.ndarray, low: np.ndarray, high: np.ndarray,
            t0: float, h: float, n_steps: int) -> KernelRun:
    """The :class:`KernelRun` of ``plan`` for the bound ``fmus`` (the master's,
    in the plan's order); it holds the arrays it points into."""
    entries = (KernelFmu * len(fmus))(*(fmu.kernel_entry(b.direct, b.sources, python=b.name in plan.python_calls,
                                                         time=signals)
                                        for fmu, b in zip(fmus, plan.fmus)))
    order = _array([b.index for b in plan.at_tn], np.int64)
    record, guard = _array(plan.record_slots, np.int64), _array(plan.watch_slots, np.int64)
    low, high = _array(low, np.float64), _array(high, np.float64)

    def p(array, kind):
        return array.ctypes.data_as(kind)

    kept = []  # the conversions' arrays, alive as long as the run
    for entry, b in zip(entries, plan.fmus):
        if b.converted:
            index, factor, offset = (_array(column, kind) for column, kind in
                                     zip(zip(*b.converted), (np.int64, np.float64, np.float64)))
            entry.n_conv, entry.conv_idx = len(index), p(index, I64P)
            entry.conv_factor, entry.conv_offset = p(factor, F64P), p(offset, F64P)
            kept += [index, factor, offset]
    slot, source, factor, offset = (_array(column, kind) for column, kind in
                                    zip(zip(*plan.derived) if plan.derived else ((),) * 4,
                                        (np.int64, np.int64, np.float64, np.float64)))
    kept += [slot, source, factor, offset]
    run = KernelRun(entries, len(fmus), p(order, I64P), len(order), p(signals, F64P), float(t0), float(h),
                    int(n_steps), p(data, F64P), 0, len(record), p(record, I64P), len(guard), p(guard, I64P),
                    p(low, F64P), p(high, F64P), len(slot), p(slot, I64P), p(source, I64P),
                    p(factor, F64P), p(offset, F64P))
    run.arrays = (entries, order, record, guard, low, high, signals, kept)  # alive as long as the run
    run.rows = data  # the recorder's rows, alive as long as the run (restarted replaces them)
    return run


def restarted(run: KernelRun, data: np.ndarray, t0: float, n_steps: int) -> KernelRun:
    """``run`` (:func:`prepare`'s, whose plan and FMUs are unchanged) made
    the next run's: from ``t0``, ``n_steps`` steps, its rows into ``data``."""
    run.t0, run.n_steps, run.data_first = float(t0), int(n_steps), 0
    run.data = data.ctypes.data_as(F64P)
    run.rows = data
    return run


_TURN = threading.local()  # the lock a thread's Python holds while it runs a study's run (python_turn)


@contextmanager
def python_turn(lock: threading.Lock):
    """This thread's Python runs holding ``lock``, handed over while the
    compiled loop runs (:func:`off_turn`): threads that fly runs side by
    side (a study on threads, :func:`cosim.study.runner.fly`) take turns at
    the Python around their loops, each turn whole. Without turns, the GIL
    changes hands at every FMI call a run's start makes (each releases it):
    two threads' Python interleaves call by call, both threads reach their
    loops together and come back together, and a core idles while the other
    thread's Python runs (a study of 10 s runs took 2.6x its ideal on 2
    cores: docs/cosim.md, "Many short runs on threads"). With turns, one thread's Python
    runs while the other's loop does."""
    lock.acquire()
    _TURN.lock = lock
    try:
        yield
    finally:
        _TURN.lock = None
        lock.release()


@contextmanager
def off_turn():
    """This thread's turn at Python (:func:`python_turn`) handed over for
    the block and taken back after: around a call into the compiled loop,
    and around a master's build (long, much of it in C: loading libraries,
    instantiating), whose Python may interleave with the other threads'."""
    lock = getattr(_TURN, "lock", None)
    if lock is None:
        yield
        return
    lock.release()
    try:
        yield
    finally:
        lock.acquire()
