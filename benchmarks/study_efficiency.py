"""A study at the loop's cost: Table 2's and many short runs' wall time against the ideal, measured in one run.

Prints, for Table 2 (the shipped study ``table2``: 186 runs of the 50 s
circles, every variant and option row at 1, 3 and 5 m/s):

* **one run's loop time** ``L``: a run as the compiled kernel flies it in a
  study, alone in this process: ``Master.run`` of the run's master, built
  and warmed beforehand (it starts the FMUs -- reset, parameters,
  initialization -- and flies the 5000 steps in the compiled loop, as the
  study's rows' ``wall_time_s`` and ``benchmarks/loop_speed.py`` time a
  run; the scenario, the master's build and the row are not in it). One
  **round** flies each of Table 2's 27 cells (case and wind speed) once,
  on the same path as a study's run (:func:`cosim.study.runner.execute`),
  and weighs each cell by its runs: the round's ``L`` is the mean loop time
  of Table 2's runs. Rounds run before the first study, between the
  repeats and after the last, interleaved with what they are compared
  with; ``L`` is their median, printed with every round (its spread is the
  machine's: one sample of ``L`` moved by 50 % between invocations);
* **the overhead per run** in this process, (wall - sum of the runs' times)
  / runs, and as a share of ``L``: what a run costs besides its loop (its
  scenario, its master when it needs a new one, its metrics, its row, the
  summary), the study flown with ``--workers 1`` (no Dask);
* **Table 2 on Dask** (``measure``, its start and stop included) on
  ``--workers`` threads of this process (Dask's threaded scheduler, no
  cluster: what ``measure`` chooses for the project's own FMUs,
  :func:`quadrotor_paper.experiments.threads_safe`) and on a LocalCluster
  of ``--workers`` worker processes (what any other study gets; skipped
  with ``--no-processes``), and the whole command ``fnn-cosim table2
  --workers N`` (a new process: imports included), each against the ideal,
  ``runs x L / workers``: target ``fnn-cosim table2`` <= 1.6x on 2 workers;
  and the Dask overhead per run, (workers x wall - sum of the runs' times)
  / runs, as a share of ``L``. ``--before TREE`` times the command with
  another checkout's packages first on ``PYTHONPATH`` too (e.g. a detached
  worktree of ``main``), alternated with this tree's (each first in
  turn), against the same ``L``;
* **CPU time** beside each wall time (this process's, and its child
  processes' polled every 20 ms: worker processes; the command's own,
  exact, from ``wait4``): on a machine others load, wall time measures the
  load, CPU time what a study costs; the in-process study's CPU is the
  reference (no Dask, one core, every master built once);
* ``--phases``: where the command's time goes, from a run of it with its
  phases timed inside (``--phases-child``): the process's start and
  imports, the study's validation, the first run's start, the runs (the
  masters built, the CPU in the compiled loop and in Python around it, a
  run's ``Master.run`` on the workers' threads against ``L``), the last
  run's end, the masters freed (wall and CPU), the files and the exit; and the wall time above the ideal
  split into the start, the runs and the end;
* whether the compiled loop leaves the GIL free: a Python counter in
  this thread while another thread flies runs of one kernel call each;
* **short runs** (``--short-runs N``, default 10 000; 0: none): a study
  written by this script into a temporary folder (:data:`SHORT_STUDY`:
  the circles cut to 10 s, two variants x N/2 draws of the plant's mass
  and the wind speed), flown by ``measure`` on ``--workers`` threads (what
  it chooses for the project's FMUs), wall and CPU against its ideal
  ``runs x L / workers`` (``L`` its runs' mean loop time, rounds as
  above): target <= 1.3x on 2 workers, printed beside Table 2's figure
  (<= 1.1x); and the wall time against the runs' own loop times (their
  ``Master.run`` in the study, summed, / workers), the same ratio with the
  loop timed during the study itself: on a machine whose speed changes
  from minute to minute (one invocation's rounds of ``L`` went from 17 to
  10 ms), the rounds' ``L`` may be another machine's than the study's,
  this figure is not (Table 2's counterpart: its ``efficiency``, the
  inverse). ``--short-only`` runs that study alone (no Table 2);
  ``--cluster`` also flies it on a Dask cluster started by address (``dask
  scheduler`` and ``--workers`` ``dask worker tcp://...`` processes of one
  thread each, given to ``measure`` as ``scheduler``) and says whether its
  summary is the threads' one;
* the driver's peak Python memory (tracemalloc) for a study of 200 and of
  800 one-second runs: the rows are streamed to runs.csv, not held, and the
  local scheduler's logs are kept short (cosim/study/runner.py), so the ratio
  should stay near 1 (with Dask's default logs it was 2.3 for 50 -> 200 runs).

Printed, never asserted: a slow or busy machine changes the figures, not
the verdict of the test suite. On a shared machine, repeat (``--repeats``):
the Dask figures are the median of the repeats. Run it with the bytecode
cache on (``PYTHONDONTWRITEBYTECODE`` unset), as users run.

    .venv/bin/python benchmarks/study_efficiency.py [--workers 2] [--repeats 1] [--no-memory] [--no-processes]
        [--phases] [--before TREE] [--short-runs N] [--short-only] [--cluster] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
from pathlib import Path
from typing import Any


def _table2():
    from quadrotor_paper.report import table_study

    return table_study(2)


SHORT_STUDY = """# benchmarks/study_efficiency.py: many short runs (a Monte Carlo over the vehicle's mass and the wind)
scenario = "circles"
name = "short_runs"
description = "The circles cut to 10 s: two variants x {samples} draws of the plant's mass and the wind speed"

[set]
"simulation.duration" = 10.0
"controller.plant" = ""   # the controller keeps its nominal (Table 1) vehicle: the drawn mass is a mismatch

[sweep.grid]
"controller.variant" = ["pd", "pd+lm"]

[sweep.random]
samples = {samples}
seed = 0
"fmus.Quadrotor.parameters.m" = {{ uniform = [0.856, 1.284] }}
"wind.speed" = {{ uniform = [0.0, 5.0] }}
"""


def _short_study(runs: int, folder: Path):
    """The study of ``runs`` short runs (:data:`SHORT_STUDY`), written as a study file into ``folder`` and read."""
    from cosim.study.definition import load_study

    path = folder / "short_runs.toml"
    path.write_text(SHORT_STUDY.format(samples=max(1, runs // 2)), encoding="utf-8")
    return load_study(path)


def _memory_study(seeds: int):
    from cosim.scenario.definition import scenario_path
    from cosim.study.definition import parse_study
    from fnn_controller.variants import variant_names

    raw = {"scenario": str(scenario_path("circles")), "name": "efficiency", "set": {"simulation.duration": 1.0},
           "sweep": {"seeds": seeds, "grid": {"controller.variant": list(variant_names()), "wind.speed": [1.0]}}}
    return parse_study(raw)


class _Cpu:
    """CPU time (s, user + system) of a process and its descendants while
    it runs: the process's own ``process_time`` when it is this one, else
    polled; descendants polled every ``every`` s (the last reading of each
    counts: a process's last ``every`` s may be missed)."""

    def __init__(self, pid: int | None = None, every: float = 0.02):
        import psutil

        self.root = psutil.Process(pid)
        self.own = pid is None
        self.every, self.seen, self.stop = every, {}, threading.Event()
        self.thread = threading.Thread(target=self._poll, daemon=True)

    def _poll(self) -> None:
        import psutil

        while not self.stop.is_set():
            try:
                procs = ([] if self.own else [self.root]) + self.root.children(recursive=True)
            except psutil.Error:
                procs = []
            for proc in procs:
                try:
                    t = proc.cpu_times()
                    self.seen[proc.pid] = t.user + t.system
                except psutil.Error:
                    pass
            self.stop.wait(self.every)

    def __enter__(self):
        self.start = time.process_time()
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join()
        self.cpu = sum(self.seen.values()) + (time.process_time() - self.start if self.own else 0.0)


def _run(study, out: Path, workers: int, threads: bool | None = None) -> tuple[float, float, list[float]]:
    """Wall and CPU time of ``measure`` (s; ``threads`` forces the local
    cluster's kind) and the runs' own times."""
    from cosim.study.run import read_runs
    from quadrotor_paper import experiments

    chosen = experiments.threads_safe
    if threads is not None:
        experiments.threads_safe = lambda *args, **kwargs: threads
    try:
        with _Cpu() as cpu:
            t = time.perf_counter()
            experiments.measure(study, out, workers=workers)
            wall = time.perf_counter() - t
    finally:
        experiments.threads_safe = chosen
    return wall, cpu.cpu, [float(r["wall_time_s"]) for r in read_runs(out / "runs.csv") if r["wall_time_s"]]


def _command(out: Path, workers: int, tree: Path | None = None) -> tuple[float, float]:
    """Wall and CPU time (s) of ``fnn-cosim table2`` in a new process (``tree``: that checkout's packages first)."""
    from processes import measured

    env = ["env", f"PYTHONPATH={tree.resolve()}"] if tree is not None else []
    wall, cpu, _ = measured(env + [sys.executable, "-m", "quadrotor_paper.cli", "table2", "--out", str(out),
                                   "--quiet", "--workers", str(workers)])
    return wall, cpu


ROUND_S = 0.5  # s a round of L lasts at least: a round of a few short runs is one sample of the machine's noise


class _Loops:
    """Rounds of ``L``: each of the study's cells (case and grid point) flown
    on a master built and warmed beforehand, on a study's run path
    (:func:`cosim.study.runner.execute`: the lean record, the metrics taken
    as the rows stream), as many times each as make a round last about
    :data:`ROUND_S` (once each for Table 2's 27 cells of 50 s runs; about
    15 times each for the short study's 2 cells of 10 s runs, whose round
    of one run a cell moved by 25 % between rounds); a round's ``L`` is the
    cells' mean ``Master.run`` times weighed by their runs (the mean loop
    time of the study's runs)."""

    def __init__(self, study):
        from cosim.study.runner import MasterCache, execute
        from cosim.scenario.definition import apply_overrides, parse_scenario
        from cosim.study.definition import cell_of, cells, runs
        from quadrotor_paper.experiments import lean_signals, study_metrics

        base = study.scenario
        base = parse_scenario(apply_overrides(base.raw, {"record.signals": lean_signals(base)}), source=base.source)
        self.raw, self.source, self.metrics = base.raw, str(base.source), study_metrics
        self.execute = execute
        self.first, self.weights = {}, [0] * len(cells(study))
        for run in runs(study):
            cell = cell_of(study, run.index)
            self.first.setdefault(cell, run)
            self.weights[cell] += 1
        self.cache = MasterCache(size=len(self.first) + 1, scenarios=len(self.first) + 1)
        self.rounds: list[float] = []
        self.repeat = 1
        self._round(keep=False)  # builds every master, loads every library
        started = time.perf_counter()
        self._round(keep=False)
        self.repeat = max(1, math.ceil(ROUND_S / (time.perf_counter() - started)))

    def _round(self, keep: bool = True) -> float:
        times = {}
        for cell, run in self.first.items():
            flown = []
            for _ in range(self.repeat):
                rec = self.execute(self.raw, self.source, run, self.metrics, self.cache)
                if rec["status"] != "ok":
                    raise SystemExit(f"L: run {run.index} {rec['status']}: {rec['error']}")
                flown.append(rec["wall_time_s"])
            times[cell] = statistics.fmean(flown)
        value = sum(self.weights[c] * t for c, t in times.items()) / sum(self.weights)
        if keep:
            self.rounds.append(value)
        return value

    def sample(self) -> None:
        self._round()

    def close(self) -> None:
        self.cache.close()


def _gil_free(runs: int = 5) -> tuple[float, float]:
    """Whether another thread runs Python while a run's compiled loop runs:
    counts per second of a Python counter in this thread while another
    thread flies ``runs`` circles missions, each one kernel call (a block
    of every row), and while it runs a Python loop (which shares the GIL at
    the switch interval). A call that held the GIL would stop the counter
    for each whole run."""
    from cosim.scenario.assembly import build_master
    from cosim.scenario.definition import load_scenario

    scenario = load_scenario("circles")
    master = build_master(scenario)

    def fly() -> None:
        for _ in range(runs):
            master.run(scenario.duration, seed=0, keep=0, block_rows=10 ** 9)

    def spin() -> None:
        x = 0
        for _ in range(3_000_000):
            x += 1

    def counts(target) -> float:
        done, n = threading.Event(), 0
        thread = threading.Thread(target=lambda: (target(), done.set()))
        t = time.perf_counter()
        thread.start()
        while not done.is_set():
            n += 1
        thread.join()
        return n / (time.perf_counter() - t)

    try:
        fly()  # loaded
        return counts(fly), counts(spin)
    finally:
        master.close()


def _short_runs(runs: int, workers: int, tmp: Path) -> dict[str, float]:
    """The study of ``runs`` short runs (:data:`SHORT_STUDY`) as ``measure``
    flies it on ``workers`` (threads: the project's FMUs), against its
    ideal, ``runs x L / workers``, ``L`` its runs' mean loop time
    (:class:`_Loops`: rounds before and after, their median)."""
    study = _short_study(runs, tmp)
    loops = _Loops(study)
    try:
        loops.sample()
        wall, cpu, times = _run(study, tmp / "short", workers)
        loops.sample()
        loops.sample()
    finally:
        loops.close()
    loop = statistics.median(loops.rounds)
    from cosim.study.definition import count

    n = count(study)
    ideal = n * loop / workers
    return {"runs": n, "loop_s": loop, "loop_rounds_s": loops.rounds, "loop_round_runs": loops.repeat * len(loops.first),
            "wall_s": wall, "cpu_s": cpu,
            "ideal_s": ideal, "wall_over_ideal": wall / ideal, "cpu_over_runs_x_loop": cpu / (n * loop),
            "sum_of_run_times_s": sum(times), "rows": len(times),
            "wall_over_own_loops": wall * workers / sum(times)}


def _on_a_cluster(runs: int, workers: int, tmp: Path) -> dict[str, Any]:
    """The short study on a Dask cluster started by address: ``dask
    scheduler`` and ``workers`` ``dask worker tcp://...`` processes of one
    thread each, given to ``measure`` as ``scheduler``; its summary's cells
    against those of the same study flown on threads here (``_short_runs``'s)."""
    from quadrotor_paper import experiments

    study = _short_study(runs, tmp)
    dask = str(Path(sys.executable).with_name("dask"))
    info = tmp / "scheduler.json"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    started = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                 "--scheduler-file", str(info)], **quiet)]
    try:
        deadline = time.monotonic() + 60
        while not info.exists() or not info.stat().st_size:
            if time.monotonic() > deadline or started[0].poll() is not None:
                raise SystemExit("--cluster: the Dask scheduler did not start")
            time.sleep(0.1)
        time.sleep(0.2)  # the file is written at once, not atomically
        address = json.loads(info.read_text())["address"]
        started += [subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--no-nanny",
                                      "--no-dashboard"], **quiet) for _ in range(workers)]
        from dask.distributed import Client

        with Client(address, timeout=60) as client:  # the study starts on a cluster with its workers
            client.wait_for_workers(workers, timeout=60)
        with _Cpu() as cpu:
            t = time.perf_counter()
            there = experiments.measure(study, tmp / "cluster", scheduler=address)
            wall = time.perf_counter() - t
    finally:
        for process in reversed(started):
            process.terminate()
        for process in started:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
    here = json.loads((tmp / "short" / "summary.json").read_text())
    return {"address": address, "wall_s": wall, "cpu_s": cpu.cpu, "counts": there.counts,
            "same_summary": here["cells"] == there.summary["cells"]}


def _driver_peak_bytes(study, out: Path, workers: int) -> int:
    tracemalloc.start()
    try:
        _run(study, out, workers)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


PHASES_CHILD = "--phases-child"  # this script run as the command, its phases timed: --phases-child OUT.json ARGS...


def _phases_child(out: str, argv: list[str]) -> int:
    """Run ``fnn-cosim ARGV`` in this process with its phases timed; write
    them to ``out`` (JSON) when the process exits. Functions are wrapped by
    name where they exist, so another checkout's tree is timed alike."""
    import atexit

    events: list[tuple] = []  # (time.time(), thread, what, wall s, CPU s)
    kernel_cpu: dict[str, float] = {}  # thread -> CPU s in the compiled loop's calls
    ended: dict[str, float] = {}  # thread -> its CPU s when it ended

    def note(what: str, wall: float = 0.0, cpu: float = 0.0, at: float | None = None) -> None:
        events.append((time.time() if at is None else at, threading.current_thread().name, what, wall, cpu))

    note("interpreter started")
    from quadrotor_paper import cli

    note("imports done")
    import cosim.study.runner as runner
    import cosim.loop.kernel as kernel
    import cosim.study.run as study_run
    import quadrotor_paper.report as report

    def timed(owner, name: str, what: str) -> None:
        f = getattr(owner, name, None)
        if f is None:
            return

        def wrapper(*args, **kwargs):
            at, c = time.time(), time.thread_time()
            try:
                return f(*args, **kwargs)
            finally:
                note(what, time.time() - at, time.thread_time() - c, at)
        setattr(owner, name, wrapper)

    timed(report, "table_study", "validation")
    timed(runner, "execute", "run")
    timed(runner, "build_master", "build")
    timed(runner.MasterCache, "close", "cache closed")
    timed(study_run, "summary_of", "summary")
    timed(study_run, "write_parquet", "parquet")
    loop = kernel.load()
    if loop is not None:
        def counted(*args):
            c = time.thread_time()
            try:
                return loop(*args)
            finally:
                name = threading.current_thread().name
                kernel_cpu[name] = kernel_cpu.get(name, 0.0) + time.thread_time() - c
        kernel.load = lambda: counted

    run_thread = threading.Thread.run

    def run(self):
        try:
            run_thread(self)
        finally:
            ended[self.name] = time.thread_time()
    threading.Thread.run = run

    def dump() -> None:
        note("exit")
        ended["MainThread"] = time.thread_time()
        total = sum(os.times()[:2])
        Path(out).write_text(json.dumps({"events": events, "kernel_cpu": kernel_cpu, "ended": ended,
                                         "process_cpu": total}))
    atexit.register(dump)
    code = cli.main(argv)
    note("main returned")
    return code


def _phases(workers: int, tmp: Path, tree: Path | None, tag: str) -> dict[str, float]:
    """One ``fnn-cosim table2`` with its phases timed: seconds from its start."""
    out = tmp / f"phases-{tag}.json"
    env = ["env", f"PYTHONPATH={tree.resolve()}"] if tree is not None else []
    started = time.time()
    subprocess.run(env + [sys.executable, str(Path(__file__).resolve()), PHASES_CHILD, str(out), "table2", "--out",
                          str(tmp / f"phases-{tag}"), "--quiet", "--workers", str(workers)],
                   check=True, stdout=subprocess.DEVNULL)
    ends = time.time() - started
    got = json.loads(out.read_text())
    events = [(at - started, thread, what, wall, cpu) for at, thread, what, wall, cpu in got["events"]]
    first = {}
    for at, _, what, _, _ in events:
        first.setdefault(what, at)
    runs = [e for e in events if e[2] == "run"]
    builds = [e for e in events if e[2] == "build"]
    workers_cpu = {t: c for t, c in got["ended"].items() if t.startswith("cosim-run")}
    runs_cpu = sum(e[4] for e in runs)
    in_loop = sum(c for t, c in got["kernel_cpu"].items() if t.startswith("cosim-run"))
    validation = next((e for e in events if e[2] == "validation"), None)
    closed = [e for e in events if e[2] == "cache closed"]
    return {
        "imports_done_s": first["imports done"],
        "validated_s": validation[0] + validation[3] if validation else float("nan"),
        "first_run_s": runs[0][0], "last_run_end_s": max(at + wall for at, _, _, wall, _ in runs),
        "main_returned_s": first["main returned"], "process_end_s": ends,
        "close_wall_s": sum(e[3] for e in closed), "close_cpu_s": sum(e[4] for e in closed),
        "runs": len(runs), "builds": len(builds), "builds_cpu_s": sum(e[4] for e in builds),
        "run_mean_ms": statistics.mean(e[3] for e in runs) * 1e3,
        "runs_cpu_s": runs_cpu, "in_loop_cpu_s": in_loop, "around_loop_cpu_s": runs_cpu - in_loop,
        "main_cpu_s": got["ended"].get("MainThread", float("nan")), "worker_threads_cpu_s": sum(workers_cpu.values()),
        "other_threads_cpu_s": sum(c for t, c in got["ended"].items()
                                   if t != "MainThread" and not t.startswith("cosim-run")),
        "process_cpu_s": got["process_cpu"],
    }


_PHASE_LINES = (  # key, label, how it is shown
    ("imports_done_s", "imports done (interpreter, fnn-cosim's modules)", "{:8.2f} s"),
    ("validated_s", "the study read and validated", "{:8.2f} s"),
    ("first_run_s", "first run starts", "{:8.2f} s"),
    ("last_run_end_s", "last run ends", "{:8.2f} s"),
    ("main_returned_s", "files written, table printed", "{:8.2f} s"),
    ("process_end_s", "process ends", "{:8.2f} s"),
    ("close_wall_s", "the masters freed after the last run (MasterCache.close): wall", "{:8.3f} s"),
    ("close_cpu_s", "  its CPU", "{:8.3f} s"),
    ("builds", "masters built", "{:8.0f}  "),
    ("builds_cpu_s", "  their CPU (in the runs' threads)", "{:8.2f} s"),
    ("run_mean_ms", "a run's time on the threads (execute: scenario, master, Master.run, metrics)", "{:8.1f} ms"),
    ("runs_cpu_s", "CPU of the runs (execute, builds included)", "{:8.2f} s"),
    ("in_loop_cpu_s", "  in the compiled loop's calls", "{:8.2f} s"),
    ("around_loop_cpu_s", "  in Python around them (per run: /runs)", "{:8.2f} s"),
    ("main_cpu_s", "CPU: main thread", "{:8.2f} s"),
    ("worker_threads_cpu_s", "CPU: the run threads", "{:8.2f} s"),
    ("other_threads_cpu_s", "CPU: other threads (Dask's driver, imports ahead)", "{:8.2f} s"),
    ("process_cpu_s", "CPU: the whole process", "{:8.2f} s"),
)


def _print_phases(phases: dict[str, list[dict[str, float]]], ideal: float, loop: float) -> None:
    med = statistics.median
    kinds = list(phases)
    n = len(next(iter(phases.values())))
    print(f"where fnn-cosim table2's time goes (medians of {n}; s from the process's start)"
          + "".join(f"{k:>14s}" for k in kinds))
    for key, label, fmt in _PHASE_LINES:
        print(f"  {label:78s}" + "".join(f"{fmt.format(med(p[key] for p in phases[k])):>14s}" for k in kinds))
    print(f"  {'a run on the threads / L':78s}"
          + "".join(f"{med(p['run_mean_ms'] for p in phases[k]) / (loop * 1e3):12.2f} x" for k in kinds))
    print(f"  above the ideal ({ideal:.2f} s):")
    for k in kinds:
        start = med(p["first_run_s"] for p in phases[k])
        runs = med(p["last_run_end_s"] - p["first_run_s"] for p in phases[k])
        end = med(p["process_end_s"] - p["last_run_end_s"] for p in phases[k])
        print(f"    {k}: before the first run {start:.2f} s + the runs {runs:.2f} s (ideal {ideal:.2f}: "
              f"{runs - ideal:+.2f} s) + after the last {end:.2f} s = {start + runs + end - ideal:+.2f} s")


def _short_and_cluster(args, tmp: Path) -> dict[str, Any]:
    short = _short_runs(args.short_runs, args.workers, tmp)
    if args.cluster:
        short["cluster"] = _on_a_cluster(args.short_runs, args.workers, tmp)
    return short


def _short_only(args) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        short = _short_and_cluster(args, Path(tmp))
    _print_short(short, args.workers, None)
    return short


def _print_short(short: dict[str, Any], workers: int, table2: float | None) -> None:
    n, loop = short["runs"], short["loop_s"]
    print(f"short runs: {n} runs of the circles cut to 10 s (2 variants x random mass and wind), on {workers} threads")
    print(f"  one run's loop time L (median of {len(short['loop_rounds_s'])} rounds of {short['loop_round_runs']} runs: "
          f"{', '.join(f'{r * 1e3:.1f}' for r in short['loop_rounds_s'])} ms)  {loop * 1e3:6.2f} ms")
    print(f"  wall {short['wall_s']:8.2f} s, ideal (runs x L / workers) {short['ideal_s']:7.2f} s: "
          f"{short['wall_over_ideal']:5.2f} x ideal (target <= 1.3)"
          + (f";  Table 2 above: {table2:.2f} x ideal (must stay <= 1.1)" if table2 is not None else ""))
    print(f"  CPU  {short['cpu_s']:8.2f} s = {short['cpu_s'] / n * 1e3:.2f} ms a run = "
          f"{short['cpu_over_runs_x_loop']:.2f} x runs x L;  rows {short['rows']}, their runs' times sum to "
          f"{short['sum_of_run_times_s']:.2f} s")
    print(f"  wall against the runs' own loop times (their Master.run in the study, summed / workers: timed with "
          f"the study, so a change of the machine's speed between L's rounds and the study does not move it): "
          f"{short['wall_over_own_loops']:.2f} x")
    cluster = short.get("cluster")
    if cluster is not None:
        print(f"  on a Dask cluster by address ({cluster['address']}, {workers} worker processes started by "
              f"`dask worker`): wall {cluster['wall_s']:.2f} s, CPU {cluster['cpu_s']:.2f} s (this process, the "
              f"scheduler and the workers), "
              f"{cluster['counts']}; the same summary as on threads: {cluster['same_summary']}")


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == PHASES_CHILD:
        raise SystemExit(_phases_child(sys.argv[2], sys.argv[3:]))
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--repeats", type=int, default=1, help="Dask runs of Table 2 (median; default 1)")
    p.add_argument("--no-memory", action="store_true", help="skip the driver-memory studies")
    p.add_argument("--no-processes", action="store_true", help="skip measure on a LocalCluster of processes")
    p.add_argument("--phases", action="store_true", help="also time the command's phases (one more run a repeat)")
    p.add_argument("--before", type=Path, default=None, metavar="TREE",
                   help="also time the command with this checkout's packages first on PYTHONPATH")
    p.add_argument("--short-runs", type=int, default=10_000, metavar="N",
                   help="runs of the short-run study (the circles cut to 10 s; default 10 000; 0: none)")
    p.add_argument("--short-only", action="store_true", help="only the short-run study (no Table 2)")
    p.add_argument("--cluster", action="store_true",
                   help="also fly the short-run study on a Dask cluster of --workers processes started by address")
    p.add_argument("--json", help="also write the figures to this JSON file")
    args = p.parse_args()
    if args.short_only:
        short = _short_only(args)
        if args.json:
            Path(args.json).write_text(json.dumps(short, indent=2))
        return
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        print("note: PYTHONDONTWRITEBYTECODE is set: a module with no bytecode cached yet is compiled in every "
              "process")

    from cosim.study.definition import count

    study = _table2()
    runs = count(study)
    med = statistics.median
    kinds = {"threads": True} if args.no_processes else {"threads": True, "processes": False}
    trees = {"after": None, **({"before": args.before} if args.before is not None else {})}
    loops = _Loops(study)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            loops.sample()
            here_wall, here_cpu, here_times = _run(study, tmp / "here", 1)
            loops.sample()
            walls = {k: [] for k in kinds}
            cpus = {k: [] for k in kinds}
            sums = {k: [] for k in kinds}
            commands = {t: [] for t in trees}
            command_cpus = {t: [] for t in trees}
            phases = {t: [] for t in trees}
            for i in range(args.repeats):  # alternated, so that a change of the machine's load hits each alike
                for kind, threads in kinds.items():
                    wall, cpu, times = _run(study, tmp / f"{kind}{i}", args.workers, threads)
                    walls[kind].append(wall)
                    cpus[kind].append(cpu)
                    sums[kind].append(sum(times))
                # the trees in turn first: the first command after the studies above ran slower, whichever it was
                order = list(trees.items()) if i % 2 == 0 else list(trees.items())[::-1]
                for tag, tree in order:
                    wall, cpu = _command(tmp / f"command-{tag}{i}", args.workers, tree)
                    commands[tag].append(wall)
                    command_cpus[tag].append(cpu)
                loops.sample()
                if args.phases:
                    for tag, tree in order:
                        phases[tag].append(_phases(args.workers, tmp, tree, f"{tag}{i}"))
                    loops.sample()
            short = _short_and_cluster(args, tmp) if args.short_runs > 0 else None
            if not args.no_memory:
                small, large = _memory_study(40), _memory_study(160)
                peak_small = _driver_peak_bytes(small, tmp / "small", args.workers)
                peak_large = _driver_peak_bytes(large, tmp / "large", args.workers)
    finally:
        loops.close()

    loop = med(loops.rounds)
    ideal = runs * loop / args.workers
    here_mean = sum(here_times) / len(here_times)
    dask_walls, dask_sums = walls["threads"], sums["threads"]
    dask_wall, dask_sum = med(dask_walls), med(dask_sums)
    here_overhead = (here_wall - sum(here_times)) / runs
    dask_overhead = (args.workers * dask_wall - dask_sum) / runs
    command, command_cpu = med(commands["after"]), med(command_cpus["after"])
    figures = {
        "runs": runs, "workers": args.workers, "loop_s": loop, "loop_rounds_s": loops.rounds,
        "in_process_mean_run_s": here_mean,
        "in_process_wall_s": here_wall, "in_process_overhead_per_run_ms": here_overhead * 1e3,
        "in_process_overhead_share_of_loop": here_overhead / loop,
        "dask_wall_s": dask_wall, "dask_walls_s": dask_walls, "dask_sum_of_run_times_s": dask_sum,
        "dask_overhead_per_run_ms": dask_overhead * 1e3, "dask_overhead_share_of_loop": dask_overhead / loop,
        "efficiency": dask_sum / (args.workers * dask_wall), "ideal_s": ideal,
        "dask_wall_over_ideal": dask_wall / ideal, "command_wall_s": command, "command_walls_s": commands["after"],
        "command_wall_over_ideal": command / ideal,
        "in_process_cpu_s": here_cpu, "command_cpu_s": command_cpu, "command_cpus_s": command_cpus["after"],
        **{f"{kind}_{what}": value for kind in kinds for what, value in
           (("wall_s", med(walls[kind])), ("cpu_s", med(cpus[kind])), ("walls_s", walls[kind]),
            ("cpus_s", cpus[kind]), ("wall_over_ideal", med(walls[kind]) / ideal))},
    }
    if args.before is not None:
        figures.update({"before_command_walls_s": commands["before"], "before_command_cpus_s": command_cpus["before"],
                        "before_command_wall_over_ideal": med(commands["before"]) / ideal})
    if args.phases:
        figures["phases"] = phases
    spread = (max(loops.rounds) - min(loops.rounds)) / loop
    print(f"Table 2: {runs} runs of the 50 s circles")
    print(f"  one run's loop time L (Master.run of a run alone, compiled loop; median of {len(loops.rounds)} rounds "
          f"of the 27 cells)  {loop * 1e3:6.1f} ms")
    print(f"    rounds, in order: {', '.join(f'{r * 1e3:.1f}' for r in loops.rounds)} ms (min {min(loops.rounds) * 1e3:.1f},"
          f" max {max(loops.rounds) * 1e3:.1f}: spread {spread:.0%} of L)")
    print(f"  in this process: wall                        {here_wall:8.2f} s (its runs' mean Master.run "
          f"{here_mean * 1e3:.1f} ms)")
    print(f"    overhead per run                           {here_overhead * 1e3:8.1f} ms = "
          f"{here_overhead / loop:5.0%} of L")
    print(f"    CPU                                        {here_cpu:8.2f} s = {here_cpu / runs * 1e3:.1f} ms a run "
          f"(the reference below)")
    print(f"  ideal, runs x L / workers                    {ideal:8.2f} s")
    for kind in kinds:
        wall, cpu = med(walls[kind]), med(cpus[kind])
        print(f"  measure on {args.workers} {kind:9s} (median of {args.repeats}): wall {wall:8.2f} s = "
              f"{wall / ideal:5.2f} x ideal;  CPU {cpu:6.2f} s = {cpu / here_cpu:4.2f} x in-process")
    print(f"    threads: overhead per run (workers x wall - runs) {dask_overhead * 1e3:6.1f} ms = "
          f"{dask_overhead / loop:5.0%} of L;  efficiency {figures['efficiency']:.2f}, i.e. wall "
          f"{1 / figures['efficiency']:.2f} x the runs' own loop times / workers (timed with the study: no drift)")
    for tag in trees:
        wall, cpu = med(commands[tag]), med(command_cpus[tag])
        name = "fnn-cosim table2 (a new process)" if tag == "after" else f"  the same, {args.before.name}"
        print(f"  {name:44s} {wall / ideal:8.2f} x ideal ({wall:.2f} s; "
              f"{', '.join(f'{w:.2f}' for w in commands[tag])});  CPU {cpu:6.2f} s = {cpu / here_cpu:4.2f} x "
              f"in-process" + ("  (target <= 1.6 on 2 workers)" if tag == "after" else ""))
    if args.phases:
        _print_phases(phases, ideal, loop)
    if short is not None:
        figures["short_runs"] = short
        _print_short(short, args.workers, dask_wall / ideal)
    beside_kernel, beside_python = _gil_free()
    figures.update({"counts_per_s_beside_the_kernel": beside_kernel, "counts_per_s_beside_python": beside_python})
    print(f"the GIL during the compiled loop: a Python counter in another thread {beside_kernel:,.0f}/s while a "
          f"run's loop runs, {beside_python:,.0f}/s beside a Python loop (a loop holding the GIL would stop it)")
    if not args.no_memory:
        figures.update({"driver_peak_small_MB": peak_small / 1e6, "driver_peak_large_MB": peak_large / 1e6,
                        "driver_memory_ratio_4x_runs": peak_large / peak_small})
        print(f"driver peak Python memory: 200 one-second runs {peak_small / 1e6:.2f} MB, 800 runs "
              f"{peak_large / 1e6:.2f} MB, ratio {peak_large / peak_small:.2f} (flat: ~1)")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
