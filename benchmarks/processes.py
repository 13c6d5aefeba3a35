"""What the benchmarks that time whole processes share: the ``fnn-cosim``
command of this environment, and a process's wall and CPU time.

Imported by the scripts beside it (``python benchmarks/<script>.py`` puts
this folder first on ``sys.path``).
"""
from __future__ import annotations

import resource
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["cli", "timed"]


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
