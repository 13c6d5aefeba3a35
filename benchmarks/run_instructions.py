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
from typing import Sequence

CHILD = "--child"
WARM_UP = 10


def _child(runs: int, counted: int, duration: float) -> None:
    """Fly the first run of each cell of the short study of ``runs`` runs
    (:func:`study_efficiency._short_study`: its scenario, its plan and
    draws) until ``WARM_UP`` runs have flown, then the first ``counted`` runs
    of its plan, each ``duration`` seconds long, with its lean record and
    metrics (as ``measure`` flies them)."""
    import itertools

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from study_efficiency import _short_study

    from cosim.scenario.definition import apply_overrides, parse_scenario
    from cosim.study.definition import cell_of, runs as plan_of
    from cosim.study.runner import MasterCache, execute
    from quadrotor_paper.experiments import lean_signals, study_metrics

    try:
        from cosim.study.runner import flown
    except ImportError:  # a tree from before runner.flown (--before): its runs one by one, as its studies flew them
        def flown(raw, source, runs, metrics, cache):
            return (execute(raw, source, run, metrics, cache) for run in runs)

    with tempfile.TemporaryDirectory() as folder:
        study = _short_study(runs, Path(folder))
    base = study.scenario
    base = parse_scenario(apply_overrides(base.raw, {"simulation.duration": duration,
                                                     "record.signals": lean_signals(base)}), source=base.source)
    plan = list(plan_of(study))
    first = {}
    for run in plan:
        first.setdefault(cell_of(study, run.index), run)
    warm_up = list(itertools.islice(itertools.cycle(first.values()), WARM_UP))  # every cell's master built
    cache = MasterCache()
    try:
        for record in flown(base.raw, str(base.source), warm_up + plan[:counted], study_metrics, cache):
            if record["status"] != "ok":
                raise SystemExit(f"run {record['key']}: {record['status']}: {record['error']}")
    finally:
        cache.close()


def _flown(tree: Path | None, runs: int, counted: int, duration: float, tool: Sequence[str] = ()):
    """A child process (:func:`_child`) with ``tree``'s packages first on
    ``PYTHONPATH``, run under ``tool``; its completed process."""
    env = dict(os.environ, PYTHONHASHSEED="0")
    if tree is not None:
        env["PYTHONPATH"] = str(tree.resolve())
    with tempfile.TemporaryDirectory() as cwd:  # not this checkout's folder: PYTHONPATH decides the packages
        done = subprocess.run([*tool, sys.executable, str(Path(__file__).resolve()), CHILD, str(runs), str(counted),
                               repr(duration)], cwd=cwd, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(tool) or 'the runs'}: exit {done.returncode}\n{done.stdout[-2000:]}\n"
                         f"{done.stderr[-2000:]}")
    return done


def _count(tree: Path | None, runs: int, counted: int, duration: float) -> int:
    """Instructions of a child flying ``counted`` runs after the warm-up (callgrind's ``I refs``)."""
    done = _flown(tree, runs, counted, duration, ("valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null"))
    found = re.search(r"I\s+refs:\s+([\d,]+)", done.stderr)
    if found is None:
        raise SystemExit(f"valgrind printed no count\n{done.stderr[-2000:]}")
    return int(found.group(1).replace(",", ""))


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == CHILD:
        return _child(int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]))
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=200, help="runs counted (default 200)")
    p.add_argument("--duration", type=float, default=0.01, help="a run's simulated seconds (default 0.01: one step)")
    p.add_argument("--before", type=Path, default=None, metavar="TREE", help="also count this checkout's packages")
    args = p.parse_args()
    if shutil.which("valgrind") is None:
        raise SystemExit("valgrind is not installed (Debian: apt-get install valgrind)")
    from cosim.executor import parallel

    trees = {"this tree": None, **({args.before.name: args.before} if args.before is not None else {})}
    for tree in trees.values():  # its FMUs built and its scenarios kept before anything is counted
        _flown(tree, args.runs, 0, args.duration)
    jobs = [(tag, n) for tag in trees for n in (0, args.runs)]
    with parallel("threads", 2, name="valgrind") as executor:  # each job is a process; a thread waits for it
        counts = dict(zip(jobs, executor.map(lambda job: _count(trees[job[0]], args.runs, job[1], args.duration),
                                             jobs)))
    print(f"instructions a run ({args.runs} runs of the short study's circles, {args.duration:g} s each, after "
          f"{WARM_UP} warm-up runs; callgrind):")
    for tag in trees:
        per_run = (counts[(tag, args.runs)] - counts[(tag, 0)]) / args.runs
        print(f"  {tag:20s} {per_run / 1e6:8.2f} million")


if __name__ == "__main__":
    main()
