"""A study's run's own cost in instructions (valgrind's callgrind): a figure the machine's speed does not move.

On a shared machine the time of the same work moves by half from one
minute to the next (``docs/cosim.md``, "Many short runs on threads"); the
number of instructions it executes does not. This script counts them for
the runs of the short study of ``benchmarks/study_efficiency.py`` (the
circles, the plant's mass and the wind drawn, both variants), each on the
path a study flies it (:func:`cosim.study.runner.flown`: its scenario, a
master from the cache, the FMUs started, the compiled loop, the metrics),
as the difference between a process that flies ``--runs`` runs after ten
warm-up runs and one that flies the warm-up only, so imports, builds and
the first runs cancel out. With ``--duration 0.01`` (one step) a run is
almost only its Python and its FMUs' start; the loop adds about 7
million instructions a simulated second.

``--before TREE`` counts the same with another checkout's packages first
on ``PYTHONPATH`` (e.g. a worktree of an older commit); the processes run
side by side (their counts do not depend on it). Printed, never asserted.
The instructions of one process's start vary by about 2 % between two
processes (40 million): 200 runs put that under 0.2 million a run.

    .venv/bin/python benchmarks/run_instructions.py [--runs 200] [--duration 0.01] [--before TREE]
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = "--child"
WARM_UP = 10


def _child(runs: int, duration: float) -> None:
    """Fly ``WARM_UP`` runs, then ``runs`` more, of the short study's cells (its scenario, its draws)."""
    import random

    from cosim.scenario.definition import apply_overrides, load_scenario, parse_scenario
    from cosim.study.definition import Run
    from cosim.study.runner import MasterCache, execute
    from quadrotor_paper.experiments import lean_signals, study_metrics

    try:
        from cosim.study.runner import flown
    except ImportError:  # a tree from before runner.flown (--before): its runs one by one, as its studies flew them
        def flown(raw, source, runs, metrics, cache):
            return (execute(raw, source, run, metrics, cache) for run in runs)

    base = load_scenario("circles", {"simulation.duration": duration, "controller.plant": ""})
    base = parse_scenario(apply_overrides(base.raw, {"record.signals": lean_signals(base)}), source=base.source)
    draw = random.Random(0)

    def run(i: int) -> Run:
        return Run(i, None, (), 0, 0, {}, {"controller.variant": ("pd", "pd+lm")[i % 2],
                                           "fmus.Quadrotor.parameters.m": draw.uniform(0.856, 1.284),
                                           "wind.speed": draw.uniform(0.0, 5.0)})

    cache = MasterCache()
    try:
        for record in flown(base.raw, str(base.source), map(run, range(WARM_UP + runs)), study_metrics, cache):
            if record["status"] != "ok":
                raise SystemExit(f"run {record['key']}: {record['status']}: {record['error']}")
    finally:
        cache.close()


def _count(tree: Path | None, runs: int, duration: float, valgrind: bool = True) -> int:
    """Instructions of a child process flying ``runs`` runs after the
    warm-up (callgrind's ``I refs``); without ``valgrind``, the same child
    flown plainly (its FMUs built, its scenarios kept, before any count),
    and 0."""
    env = dict(os.environ, PYTHONHASHSEED="0")
    if tree is not None:
        env["PYTHONPATH"] = str(tree.resolve())
    tool = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null"] if valgrind else []
    with tempfile.TemporaryDirectory() as cwd:  # not this checkout's folder: PYTHONPATH decides the packages
        out = subprocess.run([*tool, sys.executable, str(Path(__file__).resolve()), CHILD, str(runs), repr(duration)],
                             cwd=cwd, env=env, capture_output=True, text=True)
    if not valgrind:
        if out.returncode != 0:
            raise SystemExit(f"the runs failed: exit {out.returncode}\n{out.stderr[-2000:]}")
        return 0
    found = re.search(r"I\s+refs:\s+([\d,]+)", out.stderr)
    if out.returncode != 0 or found is None:
        raise SystemExit(f"valgrind: exit {out.returncode}\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}")
    return int(found.group(1).replace(",", ""))


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == CHILD:
        return _child(int(sys.argv[2]), float(sys.argv[3]))
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=200, help="runs counted (default 200)")
    p.add_argument("--duration", type=float, default=0.01, help="a run's simulated seconds (default 0.01: one step)")
    p.add_argument("--before", type=Path, default=None, metavar="TREE", help="also count this checkout's packages")
    args = p.parse_args()
    if shutil.which("valgrind") is None:
        raise SystemExit("valgrind is not installed (Debian: apt-get install valgrind)")
    from cosim.executor import parallel

    trees = {"this tree": None, **({args.before.name: args.before} if args.before is not None else {})}
    for tree in trees.values():
        _count(tree, 0, args.duration, valgrind=False)
    jobs = [(tag, n) for tag in trees for n in (0, args.runs)]
    with parallel("threads", 2, name="valgrind") as executor:  # each job is a process; a thread waits for it
        counts = dict(zip(jobs, executor.map(lambda job: _count(trees[job[0]], job[1], args.duration), jobs)))
    print(f"instructions a run ({args.runs} runs of the short study's circles, {args.duration:g} s each, after "
          f"{WARM_UP} warm-up runs; callgrind):")
    for tag in trees:
        per_run = (counts[(tag, args.runs)] - counts[(tag, 0)]) / args.runs
        print(f"  {tag:20s} {per_run / 1e6:8.2f} million")


if __name__ == "__main__":
    main()
