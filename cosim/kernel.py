"""The compiled step loop for systems of FMUs only (``kernel.c``).

When every block of a run is an FMU (no Python component), the master's loop
makes nothing but FMI calls, copies between the signal array and the FMUs,
the recording and the guard: :func:`load` compiles ``kernel.c`` once per
machine (content-addressed, beside the user's cache; the C compiler FMUs are
built with) and the master hands it each block of communication points. The
Python master still plans the run and raises every error; the compiled loop
only runs what the Python loop would, and gives the same results bit for bit
(tests/engine/test_engine_kernel.py). Without a C compiler the Python loop
runs (``load`` returns ``None``); ``COSIM_PYTHON_LOOP=1`` forces it.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path

__all__ = ["KernelFmu", "KernelStop", "load", "KERNEL_OK", "KERNEL_GUARD", "KERNEL_FMU", "CALLS"]

KERNEL_OK, KERNEL_GUARD, KERNEL_FMU = 0, 1, 2
CALLS = ("set inputs", "get outputs", "doStep")
_SOURCE = Path(__file__).with_name("kernel.c")


class KernelFmu(ctypes.Structure):
    _fields_ = [("version", ctypes.c_int64), ("component", ctypes.c_void_p), ("set", ctypes.c_void_p),
                ("get", ctypes.c_void_p), ("step", ctypes.c_void_p), ("in_vr", ctypes.c_void_p),
                ("n_in", ctypes.c_int64), ("in_idx", ctypes.c_void_p), ("u", ctypes.c_void_p),
                ("out_vr", ctypes.c_void_p), ("n_out", ctypes.c_int64), ("y", ctypes.c_void_p),
                ("direct", ctypes.c_int64)]


class KernelStop(ctypes.Structure):
    _fields_ = [("n", ctypes.c_int64), ("fmu", ctypes.c_int64), ("call", ctypes.c_int64), ("status", ctypes.c_int64),
                ("recorded", ctypes.c_int64)]


def _cache() -> Path:
    root = os.environ.get("COSIM_CACHE") or os.path.join(os.environ.get("XDG_CACHE_HOME")
                                                         or os.path.expanduser("~/.cache"), "cosim")
    return Path(root)


@lru_cache(maxsize=None)
def load():
    """The compiled ``cosim_kernel_run``, or ``None`` (no compiler, or the
    Python loop asked for)."""
    if os.environ.get("COSIM_PYTHON_LOOP"):
        return None
    source = _SOURCE.read_bytes()
    target = _cache() / f"cosim_kernel_{hashlib.sha256(source).hexdigest()[:16]}.so"
    if not target.exists():
        cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
        if not cc:
            return None
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            # compile beside the target and rename: parallel processes never load half a library
            fd, tmp = tempfile.mkstemp(suffix=".so.part", dir=target.parent)
            os.close(fd)
            result = subprocess.run([cc, "-O2", "-std=c99", "-shared", "-fPIC", "-o", tmp, str(_SOURCE)],
                                    capture_output=True, text=True)
            if result.returncode != 0:
                os.unlink(tmp)
                return None
            os.replace(tmp, target)
        except OSError:
            return None
    run = ctypes.CDLL(str(target)).cosim_kernel_run
    run.restype = ctypes.c_int
    return run
