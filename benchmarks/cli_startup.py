"""Start-up of the command line, against references measured in the same run.

Times, alternating, in fresh interpreters:

* ``fnn-cosim --help`` (the entry point builds its whole parser) against
  ``python -c "import numpy, casadi, fmpy"``, the libraries every command
  may need. Target: ratio <= 1.5 (the parser must not load python-control,
  scipy.signal or matplotlib);
* ``fnn-cosim run circles --no-plots --quiet --out <tmp>``, a whole run of
  the shipped mission (its FMUs built and its scenario validated and kept
  beforehand, by one untimed run), against ``python -c "import numpy,
  fmpy"``, what any run of FMUs imports. Target: ratio <= 1.5 (a run of
  built FMUs builds no model and imports no Dask, matplotlib,
  python-control or pydantic: docs/cosim.md, "Start-up of a run").

and prints the medians and their ratios. ``--before TREE`` adds the same
run with another checkout's packages first on ``PYTHONPATH`` (e.g. a
detached worktree of ``main``: ``git worktree add --detach ../before main``),
alternated with the others, so a change is measured side by side on the
same machine in the same minutes. Tests check what is imported
(``tests/paper/test_cli.py``, ``tests/paper/test_run_startup.py``), this
script the clock. Run it with the bytecode cache on
(``PYTHONDONTWRITEBYTECODE`` unset), as users run.

    .venv/bin/python benchmarks/cli_startup.py [--repeats 9] [--before TREE]
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
    p.add_argument("--repeats", type=int, default=9)
    p.add_argument("--before", type=Path, default=None, metavar="TREE",
                   help="also time the run with this checkout's packages first on PYTHONPATH")
    args = p.parse_args(argv)
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        print("note: PYTHONDONTWRITEBYTECODE is set: a module with no bytecode cached yet is compiled in "
              "every process (PYTHONPYCACHEPREFIX=DIR keeps the bytecode out of the tree instead)")

    with tempfile.TemporaryDirectory(prefix="cli-startup-") as tmp:
        pairs = {  # label -> command: each command, then its reference
            "fnn-cosim --help": cli("--help"),
            'python -c "import numpy, casadi, fmpy"': [sys.executable, "-c", "import numpy, casadi, fmpy"],
            "fnn-cosim run circles --no-plots --quiet": cli("run", "circles", "--no-plots", "--quiet",
                                                             "--out", str(Path(tmp) / "run")),
            'python -c "import numpy, fmpy"': [sys.executable, "-c", "import numpy, fmpy"],
        }
        if args.before is not None:  # the same run, another tree's code: env puts it first on sys.path
            before = ["env", f"PYTHONPATH={args.before.resolve()}"]
            pairs[f"  the same, {args.before.name}"] = before + cli("run", "circles", "--no-plots", "--quiet",
                                                                    "--out", str(Path(tmp) / "before"))
        for command in pairs.values():  # builds the FMUs and keeps the validated scenario (first run), warms the file cache
            timed(command)
        times: dict[str, list[tuple[float, float]]] = {label: [] for label in pairs}
        for _ in range(args.repeats):
            for label, command in pairs.items():
                times[label].append(timed(command))

    wall = {label: statistics.median(w for w, _ in values) for label, values in times.items()}
    cpu = {label: statistics.median(c for _, c in values) for label, values in times.items()}
    print(f"start-up, median of {args.repeats} alternating runs (CPU: user + system, steadier on a busy machine):")
    print(f"  {'':45s} {'wall':>8s} {'CPU':>8s}")
    labels = list(pairs)
    for command, reference in (labels[0:2], labels[2:4]):
        for label in (command, reference):
            print(f"  {label:45s} {wall[label] * 1e3:5.0f} ms {cpu[label] * 1e3:5.0f} ms")
        print(f"  {'ratio':45s} {wall[command] / wall[reference]:8.2f} {cpu[command] / cpu[reference]:8.2f}"
              f"  (target <= 1.5)")
    if args.before is not None:
        label, reference = labels[4], labels[3]
        print(f"  {label:45s} {wall[label] * 1e3:5.0f} ms {cpu[label] * 1e3:5.0f} ms")
        print(f"  {'  its ratio':45s} {wall[label] / wall[reference]:8.2f} {cpu[label] / cpu[reference]:8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
