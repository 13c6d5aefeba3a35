"""Start-up of the command line, against a reference measured in the same run.

Times, alternating, in fresh interpreters:

* ``fnn-cosim --help`` (the entry point builds its whole parser);
* the reference: ``python -c "import numpy, casadi, fmpy"``, the libraries
  every command needs anyway;

and prints the medians and their ratio. Target: ratio <= 1.5 (the parser
must not load python-control, scipy.signal or matplotlib; a test checks that
by the modules imported, this script by the clock).

    .venv/bin/python benchmarks/cli_startup.py [--repeats 9]
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path


def _wall(command: list[str]) -> float:
    t = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=9)
    args = p.parse_args(argv)

    script = Path(sys.executable).with_name("fnn-cosim")
    cli = [str(script), "--help"] if script.exists() else [sys.executable, "-m", "quadrotor_paper.cli", "--help"]
    reference = [sys.executable, "-c", "import numpy, casadi, fmpy"]
    _wall(cli), _wall(reference)  # warm the file cache
    times: dict[str, list[float]] = {"cli": [], "reference": []}
    for _ in range(args.repeats):
        times["cli"].append(_wall(cli))
        times["reference"].append(_wall(reference))
    cli_s, ref_s = statistics.median(times["cli"]), statistics.median(times["reference"])
    print(f"start-up, median of {args.repeats}:")
    print(f"  {'fnn-cosim --help':40s} {cli_s * 1e3:7.0f} ms")
    reference_label = 'python -c "import numpy, casadi, fmpy"'
    print(f"  {reference_label:40s} {ref_s * 1e3:7.0f} ms")
    print(f"  {'ratio':40s} {cli_s / ref_s:7.2f}  (target <= 1.5)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
