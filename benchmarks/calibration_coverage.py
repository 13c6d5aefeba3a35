"""The coverage study of ``fnn-cosim calibrate``'s 95 % intervals on the plant.

For each seed: the plant flown by the project in the circles mission with
the sensors of ``circles_sensors`` (Measurement12: motion-capture position
and attitude noise, gyro and velocity noise; the command link's delay) and a
constant 3 m/s wind, hidden parameters (quadrotor_paper.synthetic_log.HIDDEN);
the log holds the *measured* states, the rotor commands the plant received
and the rotor speeds. ``b, Ix, k_drag_lin, tau_m`` and the wind are fitted
(every segment's initial state estimated: the logged states are noisy).
Printed per seed: each estimate's relative error and whether its 95 %
interval covers the truth; at the end, per parameter, the share of seeds
covered (about 95 % expected) and the largest relative error (target 1 %).

    .venv/bin/python benchmarks/calibration_coverage.py [--seeds 20] [--first 1] [--duration 20]
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

FIT = ("b", "Ix", "k_drag_lin", "tau_m", "wind_x", "wind_y")
GUESS = {"b": 5.5e-6, "Ix": 0.028, "k_drag_lin": 0.2, "tau_m": 0.025, "wind_x": 0.0, "wind_y": 0.0}
STATES = ("x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")


def noisy_log(folder: Path, seed: int, duration: float) -> Path:
    from quadrotor_paper.synthetic_log import fly_synthetic_log

    record = tuple(f"Sensors.{s}_m" for s in STATES) + tuple(f"Quadrotor.Omega_{i}" for i in range(1, 5)) + \
        tuple(f"Quadrotor.Omega_r_{i}" for i in range(1, 5))
    return fly_synthetic_log(folder, duration, scenario="circles_sensors", record=record,
                             extra={"simulation.seed": seed})


def column_map():
    from cosim.calibration import ColumnMap

    columns = {s: f"Sensors.{s}_m" for s in STATES}
    columns |= {f"Omega_{i}": f"Quadrotor.Omega_{i}" for i in range(1, 5)}
    columns |= {f"Omega_r_{i}": f"Quadrotor.Omega_r_{i}" for i in range(1, 5)}
    return ColumnMap.from_document({"columns": columns}, "coverage")


def one(seed: int, duration: float, workers: int):
    from cosim.calibration import CalibrationSettings, calibrate
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model
    from quadrotor_paper.synthetic_log import HIDDEN

    fmu = built_fmu("Quadrotor", 2, lambda: model("Quadrotor"))
    fixed = {k: v for k, v in HIDDEN.items() if k not in FIT} | {"z_0": -15.0}
    wind = -3.0 / 2 ** 0.5
    truth = {**HIDDEN, "wind_x": wind, "wind_y": wind}
    with tempfile.TemporaryDirectory() as tmp:
        log = noisy_log(Path(tmp), seed, duration)
        cal = calibrate(log, fmu, CalibrationSettings(fit=list(FIT), guess=GUESS, fix=fixed, segment=2.0,
                                                      holdout=0.0, initial_states="estimated", workers=workers),
                        column_map())
    out = {}
    for j, n in enumerate(FIT):
        lo, hi = cal.stats.ci95[j]
        out[n] = (abs(cal.fit.theta[j] / truth[n] - 1), bool(lo <= truth[n] <= hi), cal.converged)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first", type=int, default=1, help="the first seed (a study split over processes)")
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    rows = []
    for seed in range(args.first, args.first + args.seeds):
        r = one(seed, args.duration, args.workers)
        rows.append(r)
        print(f"seed {seed:2d}: " + ", ".join(f"{n} {e:.1e}{'' if c else ' NOT COVERED'}" for n, (e, c, _) in r.items())
              + ("" if all(v[2] for v in r.values()) else " (not converged)"), flush=True)
    for n in FIT:
        covered = np.mean([r[n][1] for r in rows])
        worst = max(r[n][0] for r in rows)
        print(f"{n:11s}: 95 % interval covers the truth in {covered:.0%} of {len(rows)} seeds; "
              f"largest relative error {worst:.2e}")


if __name__ == "__main__":
    main()
