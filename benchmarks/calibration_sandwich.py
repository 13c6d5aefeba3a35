"""Coverage of ``fnn-cosim calibrate``'s 95 % intervals with correlated
noise: classical against robust (sandwich) standard errors.

For each seed: the Reference FMU Dahlquist's own Co-Simulation (``k = 1``,
``x(0) = 1``, 3 s at 0.01 s) plus AR(1) noise (``rho``, a stationary
standard deviation of 0.005: a logger that filtered its noise), ``k``
fitted from 0.5. Printed per seed: the estimate, both standard errors,
whether each interval covers the truth and whether the residuals warned;
at the end, each interval's coverage (95 % expected), the mean ratio of the
standard errors beside ``sqrt((1 + rho) / (1 - rho))`` (the variance factor
of a mean through AR(1) noise), and the share of seeds that warned
``residuals-not-white``.

    .venv/bin/python benchmarks/calibration_sandwich.py [--seeds 40] [--rho 0.8]
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

FMU = Path(__file__).resolve().parents[1].parent / "shared" / "reference-fmus" / "fmi2" / "Dahlquist.fmu"
SIGMA = 0.005


def ar1(rng: np.random.Generator, n: int, rho: float, sigma: float) -> np.ndarray:
    """Stationary AR(1) noise of standard deviation ``sigma``."""
    w = rng.standard_normal(n) * sigma * np.sqrt(1 - rho ** 2)
    e = np.empty(n)
    e[0] = sigma * rng.standard_normal()
    for i in range(1, n):
        e[i] = rho * e[i - 1] + w[i]
    return e


def main() -> None:
    from fmpy import simulate_fmu

    from cosim.calibration import CalibrationSettings, calibrate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--rho", type=float, default=0.8)
    args = ap.parse_args()
    run = simulate_fmu(str(FMU), stop_time=3.0, output_interval=0.01)
    t, x = run["time"], run["x"]
    covered = {"classical": 0, "robust": 0}
    ratios, warned = [], 0
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            path = Path(tmp) / f"log{seed}.csv"
            noisy = x + ar1(np.random.default_rng(seed), t.size, args.rho, SIGMA)
            np.savetxt(path, np.column_stack([t, noisy]), delimiter=",", header="time,x", comments="")
            cal = calibrate(path, FMU, CalibrationSettings(fit=["k"], guess={"k": 0.5}, initial_states="estimated"))
            st = cal.stats
            robust = st.covariance == "robust"
            std_c, std_r = st.std_classical[0], st.std_robust[0]
            k = float(cal.fit.theta[0])
            half = (st.ci95[0, 1] - st.ci95[0, 0]) / 2 / st.std[0]  # t(0.975, dof)
            hit = {"classical": abs(k - 1.0) <= half * std_c, "robust": abs(k - 1.0) <= half * std_r}
            for key in hit:
                covered[key] += hit[key]
            ratios.append(std_r / std_c)
            warned += robust
            print(f"seed {seed:3d}: k = {k:.6f}  std classical {std_c:.3g} "
                  f"({'covers' if hit['classical'] else 'misses'})"
                  f"  robust {std_r:.3g} ({'covers' if hit['robust'] else 'misses'})"
                  f"  {'warned' if robust else 'white'}")
    n = args.seeds
    print(f"\nrho = {args.rho}: coverage of the truth by the 95 % intervals over {n} seeds: classical "
          f"{covered['classical']}/{n} ({covered['classical'] / n:.0%}), robust {covered['robust']}/{n} "
          f"({covered['robust'] / n:.0%})")
    print(f"robust / classical standard error: mean {np.mean(ratios):.3f}, expected about "
          f"sqrt((1+rho)/(1-rho)) = {np.sqrt((1 + args.rho) / (1 - args.rho)):.3f}")
    print(f"residuals-not-white warned on {warned}/{n} seeds (the robust intervals reported there)")


if __name__ == "__main__":
    main()
