"""What the benchmarks that time whole processes share: the ``fnn-cosim``
command of this environment, and a process's wall and CPU time.

Imported by the scripts beside it (``python benchmarks/<script>.py`` puts
this folder first on ``sys.path``).
"""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["cli", "timed", "measured"]


def cli(*args: str) -> list[str]:
    """``fnn-cosim ARGS`` as this interpreter's environment runs it."""
    script = Path(sys.executable).with_name("fnn-cosim")
    return [str(script), *args] if script.exists() else [sys.executable, "-m", "quadrotor_paper.cli", *args]


def timed(command: list[str]) -> tuple[float, float]:
    """Wall time and CPU time (user + system of the finished child) of one run of ``command``, s."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def measured(command: list[str]) -> tuple[float, float, int]:
    """Wall time (s), CPU time (s) and peak resident memory (bytes) of one run
    of ``command``, the process's own (``wait4``: not the largest of every
    child so far, as ``RUSAGE_CHILDREN`` would say); a failure raises."""
    t = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - t
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode:
        raise subprocess.CalledProcessError(process.returncode, command)
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss * 1024  # Linux: ru_maxrss in KiB
