"""The compiled step loop (``kernel.c``) and its one definition of what
crosses between Python and C.

When every block a plan evaluates at t_n is an FMU (with no signal held
as an object: :attr:`Plan.compiled <cosim.plan.Plan.compiled>`), the master's loop makes nothing but FMI
calls, copies between the signal array and the FMUs, the recording and the
guard: the master hands this loop the plan (:func:`prepare`) and each block
of communication points (:func:`load` compiles ``kernel.c`` once per machine,
content-addressed beside the user's cache, with the C compiler FMUs are built
with). The master still plans the run and raises every error; the compiled
loop only runs what the Python loop would, and gives the same results bit for
bit (tests/engine/test_engine_kernel.py). Without a C compiler the Python
loop runs (``load`` returns ``None``); ``COSIM_PYTHON_LOOP=1`` forces it.

One definition: the structures (:class:`KernelFmu`, :class:`KernelRun`,
:class:`KernelStop`), the codes (:class:`Stop`, :class:`Call`) and the
prototype of ``cosim_kernel_run`` are declared here, in Python, and
:func:`header` writes them as the C header ``kernel.c`` is compiled with; the
compiled library is addressed by the hash of both, so the two sides cannot
drift apart (a prototype that does not match is a compile error).
"""
from __future__ import annotations

import ctypes
import enum
import hashlib
import os
import shutil
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path

import numpy as np

from .file_lock import exclusive

__all__ = ["KernelFmu", "KernelRun", "KernelStop", "Stop", "Call", "header", "c_header", "load", "prepare",
           "compiled_library"]

_SOURCE = Path(__file__).with_name("kernel.c")
_HEADER = "kernel_abi.h"


class Stop(enum.IntEnum):
    """Why ``cosim_kernel_run`` returned."""

    OK = 0  # the block of points ran
    GUARD = 1  # a guarded signal left its envelope (or is not finite)
    FMU = 2  # an FMI call failed (KernelStop says which FMU, which call, which status)
    TERMINATE = 3  # an FMI 3.0 FMU's doStep asked to terminate the simulation (KernelStop says which, when)


class Call(enum.IntEnum):
    """The loop's three FMI calls, as a failure names them."""

    SET = 0  # fmi2SetReal / fmi3SetFloat64 of the bound inputs
    GET = 1  # fmi2GetReal / fmi3GetFloat64 of the bound outputs and internals
    STEP = 2  # fmi2DoStep / fmi3DoStep

    @property
    def label(self) -> str:
        return ("set inputs", "get outputs", "doStep")[self]


_i64, _f64, _ptr = ctypes.c_int64, ctypes.c_double, ctypes.c_void_p
_u32p, _i64p, _f64p = (ctypes.POINTER(t) for t in (ctypes.c_uint32, ctypes.c_int64, ctypes.c_double))

# (name, ctypes type, what it is): the fields of each structure, in order
_FMU_FIELDS = (
    ("version", _i64, "FMI 2 or 3"),
    ("component", _ptr, "the fmi2Component / fmi3Instance"),
    ("set", _ptr, "fmi2SetReal / fmi3SetFloat64"),
    ("get", _ptr, "fmi2GetReal / fmi3GetFloat64"),
    ("step", _ptr, "fmi2DoStep / fmi3DoStep"),
    ("in_vr", _u32p, "value references of the bound inputs"),
    ("n_in", _i64, "how many"),
    ("in_idx", _i64p, "signal slots of their sources"),
    ("u", _f64p, "the inputs, gathered"),
    ("out_vr", _u32p, "value references of the outputs and internals read"),
    ("n_out", _i64, "how many"),
    ("y", _f64p, "their slots in the signal array (contiguous)"),
    ("direct", _i64, "evaluated at t_n (feedthrough ordering), else its inputs are set at the exchange"),
    ("n_conv", _i64, "inputs with a unit conversion (FmuBlock.converted)"),
    ("conv_idx", _i64p, "their indices among the bound inputs"),
    ("conv_factor", _f64p, "u = factor * source + offset"),
    ("conv_offset", _f64p, ""),
    ("python", _i64, "driven by Python calls (Plan.python_calls): set, get and step called even with nothing bound"),
)


class KernelFmu(ctypes.Structure):
    """One FMU as the plan binds it (cosim.plan.FmuBlock)."""

    _fields_ = [(name, kind) for name, kind, _ in _FMU_FIELDS]


_RUN_FIELDS = (
    ("fmus", ctypes.POINTER(KernelFmu), "every FMU, in stepping order"),
    ("n_fmus", _i64, "how many"),
    ("order", _i64p, "the FMUs evaluated at t_n, in order (indices into fmus)"),
    ("n_order", _i64, "how many"),
    ("signals", _f64p, "the signal array (slot 0 is the time)"),
    ("t0", _f64, "start time (s)"),
    ("h", _f64, "communication step (s)"),
    ("n_steps", _i64, "steps of the run: points 0 .. n_steps"),
    ("data", _f64p, "the recorder's rows in memory, n_columns each"),
    ("data_first", _i64, "the point whose row is data[0] (the recorder's chunk)"),
    ("n_columns", _i64, "recorded columns"),
    ("record_idx", _i64p, "their slots"),
    ("n_guard", _i64, "guarded signals"),
    ("guard_idx", _i64p, "their slots"),
    ("low", _f64p, "their inclusive bounds (finite)"),
    ("high", _f64p, ""),
    ("n_derived", _i64, "converted inputs recorded or bounded (Plan.derived)"),
    ("derived_slot", _i64p, "their own slots"),
    ("derived_source", _i64p, "the slots of their sources"),
    ("derived_factor", _f64p, "slot = factor * source + offset, before each row is recorded"),
    ("derived_offset", _f64p, ""),
)


class KernelRun(ctypes.Structure):
    """A whole run: the plan's arrays and the run's time grid."""

    _fields_ = [(name, kind) for name, kind, _ in _RUN_FIELDS]


_STOP_FIELDS = (
    ("n", _i64, "the communication point it stopped at"),
    ("fmu", _i64, "Stop.FMU: which FMU (index into fmus)"),
    ("call", _i64, "Stop.FMU: which Call"),
    ("status", _i64, "Stop.FMU: the FMI status"),
    ("recorded", _i64, "the row of point n was recorded before it stopped"),
)


class KernelStop(ctypes.Structure):
    """Where and why a block of points stopped early."""

    _fields_ = [(name, kind) for name, kind, _ in _STOP_FIELDS]


# the compiled entry point: runs points first .. last of the run, returns a Stop
_RUN_ARGS = (("run", ctypes.POINTER(KernelRun)), ("first", _i64), ("last", _i64),
             ("stop", ctypes.POINTER(KernelStop)))

_C_SCALARS = {ctypes.c_int64: "int64_t", ctypes.c_double: "double", ctypes.c_void_p: "void *",
              ctypes.c_uint32: "uint32_t", ctypes.c_int: "int", ctypes.c_size_t: "size_t", ctypes.c_char: "char"}


def _c_type(kind) -> str:
    if kind in _C_SCALARS:
        return _C_SCALARS[kind]
    if issubclass(kind, ctypes._Pointer):
        return _c_type(kind._type_) + " *"
    if issubclass(kind, ctypes.Structure):
        return kind.__name__
    raise TypeError(f"no C spelling for {kind!r}")


def _declare(kind, name: str) -> str:
    if issubclass(kind, ctypes.Array):  # a fixed array inside a structure (a message buffer)
        return f"{_c_type(kind._type_)} {name}[{kind._length_}]"
    spelled = _c_type(kind)
    return f"{spelled}{name}" if spelled.endswith("*") else f"{spelled} {name}"


def c_header(guard: str, source: str, enums, structs, prototypes) -> str:
    """A C header from ctypes definitions, the one way Python declares what
    crosses into C (``kernel.c``, ``me_system.c``): ``enums`` as ``(prefix,
    IntEnum)``, ``structs`` as ``(Structure, fields)`` with fields ``(name,
    ctypes type, comment)``, ``prototypes`` as ``(name, ((argument, ctypes
    type), ...))`` of functions returning ``int``."""
    lines = [f"/* Generated by {source} from its ctypes structures and enums: do not edit. */",
             f"#ifndef {guard}", f"#define {guard}", "#include <stdint.h>", ""]
    for prefix, codes in enums:
        lines.append("enum { " + ", ".join(f"{prefix}_{c.name} = {int(c)}" for c in codes) + " };")
    for struct, fields in structs:
        lines += ["", f"/* {struct.__doc__.splitlines()[0]} */", "typedef struct {"]
        lines += [f"    {_declare(kind, name)};" + (f"  /* {text} */" if text else "") for name, kind, text in fields]
        lines.append(f"}} {struct.__name__};")
    lines.append("")
    for name, args in prototypes:
        lines.append(f"int {name}({', '.join(_declare(kind, arg) for arg, kind in args)});")
    lines += ["", "#endif", ""]
    return "\n".join(lines)


def header() -> str:
    """The C header of this module's definitions, as ``kernel.c`` includes it."""
    return c_header("COSIM_KERNEL_ABI_H", "cosim/kernel.py", (("KERNEL", Stop), ("CALL", Call)),
                    ((KernelFmu, _FMU_FIELDS), (KernelRun, _RUN_FIELDS), (KernelStop, _STOP_FIELDS)),
                    (("cosim_kernel_run", _RUN_ARGS),))


def _cache() -> Path:
    root = os.environ.get("COSIM_CACHE") or os.path.join(os.environ.get("XDG_CACHE_HOME")
                                                         or os.path.expanduser("~/.cache"), "cosim")
    return Path(root)


def compiled_library(source: bytes, stem: str, flags: tuple[str, ...] = (), include: dict[str, bytes] | None = None
                     ) -> Path | None:
    """The shared library of the C ``source`` (with the headers ``include``,
    name -> text), compiled once per machine with the C compiler FMUs are
    built with and kept content-addressed in the cache (``stem`` and the hash
    of the source, the headers and the flags); ``None`` without a compiler.
    A source that does not compile raises: ours, a bug, never a silent
    fallback. The kernel's and the calibrator's compiled functions
    (:mod:`cosim.calibration.symbolic`) are made here."""
    digest = hashlib.sha256(source)
    for name, text in sorted((include or {}).items()):
        digest.update(name.encode() + text)
    digest.update(" ".join(flags).encode())
    target = _cache() / f"{stem}_{digest.hexdigest()[:16]}.so"
    if target.exists():
        return target
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        return None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        # one compiler per library across processes (the calibration's segments take 5-20 s of CPU each)
        with exclusive(target.with_suffix(".lock")):
            if target.exists():  # compiled by the process that held the lock before us
                return target
            return _compile_library(cc, source, stem, flags, include, target)
    except OSError:
        return None


def _compile_library(cc: str, source: bytes, stem: str, flags: tuple[str, ...], include: dict[str, bytes] | None,
                     target: Path) -> Path:
    # compile beside the target and rename: parallel processes never load half a library
    fd, tmp = tempfile.mkstemp(suffix=".so.part", dir=target.parent)
    os.close(fd)
    with tempfile.TemporaryDirectory() as folder:
        for name, text in (include or {}).items():
            Path(folder, name).write_bytes(text)
        src = Path(folder, f"{stem}.c")
        src.write_bytes(source)
        result = subprocess.run([cc, *flags, "-shared", "-fPIC", f"-I{folder}", "-o", tmp, str(src)],
                                capture_output=True, text=True)
    if result.returncode != 0:
        os.unlink(tmp)
        raise RuntimeError(f"compiling {stem}.c with {cc} failed: {result.stderr.strip()}")
    os.replace(tmp, target)
    return target


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
            entry.n_conv, entry.conv_idx = len(index), p(index, _i64p)
            entry.conv_factor, entry.conv_offset = p(factor, _f64p), p(offset, _f64p)
            kept += [index, factor, offset]
    slot, source, factor, offset = (_array(column, kind) for column, kind in
                                    zip(zip(*plan.derived) if plan.derived else ((),) * 4,
                                        (np.int64, np.int64, np.float64, np.float64)))
    kept += [slot, source, factor, offset]
    run = KernelRun(entries, len(fmus), p(order, _i64p), len(order), p(signals, _f64p), float(t0), float(h),
                    int(n_steps), p(data, _f64p), 0, len(record), p(record, _i64p), len(guard), p(guard, _i64p),
                    p(low, _f64p), p(high, _f64p), len(slot), p(slot, _i64p), p(source, _i64p),
                    p(factor, _f64p), p(offset, _f64p))
    run.arrays = (entries, order, record, guard, low, high, signals, data, kept)  # alive as long as the run
    return run
