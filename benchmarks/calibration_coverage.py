"""The coverage study of ``fnn-cosim calibrate``'s 95 % intervals on the plant.

For each seed: the plant flown by the project in the circles mission with
the sensors of ``circles_sensors`` (Measurement12: motion-capture position
and attitude noise, gyro and velocity noise; the command link's delay) and a
constant 3 m/s wind, hidden parameters (quadrotor_paper.synthetic_log.HIDDEN);
the log (``fly_sensed_log``) is written as another vehicle's: ENU world, FLU
body, the attitude a quaternion (scalar last), the rotor commands in PX4's
motor order by position and the ESCs' noisy rotor speeds, read through the
column map a user would write (``sensed_column_map``). ``b, Ix, k_drag_lin,
tau_m`` and the wind are fitted (every segment's initial state estimated:
the logged states are noisy). Printed per seed: each estimate's relative
error and whether its 95 % interval covers the truth, the intervals used
(classical, or robust after a warning) and the warnings; at the end, per
parameter, the share of seeds covered (about 95 % expected) and the largest
relative error.

With ``--aero`` (issue 42's "Done when"): the plant an X frame with rotor
drag, axial inflow and translational lift (HIDDEN_X_AERO), the controller's
mixer an X as it reads the plant's arm_angle, the same sensors and wind, and
FIT_AERO fitted: b, d, the three inertias, tau_m, the three rotor
coefficients, both body drags and the three wind components (wind_z's truth
is 0: its absolute error is printed). ``--processes N``: N seeds fitted side
by side on a Dask ``LocalCluster`` (minutes a seed; docs/calibration.md).

    .venv/bin/python benchmarks/calibration_coverage.py [--aero] [--seeds 20] [--first 1] [--duration 20] [--processes 2]
"""
from __future__ import annotations

import argparse
import contextlib
import tempfile
from pathlib import Path

import numpy as np

FIT = ("b", "Ix", "k_drag_lin", "tau_m", "wind_x", "wind_y")
GUESS = {"b": 5.5e-6, "Ix": 0.028, "k_drag_lin": 0.2, "tau_m": 0.025, "wind_x": 0.0, "wind_y": 0.0}
FIT_AERO = ("b", "d", "Ix", "Iy", "Iz", "tau_m", "k_rotor_drag", "k_inflow", "k_translational_lift",
            "k_drag_lin", "k_drag_quad", "wind_x", "wind_y", "wind_z")
GUESS_AERO = {"b": 6.0e-6, "d": 1.6e-7, "Ix": 0.03, "Iy": 0.04, "Iz": 0.021, "tau_m": 0.02, "k_rotor_drag": 1.0e-4,
              "k_inflow": 1.0e-4, "k_translational_lift": 0.005, "k_drag_lin": 0.2, "k_drag_quad": 0.04,
              "wind_x": 0.0, "wind_y": 0.0, "wind_z": 0.0}


def one(seed: int, duration: float, workers: int, aero: bool = False):
    from cosim.calibration import CalibrationSettings, calibrate
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model
    from quadrotor_paper.synthetic_log import HIDDEN, HIDDEN_X_AERO, WIND, fly_sensed_log, sensed_column_map

    fit, guess, hidden = (FIT_AERO, GUESS_AERO, HIDDEN_X_AERO) if aero else (FIT, GUESS, HIDDEN)
    fmu = built_fmu("Quadrotor", 2, lambda: model("Quadrotor"))
    fixed = {k: v for k, v in hidden.items() if k not in fit} | {"z_0": -15.0}
    truth = {**hidden, **WIND}
    with tempfile.TemporaryDirectory() as tmp:
        log = fly_sensed_log(Path(tmp), seed, duration, hidden)
        cal = calibrate(log, fmu, CalibrationSettings(fit=list(fit), guess=guess, fix=fixed, segment=2.0,
                                                      holdout=0.0, initial_states="estimated", workers=workers),
                        sensed_column_map(hidden))
    out = {}
    for j, n in enumerate(fit):
        lo, hi = cal.stats.ci95[j]
        error = abs(cal.fit.theta[j] / truth[n] - 1) if truth[n] else abs(cal.fit.theta[j])
        out[n] = (error, bool(lo <= truth[n] <= hi), cal.converged)
    # why a seed misses: the intervals used (robust after a residuals-not-white warning) and the warnings
    out["_why"] = f"{cal.stats.covariance} intervals, warnings: {sorted({d.kind for d in cal.diagnostics}) or 'none'}"
    return out


def _one(job):
    seed, duration, workers, aero = job
    return seed, one(seed, duration, workers, aero)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first", type=int, default=1, help="the first seed (a study split over processes)")
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--aero", action="store_true", help="an X frame with rotor aerodynamics, FIT_AERO fitted")
    ap.add_argument("--processes", type=int, default=1, help="seeds fitted side by side (each with --workers)")
    args = ap.parse_args()
    rows = []
    jobs = [(seed, args.duration, args.workers, args.aero) for seed in range(args.first, args.first + args.seeds)]
    cluster = contextlib.ExitStack()
    if args.processes > 1:  # the project's executor (cosim.executor): a Dask cluster of processes
        from cosim.executor import parallel

        pool = cluster.enter_context(parallel("dask", args.processes))
        results = (pool.result(f) for f in pool.as_completed([pool.submit(_one, job) for job in jobs]))
    else:
        results = map(_one, jobs)
    for seed, r in results:
        why = r.pop("_why")
        rows.append(r)
        print(f"seed {seed:2d}: " + ", ".join(f"{n} {e:.1e}{'' if c else ' NOT COVERED'}" for n, (e, c, _) in r.items())
              + ("" if all(v[2] for v in r.values()) else " (not converged)") + f" ({why})", flush=True)
    cluster.close()
    for n in (FIT_AERO if args.aero else FIT):
        covered = np.mean([r[n][1] for r in rows])
        worst = max(r[n][0] for r in rows)
        print(f"{n:11s}: 95 % interval covers the truth in {covered:.0%} of {len(rows)} seeds; "
              f"largest {'absolute' if n == 'wind_z' else 'relative'} error {worst:.2e}")


if __name__ == "__main__":
    main()
