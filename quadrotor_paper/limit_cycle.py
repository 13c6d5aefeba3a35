"""The z-axis limit cycle of the learning laws, with and without a boundary
layer: ``python -m quadrotor_paper.limit_cycle`` prints, for PD+SMC-FNN and
PD+LM-FNN on the circles mission (3 m/s gust, seed 0), the RMSE and, over the
last 20 s, the period of tau_n,z (autocorrelation), the amplitude of e_z, the
peak-to-peak of tau_n,z, and the PD's share in z in the first 5 s and the last
10 s, for boundary layers phi = 0 (the paper's sgn), 0.05, 0.1, 0.2 m/s
(docs/results.md)."""
from __future__ import annotations

import sys

import numpy as np

from cosim.scenario import build_master, load_scenario

from .metrics import oscillation_period, pd_share, rmse

__all__ = ["limit_cycle", "main"]

_POSITION = ["Quadrotor.x", "Quadrotor.y", "Quadrotor.z"]
_REFERENCE = ["reference.x", "reference.y", "reference.z"]


def limit_cycle(variant: str, phi: float, seed: int = 0) -> dict[str, float]:
    """The figures of one run (phi in m/s on every axis)."""
    record = _POSITION + _REFERENCE + ["controller.tau_c_z", "controller.tau_n_z"]
    sc = load_scenario("circles", {"controller.variant": variant, "controller.position.phi": [phi] * 3,
                                   "record.signals": record})
    with build_master(sc) as master:
        run = master.run(sc.duration, seed=seed)
    t, late = run.time, run.time >= sc.duration - 20.0
    e_z = run["reference.z"] - run["Quadrotor.z"]
    tau_n, tau_c = run["controller.tau_n_z"], run["controller.tau_c_z"]
    period, height = oscillation_period(tau_n[late], sc.step)
    share = pd_share(tau_c, tau_n)
    return {"rmse_m": rmse(run, _POSITION, _REFERENCE), "period_s": period, "autocorrelation": height,
            "e_z_amplitude_m": float(np.ptp(e_z[late]) / 2), "tau_n_z_peak_to_peak": float(np.ptp(tau_n[late])),
            "pd_share_first_5s": float(share[t < 5].mean()), "pd_share_last_10s": float(share[t >= t[-1] - 10].mean())}


def main() -> int:
    print("| variant | phi (m/s) | RMSE (m) | period of tau_n,z (s) | its autocorrelation | e_z amplitude (m) "
          "| tau_n,z peak to peak (m/s) | PD share in z, first 5 s | last 10 s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for variant in ("pd+smc", "pd+lm"):
        for phi in (0.0, 0.05, 0.1, 0.2):
            f = limit_cycle(variant, phi)
            print(f"| {variant} | {phi:g} | {f['rmse_m']:.4f} | {f['period_s']:.2f} | {f['autocorrelation']:.2f} | "
                  f"{f['e_z_amplitude_m']:.3f} | {f['tau_n_z_peak_to_peak']:.3f} | {f['pd_share_first_5s']:.2f} | "
                  f"{f['pd_share_last_10s']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
