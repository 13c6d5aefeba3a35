"""Time of the along-flight study (docs/stability.md, "Along the flight") on one run.

The circles mission (PD+LM-FNN, boundary layer 0.2 m/s) over ``--duration``
s, frozen every ``--every`` s with the perturbation checks of 1 s: the work
of one case of ``fnn-cosim stability --along-every S``, in this process. Prints
the wall time of the run and its frozen points (median of ``--repeats``,
after one warm-up), and the time per frozen point. Printed, never asserted.

    python benchmarks/along_flight_speed.py [--duration 12] [--every 2] [--repeats 3]
"""
from __future__ import annotations

import argparse
import statistics
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=12.0)
    parser.add_argument("--every", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    from cosim.scenario import load_scenario
    from quadrotor_paper.stability.along_flight import AlongFlight, along_flight

    scenario = load_scenario("circles", {"controller.variant": "pd+lm", "controller.position.phi": [0.2] * 3,
                                         "simulation.duration": args.duration})
    metric = AlongFlight(every=args.every, check=1.0)
    times, points = [], 0
    for i in range(args.repeats + 1):
        t = time.perf_counter()
        flight = along_flight(scenario, metric)
        if i:  # the first run warms the FMU cache and the imports
            times.append(time.perf_counter() - t)
        points = len(flight.points)
    wall = statistics.median(times)
    print(f"along the circles, pd+lm, phi 0.2 m/s, {args.duration:g} s frozen every {args.every:g} s "
          f"({points} points, checks of 1 s): {wall:.2f} s (median of {args.repeats}), "
          f"{wall / max(points, 1) * 1e3:.0f} ms per frozen point")


if __name__ == "__main__":
    main()
