"""Whole-process time of ``fnn-cosim stability`` (the default: the PD's report).

Runs, alternating, in fresh interpreters (the FMUs built beforehand by one
untimed run, which also warms the file cache):

* ``fnn-cosim stability --out <tmp>``: the command as users run it (on a
  2-core machine ``--workers`` defaults to 2: the operating points' figures
  are drawn in a second process while the study goes on);
* ``fnn-cosim stability --workers 1 --out <tmp>``: everything in one process;
* ``fnn-cosim stability --figures --out <tmp>``: the report without its
  figures (the PD's numbers alone).

and prints, for each, the median wall time and the median CPU time of the
process and its children (user + sys; the steadier figure on a shared
machine, where the wall time also measures the other jobs), with the load
average before and after. Target (issue 26): the default <= 20 s on an idle
2-core machine. Printed, never asserted.

    .venv/bin/python benchmarks/stability_speed.py [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

from processes import cli, timed


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="stability-speed-") as tmp:
        commands = {
            "fnn-cosim stability": cli("stability", "--out", str(Path(tmp) / "default")),
            "fnn-cosim stability --workers 1": cli("stability", "--workers", "1", "--out", str(Path(tmp) / "one")),
            "fnn-cosim stability --figures": cli("stability", "--figures", "--out", str(Path(tmp) / "none")),
        }
        timed(next(iter(commands.values())))  # builds the FMUs if needed, warms the caches
        load = os.getloadavg()[0]
        times: dict[str, list[tuple[float, float]]] = {label: [] for label in commands}
        for _ in range(args.repeats):
            for label, command in commands.items():
                times[label].append(timed(command))
        load_after = os.getloadavg()[0]

    print(f"fnn-cosim stability, whole process, median of {args.repeats} alternating runs "
          f"({os.cpu_count()} cores, load average {load:.1f} -> {load_after:.1f}):")
    for label, values in times.items():
        wall = statistics.median(w for w, _ in values)
        cpu = statistics.median(c for _, c in values)
        print(f"  {label:35s} wall {wall:6.1f} s   CPU {cpu:6.1f} s")
    print("  target: the default <= 20 s wall on an idle 2-core machine")
    return 0


if __name__ == "__main__":
    sys.exit(main())
