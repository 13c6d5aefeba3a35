"""Our plant as Model Exchange against its Co-Simulation form, measured in one run.

Prints, for the 50 s circles mission (PD+LM-FNN, 3 m/s gust, 5000 steps of
10 ms), the wall time of ``Master.run`` (median of --repeats runs after a
warm-up; it includes starting the FMUs) and the time per step with the
Quadrotor FMU

1. in Co-Simulation (its RK4 at the communication step, inside the FMU; the
   master's compiled loop), and
2. in Model Exchange, integrated by the master (``cosim.model_exchange``:
   CVODE restarted at every communication point, where the rotor speeds
   change, at each --tolerances value; the Python loop),

then the ratio of each to 1., and the position RMSE of each Model Exchange
run against the Co-Simulation run (target: < 1e-4 m, the two integrators'
difference). Printed, never asserted.

    .venv/bin/python benchmarks/model_exchange.py [--repeats 3] [--tolerances 1e-6,1e-8] [--fmi-version 2]
"""
from __future__ import annotations

import argparse
import statistics

import numpy as np

from cosim.scenario import load_scenario
from cosim.assembly import build_master

POSITION = ("Quadrotor.x", "Quadrotor.y", "Quadrotor.z")


def fly(overrides: dict, repeats: int) -> tuple[float, np.ndarray, int]:
    scenario = load_scenario("circles", overrides)
    with build_master(scenario) as master:
        master.run(scenario.duration, seed=scenario.seed)  # warm-up
        times, result = [], None
        for _ in range(repeats):
            result = master.run(scenario.duration, seed=scenario.seed)
            times.append(result.wall_time)
    return statistics.median(times), np.column_stack([result[s] for s in POSITION]), result.n_steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--tolerances", default="1e-6,1e-8", help="CVODE relative tolerances, comma-separated")
    parser.add_argument("--fmi-version", type=int, default=2, choices=(2, 3))
    args = parser.parse_args()
    version = {"fmus.Quadrotor.fmi_version": args.fmi_version}
    cs_time, cs_xyz, n = fly(version, args.repeats)
    print(f"circles, 50 s, {n} steps, Quadrotor FMI {args.fmi_version}.0, median of {args.repeats}")
    print(f"{'plant':<40} {'run (s)':>9} {'per step (us)':>14} {'x CS':>7} {'RMSE vs CS (m)':>15}")
    print(f"{'Co-Simulation (RK4 in the FMU)':<40} {cs_time:9.3f} {cs_time / n * 1e6:14.1f} {1.0:7.1f} {0.0:15.2e}")
    for tolerance in (float(t) for t in args.tolerances.split(",")):
        me_time, me_xyz, _ = fly({**version, "fmus.Quadrotor.interface": "ModelExchange",
                                  "fmus.Quadrotor.solver.relative_tolerance": tolerance}, args.repeats)
        rmse = float(np.sqrt(np.mean(np.sum((me_xyz - cs_xyz) ** 2, axis=1))))
        print(f"{f'Model Exchange, CVODE rtol {tolerance:g}':<40} {me_time:9.3f} {me_time / n * 1e6:14.1f} "
              f"{me_time / cs_time:7.1f} {rmse:15.2e}")


if __name__ == "__main__":
    main()
