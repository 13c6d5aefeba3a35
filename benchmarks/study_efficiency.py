"""A study at the loop's cost: Table 2's overhead per run and wall time against the ideal, measured in one run.

Prints, for Table 2 (the shipped study ``table2``: 186 runs of the 50 s
circles, every variant and option row at 1, 3 and 5 m/s):

* **one run's loop time** ``L``: the mean of the runs' own times (each
  row's ``wall_time_s``: ``Master.run``, which starts the FMUs -- reset,
  parameters, initialization -- and flies the 5000 steps, as
  ``benchmarks/loop_speed.py`` times a run), measured here by flying the
  study in this process (``--workers 1``, no Dask);
* **the overhead per run** in this process, (wall - sum of the runs' times)
  / runs, and as a share of ``L``: what a run costs besides its loop (its
  scenario, its master when it needs a new one, its metrics, its row, the
  summary);
* **Table 2 on Dask** (``measure``, its start and stop included) on
  ``--workers`` threads of this process (Dask's threaded scheduler, no
  cluster: what ``measure`` chooses for the project's own FMUs,
  :func:`quadrotor_paper.experiments.threads_safe`) and on a LocalCluster
  of ``--workers`` worker processes (what any other study gets), and the whole command
  ``fnn-cosim table2 --workers N`` (a new process: imports included), each
  against the ideal, ``runs x L / workers``: target ``fnn-cosim table2`` <=
  1.6x on 2 workers; and the Dask overhead per run, (workers x wall - sum
  of the runs' times) / runs, as a share of ``L``;
* **CPU time** beside each wall time (this process's, and its child
  processes' polled every 20 ms: worker processes, the command's tree): on
  a machine others load, wall time measures the load, CPU time what a
  study costs; the in-process study's CPU is the reference (no Dask, one
  core, every master built once);
* whether the compiled loop leaves the GIL free: a Python counter in
  this thread while another thread flies runs of one kernel call each;
* the driver's peak Python memory (tracemalloc) for a study of 200 and of
  800 one-second runs: the rows are streamed to runs.csv, not held, and the
  local scheduler's logs are kept short (cosim/dask_runner.py), so the ratio
  should stay near 1 (with Dask's default logs it was 2.3 for 50 -> 200 runs).

Printed, never asserted: a slow or busy machine changes the figures, not
the verdict of the test suite. On a shared machine, repeat (``--repeats``):
the Dask figures are the median of the repeats.

    .venv/bin/python benchmarks/study_efficiency.py [--workers 2] [--repeats 1] [--no-memory] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
from pathlib import Path


def _table2():
    from quadrotor_paper.report import table_study

    return table_study(2)


def _memory_study(seeds: int):
    from cosim.scenario import scenario_path
    from cosim.study import parse_study
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
    from cosim.study_run import read_runs
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


def _command(out: Path, workers: int) -> tuple[float, float]:
    """Wall and CPU time (s) of ``fnn-cosim table2`` in a new process (its whole tree)."""
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "quadrotor_paper.cli", "table2", "--out", str(out), "--quiet",
                             "--workers", str(workers)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with _Cpu(proc.pid) as cpu:
        if proc.wait():
            raise SystemExit(f"fnn-cosim table2 exited with {proc.returncode}")
    return time.perf_counter() - t, cpu.cpu


def _gil_free(runs: int = 5) -> tuple[float, float]:
    """Whether another thread runs Python while a run's compiled loop runs:
    counts per second of a Python counter in this thread while another
    thread flies ``runs`` circles missions, each one kernel call (a block
    of every row), and while it runs a Python loop (which shares the GIL at
    the switch interval). A call that held the GIL would stop the counter
    for each whole run."""
    from cosim.assembly import build_master
    from cosim.scenario import load_scenario

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


def _driver_peak_bytes(study, out: Path, workers: int) -> int:
    tracemalloc.start()
    try:
        _run(study, out, workers)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--repeats", type=int, default=1, help="Dask runs of Table 2 (median; default 1)")
    p.add_argument("--no-memory", action="store_true", help="skip the driver-memory studies")
    p.add_argument("--json", help="also write the figures to this JSON file")
    args = p.parse_args()

    study = _table2()
    med = statistics.median
    with tempfile.TemporaryDirectory() as tmp:
        here_wall, here_cpu, here_times = _run(study, Path(tmp) / "here", 1)
        runs = len(here_times)
        loop = sum(here_times) / runs
        ideal = runs * loop / args.workers
        kinds = {"threads": True, "processes": False}
        walls = {k: [] for k in kinds}
        cpus = {k: [] for k in kinds}
        sums = {k: [] for k in kinds}
        commands, command_cpus = [], []
        for i in range(args.repeats):  # alternated, so that a change of the machine's load hits each alike
            for kind, threads in kinds.items():
                wall, cpu, times = _run(study, Path(tmp) / f"{kind}{i}", args.workers, threads)
                walls[kind].append(wall)
                cpus[kind].append(cpu)
                sums[kind].append(sum(times))
            wall, cpu = _command(Path(tmp) / f"command{i}", args.workers)
            commands.append(wall)
            command_cpus.append(cpu)
        dask_walls, dask_sums = walls["threads"], sums["threads"]
        dask_wall, dask_sum, command = med(dask_walls), med(dask_sums), med(commands)
        if not args.no_memory:
            small, large = _memory_study(40), _memory_study(160)
            peak_small = _driver_peak_bytes(small, Path(tmp) / "small", args.workers)
            peak_large = _driver_peak_bytes(large, Path(tmp) / "large", args.workers)

    here_overhead = (here_wall - sum(here_times)) / runs
    dask_overhead = (args.workers * dask_wall - dask_sum) / runs
    figures = {
        "runs": runs, "workers": args.workers, "loop_s": loop,
        "in_process_wall_s": here_wall, "in_process_overhead_per_run_ms": here_overhead * 1e3,
        "in_process_overhead_share_of_loop": here_overhead / loop,
        "dask_wall_s": dask_wall, "dask_walls_s": dask_walls, "dask_sum_of_run_times_s": dask_sum,
        "dask_overhead_per_run_ms": dask_overhead * 1e3, "dask_overhead_share_of_loop": dask_overhead / loop,
        "efficiency": dask_sum / (args.workers * dask_wall), "ideal_s": ideal,
        "dask_wall_over_ideal": dask_wall / ideal, "command_wall_s": command, "command_walls_s": commands,
        "command_wall_over_ideal": command / ideal,
        "in_process_cpu_s": here_cpu, "command_cpu_s": med(command_cpus), "command_cpus_s": command_cpus,
        **{f"{kind}_{what}": value for kind in kinds for what, value in
           (("wall_s", med(walls[kind])), ("cpu_s", med(cpus[kind])), ("walls_s", walls[kind]),
            ("cpus_s", cpus[kind]), ("wall_over_ideal", med(walls[kind]) / ideal))},
    }
    print(f"Table 2: {runs} runs of the 50 s circles")
    print(f"  one run's loop time L (mean Master.run)      {loop * 1e3:8.1f} ms")
    print(f"  in this process: wall                        {here_wall:8.2f} s")
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
          f"{dask_overhead / loop:5.0%} of L;  efficiency {figures['efficiency']:.2f}")
    print(f"  fnn-cosim table2 (a new process) / ideal     {command / ideal:8.2f} x   ({command:.2f} s; "
          f"target <= 1.6 on 2 workers);  CPU {med(command_cpus):6.2f} s = "
          f"{med(command_cpus) / here_cpu:4.2f} x in-process")
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
