"""Efficiency and driver memory of a study on a local Dask cluster, measured in one run.

Prints, for a study of the circles mission (every registered variant x five
wind speeds x --seeds seeds, 200 runs by default) on a LocalCluster of
--workers processes:

* the wall time of the study, and the sum of the runs' own times (each row's
  ``wall_time_s``, measured inside the worker around the run);
* the parallel efficiency, sum of run times / (workers x wall time): 1 when
  the cluster adds nothing; target >= 0.8 on 2 workers;
* Dask's overhead per task, (workers x wall - sum of run times) / runs,
  which includes the cluster's start-up and the workers' first FMU loads;
* the driver's peak Python memory (tracemalloc) for a study of 200 and of
  800 one-second runs: the rows are streamed to runs.csv, not held, and the
  local scheduler's logs are kept short (cosim/dask_runner.py), so the ratio
  should stay near 1 (with Dask's default logs it was 2.3 for 50 -> 200 runs).

Printed, never asserted: a slow or busy machine changes the figures, not
the verdict of the test suite.

    .venv/bin/python benchmarks/study_efficiency.py [--workers 2] [--seeds 8] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
import tracemalloc
from pathlib import Path

WINDS = [1.0, 2.0, 3.0, 4.0, 5.0]


def _study(seeds: int, duration: float | None = None, winds=WINDS):
    from cosim.study import parse_study
    from cosim.scenario import scenario_path
    from fnn_controller.variants import variant_names

    raw = {"scenario": str(scenario_path("circles")), "name": "efficiency",
           "sweep": {"seeds": seeds, "grid": {"controller.variant": list(variant_names()), "wind.speed": winds}}}
    if duration:
        raw["set"] = {"simulation.duration": duration}
    return parse_study(raw)


def _run(study, out: Path, workers: int):
    from cosim.study_run import read_runs
    from quadrotor_paper.experiments import measure

    t = time.perf_counter()
    measure(study, out, workers=workers)
    wall = time.perf_counter() - t
    return wall, read_runs(out / "runs.csv")


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
    p.add_argument("--seeds", type=int, default=8, help="seeds per cell (default 8: 5 variants x 5 winds x 8 = 200 runs)")
    p.add_argument("--json", help="also write the figures to this JSON file")
    args = p.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        study = _study(args.seeds)
        wall, rows = _run(study, Path(tmp) / "study", args.workers)
        run_times = sum(float(r["wall_time_s"]) for r in rows)
        efficiency = run_times / (args.workers * wall)
        overhead = (args.workers * wall - run_times) / len(rows)

        small, large = _study(40, duration=1.0, winds=[1.0]), _study(160, duration=1.0, winds=[1.0])
        peak_small = _driver_peak_bytes(small, Path(tmp) / "small", args.workers)
        peak_large = _driver_peak_bytes(large, Path(tmp) / "large", args.workers)

    figures = {
        "runs": len(rows), "workers": args.workers, "wall_s": wall, "sum_of_run_times_s": run_times,
        "efficiency": efficiency, "overhead_per_task_ms": overhead * 1e3,
        "driver_peak_small_MB": peak_small / 1e6, "driver_peak_large_MB": peak_large / 1e6,
        "driver_memory_ratio_4x_runs": peak_large / peak_small,
        "runs_small": len(small.grid["controller.variant"]) * 40,
        "runs_large": len(large.grid["controller.variant"]) * 160,
    }
    print(f"study: {figures['runs']} runs of the 50 s circles on a LocalCluster of {args.workers} workers")
    print(f"  wall time                      {wall:8.2f} s")
    print(f"  sum of the runs' own times     {run_times:8.2f} s")
    print(f"  efficiency                     {efficiency:8.2f}   (target >= 0.8)")
    print(f"  Dask overhead per task         {overhead * 1e3:8.1f} ms (cluster start and first FMU loads included)")
    print(f"driver peak Python memory: {figures['runs_small']} runs {peak_small / 1e6:.2f} MB, "
          f"{figures['runs_large']} runs {peak_large / 1e6:.2f} MB, ratio {peak_large / peak_small:.2f} "
          "(flat: ~1)")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
