"""Speed of the co-simulation, measured in one run.

Prints, for the 50 s mission of section 5.2 (circles, 3 m/s gust) with
PD+LM-FNN at dt = 0.01 s (5000 steps):

* the wall time (median of --repeats runs, after one warm-up run) with the
  scenario's 23 recorded signals kept in memory, and with them also streamed
  to a CSV file, and the real-time factor;
* the per-step cost split into the FMU exchange (set inputs, doStep, get
  outputs), the controller FMU evaluated at t_n, recording and the
  divergence guard (profiling runs the master's Python loop; unprofiled, the
  mission of FMUs only runs in its compiled loop);
* ``fmpy.simulate_fmu`` of the plant FMU alone over the same 50 s with the
  same output interval, as a reference;
* ``table2``: the shipped study (every variant and option row, 186 runs) on
  --workers processes (skip with --no-table2).

Targets, as ratios measured in this run: the whole mission (plant, wind,
reference and controller FMUs, recording, the guard) at most 3x fmpy's own
loop over the plant FMU alone. Printed, never asserted: a slow or busy machine changes the
figures, not the verdict of the test suite.

    .venv/bin/python benchmarks/cosim_speed.py [--repeats 7] [--workers 2] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path


def _median_runs(master, scenario, repeats: int, csv: Path | None, profile: bool = False):
    times, results = [], []
    master.run(scenario.duration, seed=0, csv_path=csv)  # warm-up
    for i in range(repeats):
        t = time.perf_counter()
        r = master.run(scenario.duration, seed=i, csv_path=csv, profile=profile)
        times.append(time.perf_counter() - t)
        results.append(r)
    return statistics.median(times), times, results


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--no-table2", action="store_true")
    p.add_argument("--json", help="also write the figures to this JSON file")
    args = p.parse_args(argv)

    import fmpy

    import quadrotor_paper  # noqa: F401  (registers the paper's scenarios)
    from quadrotor_paper.report import table_study
    from quadrotor_paper.experiments import measure
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master, fmu_file

    scenario = load_scenario("circles", {"controller.variant": "pd+lm", "wind.speed": 3.0})
    n_steps = int(round(scenario.duration / scenario.step))
    figures: dict = {"steps": n_steps, "cores": os.cpu_count()}

    with build_master(scenario) as master, tempfile.TemporaryDirectory() as tmp:
        med_mem, times_mem, results = _median_runs(master, scenario, args.repeats, None)
        med_csv, times_csv, _ = _median_runs(master, scenario, args.repeats, Path(tmp) / "r.csv")
        _, _, profiled = _median_runs(master, scenario, args.repeats, None, profile=True)
    assert all(r.status == "ok" for r in results + profiled)
    phases: dict[str, list[float]] = {}
    for r in profiled:
        for k, v in r.phase_times.items():
            phases.setdefault(k, []).append(v / n_steps * 1e6)
    per_step = {k: statistics.median(v) for k, v in phases.items()}
    figures["mission_wall_s"] = {"in_memory": med_mem, "with_csv": med_csv,
                                 "runs_in_memory": times_mem, "runs_with_csv": times_csv}
    figures["real_time_factor"] = {"in_memory": scenario.duration / med_mem, "with_csv": scenario.duration / med_csv}
    figures["per_step_us"] = per_step
    figures["per_step_us"]["total"] = med_mem / n_steps * 1e6

    plant = str(fmu_file(scenario.fmus["Quadrotor"]))
    fmpy_times = []
    for _ in range(max(3, args.repeats // 2)):
        t = time.perf_counter()
        fmpy.simulate_fmu(plant, stop_time=scenario.duration, output_interval=scenario.step,
                          start_values={"z_0": -15.0}, validate=False)
        fmpy_times.append(time.perf_counter() - t)
    figures["fmpy_simulate_fmu_plant_alone_s"] = statistics.median(fmpy_times)

    print(f"50 s mission (circles, PD+LM-FNN, 3 m/s gust), {n_steps} steps of {scenario.step} s, "
          f"median of {args.repeats}:")
    print(f"  wall time, recording in memory : {med_mem * 1e3:7.1f} ms   real-time factor {scenario.duration / med_mem:6.0f}")
    print(f"  wall time, also streaming CSV  : {med_csv * 1e3:7.1f} ms   real-time factor {scenario.duration / med_csv:6.0f}")
    print("  cost per step (median of profiled runs, in memory; the timers add their own cost):")
    names = {"fmu": "FMU exchange (4 FMUs: set, doStep, get)",
             "fmu:controller": "controller FMU at t_n (set, get)", "record": "recording (23 signals)",
             "guard": "divergence guard", "total": "total, unprofiled (wall / steps)"}
    for k in per_step:
        print(f"    {names.get(k, k):40s} {per_step[k]:6.2f} us")
    print(f"  fmpy.simulate_fmu, plant FMU alone, 50 s: {figures['fmpy_simulate_fmu_plant_alone_s'] * 1e3:7.1f} ms")
    figures["ratio_mission_to_fmpy_plant_alone"] = med_mem / figures["fmpy_simulate_fmu_plant_alone_s"]
    print(f"  ratio, whole mission (4 FMUs + recording) / fmpy plant alone: "
          f"{figures['ratio_mission_to_fmpy_plant_alone']:.2f}  (target <= 3)")

    if not args.no_table2:
        study = table_study(2)  # what `fnn-cosim table2` runs: every variant and the option rows
        t = time.perf_counter()
        result = measure(study, workers=args.workers)
        wall = time.perf_counter() - t
        assert result.counts == {"ok": result.total}, result.counts
        figures["table2_wall_s"] = wall
        figures["table2_workers"] = args.workers
        print(f"table2: {result.total} runs of 50 s on {args.workers} workers: {wall:.1f} s "
              f"({wall / result.total * 1e3:.0f} ms a run, including worker start-up)")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
