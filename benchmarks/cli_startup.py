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

``--phases`` prints instead where the run's time goes, medians over
``--repeats`` fresh processes of ``fnn-cosim run circles --no-plots
--quiet`` (the main thread's CPU, steadier on a busy machine, and wall
time): the interpreter's start and the imports (numpy, fmpy, ours: those
the phases' functions live in are imported before ``main`` to be timed),
then ``main``: the command's own parser, the scenario read, the master's
build (the FMU components and their instances), the run (its compiled loop,
and the results file written as it goes), the summary, and the process's
end. The phases are timed by wrapping those functions in the child process;
with ``--before TREE`` the same for that tree.

    .venv/bin/python benchmarks/cli_startup.py [--repeats 9] [--before TREE] [--phases]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from processes import cli, timed

# (label, module, attribute path): a phase of the run, timed around that function in the child process
PHASES = (("parser", "quadrotor_paper.cli", "_parser"),
          ("scenario read", "cosim.scenario.definition", "load_scenario"),
          ("master built", "cosim.scenario.assembly", "build_master"),
          ("  its FMU components (descriptions)", "cosim.fmi.fmu", "FmuComponent.__init__"),
          ("  their instances (library, fmiInstantiate)", "cosim.fmi.fmu", "FmuComponent.instantiate"),
          ("run", "cosim.loop.master", "Master.run"),
          ("  results.csv written", "cosim.loop.recorder", "Recorder.flush"),
          ("summary written", "cosim.files", "write_json"))

# the child: the phases' functions wrapped (an inner call of the same function counted once), then fnn-cosim's
# own main(), whose end (cli._end) prints nothing more: the times go out from an exit handler
_CHILD = r"""
import atexit, importlib, json, sys, time
start_cpu, start = time.thread_time(), time.perf_counter()
sys.path[0] = sys.argv.pop(1)  # the fnn-cosim script's folder, as for the script
phases, out = json.loads(sys.argv.pop(1)), {}
from quadrotor_paper.cli import main
def wrapped(label, f):
    def timed(*args, **kwargs):
        if label in active:
            return f(*args, **kwargs)
        active.add(label)
        c, t = time.thread_time(), time.perf_counter()
        try:
            return f(*args, **kwargs)
        finally:
            active.discard(label)
            spent = out.setdefault(label, [0.0, 0.0])
            spent[0] += time.thread_time() - c
            spent[1] += time.perf_counter() - t
    return timed
active = set()
for label, module, path in phases:
    owner = importlib.import_module(module)
    *outer, name = path.split(".")
    for part in outer:
        owner = getattr(owner, part)
    setattr(owner, name, wrapped(label, getattr(owner, name)))
out["imports (numpy, fmpy, ours)"] = [time.thread_time() - start_cpu, time.perf_counter() - start]
def told():
    out["main"] = [time.thread_time() - main_cpu, time.perf_counter() - main_wall]
    sys.stderr.write("PHASES " + json.dumps({**out, "ended": time.clock_gettime(time.CLOCK_MONOTONIC)}) + "\n")
atexit.register(told)
sys.argv = ["fnn-cosim", *sys.argv[1:]]
main_cpu, main_wall = time.thread_time(), time.perf_counter()
main()
"""


def phases(repeats: int, trees: dict[str, str | None], out: Path) -> None:
    """Print where ``fnn-cosim run circles --no-plots --quiet``'s time goes (see the module's doc)."""
    script = Path(cli()[0]).parent if Path(cli()[0]).name == "fnn-cosim" else Path(__file__).parent
    args = ["run", "circles", "--no-plots", "--quiet", "--out", str(out)]
    found: dict[str, dict[str, list[tuple[float, float]]]] = {name: {} for name in trees}
    for _ in range(repeats + 1):  # the first round builds, keeps and warms what the runs read
        for name, tree in trees.items():
            env = {**os.environ, "PYTHONPATH": tree} if tree else None
            started = _monotonic()
            proc = subprocess.run([sys.executable, "-c", _CHILD, str(script), json.dumps(PHASES), *args],
                                  capture_output=True, text=True, env=env)
            ended = _monotonic()
            line = [x for x in proc.stderr.splitlines() if x.startswith("PHASES ")]
            if proc.returncode or not line:
                raise SystemExit(f"{name}: the run failed ({proc.returncode}): {proc.stderr[-2000:]}")
            told = json.loads(line[-1].removeprefix("PHASES "))
            told["process end"] = [0.0, ended - told.pop("ended")]
            told["whole process"] = [0.0, ended - started]
            for label, (cpu, wall) in told.items():
                found[name].setdefault(label, []).append((cpu, wall))
    found = {name: {label: values[1:] for label, values in times.items()} for name, times in found.items()}
    labels = ["whole process", "imports (numpy, fmpy, ours)", "main", *(label for label, _, _ in PHASES),
              "process end"]
    print(f"where fnn-cosim run circles --no-plots --quiet spends its time, median of {repeats} processes "
          f"(CPU: the main thread's; ms):")
    print(f"  {'':45s}" + "".join(f" {name[-18:]:>18s}" for name in trees))
    print(f"  {'':45s}" + "".join(f" {'CPU':>8s} {'wall':>9s}" for _ in trees))
    for label in labels:
        cells = []
        for name in trees:
            values = found[name].get(label)
            if not values:
                cells.append(f" {'-':>8s} {'-':>9s}")
                continue
            cpu, wall = statistics.median(c for c, _ in values), statistics.median(w for _, w in values)
            cells.append(f" {cpu * 1e3:8.1f} {wall * 1e3:9.1f}" if cpu else f" {'':8s} {wall * 1e3:9.1f}")
        print(f"  {label:45s}" + "".join(cells))


def _monotonic() -> float:
    import time

    return time.clock_gettime(time.CLOCK_MONOTONIC)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=9)
    p.add_argument("--before", type=Path, default=None, metavar="TREE",
                   help="also time the run with this checkout's packages first on PYTHONPATH")
    p.add_argument("--phases", action="store_true", help="where the run's time goes instead (see above)")
    args = p.parse_args(argv)
    if args.phases:
        trees = {"this tree": os.environ.get("PYTHONPATH")}
        if args.before is not None:
            trees[args.before.name] = str(args.before.resolve())
        with tempfile.TemporaryDirectory(prefix="cli-startup-") as tmp:
            phases(args.repeats, trees, Path(tmp) / "run")
        return 0
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
