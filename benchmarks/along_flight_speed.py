"""Time of the along-flight study (docs/stability.md, "Along the flight") on one run.

The circles mission (PD+LM-FNN, boundary layer 0.2 m/s) over ``--duration``
s, frozen every ``--every`` s with the perturbation checks of 1 s: the work
of one case of ``fnn-cosim stability --along-every S``, in this process. Prints
the wall and CPU time of the run and its frozen points (medians of
``--repeats``, after one warm-up; the CPU time of this process is the
steadier figure on a shared machine), the time per frozen point, and the FMU
instances made per frozen point (every :class:`cosim.fmi.fmu.FmuComponent`
instantiation counted). Printed, never asserted.

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

    from cosim.fmi.fmu import FmuComponent
    from cosim.scenario.definition import load_scenario
    from quadrotor_paper.stability.along_flight import AlongFlight, along_flight

    made = [0]
    instantiate = FmuComponent.instantiate

    def counted(self):
        made[0] += self._slave is None
        return instantiate(self)

    FmuComponent.instantiate = counted

    scenario = load_scenario("circles", {"controller.variant": "pd+lm", "controller.position.phi": [0.2] * 3,
                                         "simulation.duration": args.duration})
    metric = AlongFlight(every=args.every, check=1.0)
    walls, cpus, points = [], [], 0
    for i in range(args.repeats + 1):
        made[0] = 0
        t, c = time.perf_counter(), time.process_time()
        flight = along_flight(scenario, metric)
        if i:  # the first run warms the FMU cache and the imports
            walls.append(time.perf_counter() - t)
            cpus.append(time.process_time() - c)
        points = len(flight.points)
    wall, cpu, n = statistics.median(walls), statistics.median(cpus), max(points, 1)
    print(f"along the circles, pd+lm, phi 0.2 m/s, {args.duration:g} s frozen every {args.every:g} s "
          f"({points} points, checks of 1 s), medians of {args.repeats}: wall {wall:.2f} s "
          f"({wall / n * 1e3:.0f} ms per frozen point), CPU {cpu:.2f} s ({cpu / n * 1e3:.0f} ms per point); "
          f"FMU instances made: {made[0]}, {(made[0] - 8) / n:.1f} per frozen point besides the 8 of the run's and the "
          f"study's masters")


if __name__ == "__main__":
    main()
