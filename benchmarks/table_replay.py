"""A recorded run replayed through the signal table, in the compiled loop and in the Python loop.

Records 50 s of the circles mission (the plant's states and the controller's
rotor commands, 5000 steps of 10 ms) to a results.csv, then replays the
commands into the plant and the gust alone (``kind = "signal_table"``,
docs/cosim.md "The signal table") with the table

1. as its table FMU (``form = "fmu"``): the master's compiled loop, and
2. as the Python component (``form = "python"``): the Python loop,

and prints the wall time of ``Master.run`` of each (median of --repeats runs
after a warm-up), their ratio, and the largest state difference of each
replay from the recorded run (0 expected: the same inputs, the same FMU).
Printed, never asserted.

    .venv/bin/python benchmarks/table_replay.py [--repeats 3]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

import numpy as np

from cosim.scenario.definition import load_scenario, parse_scenario
from cosim.scenario.assembly import build_master

STATES = [f"Quadrotor.{s}" for s in ("x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")]
COMMANDS = [f"controller.Omega_{i}" for i in range(1, 5)]


def replay(log: Path, form: str, duration: float) -> dict:
    circles = load_scenario("circles")
    fmus = {name: {"model": spec["model"], "fmi_version": 2, "parameters": dict(spec["parameters"])}
            for name, spec in circles.fmus.items()}
    return {"connections": ["WindGust.v_wind_{x,y,z} -> Quadrotor.wind_{x,y,z}",
                            "log.controller.Omega_{1,2,3,4} -> Quadrotor.Omega_{1,2,3,4}"],
            "simulation": {"duration": duration, "step": 0.01}, "fmus": fmus,
            "components": {"log": {"kind": "signal_table", "file": str(log), "form": form}},
            "record": {"signals": STATES}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    duration = 50.0
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "results.csv"
        scenario = load_scenario("circles", {"record.signals": STATES + COMMANDS})
        with build_master(scenario) as master:
            original = master.run(duration, csv_path=log)
        times = {}
        for form in ("fmu", "python"):
            with build_master(parse_scenario(replay(log, form, duration))) as master:
                loop = "compiled" if master.plan.compiled else "Python"
                master.run(duration)  # warm-up
                walls, result = [], None
                for _ in range(args.repeats):
                    result = master.run(duration)
                    walls.append(result.wall_time)
            times[form] = statistics.median(walls)
            gap = max(float(np.max(np.abs(result[s] - original[s]))) for s in STATES)
            print(f"table as {form:6s} ({loop} loop): {times[form]:.3f} s for {result.n_steps} steps "
                  f"({1e6 * times[form] / result.n_steps:.1f} us/step); largest state difference from the "
                  f"recorded run: {gap:.3g}")
        print(f"Python component / table FMU: {times['python'] / times['fmu']:.1f}x")


if __name__ == "__main__":
    main()
