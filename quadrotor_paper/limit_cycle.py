"""The z-axis limit cycle of the learning laws, with and without a boundary
layer: ``python -m quadrotor_paper.limit_cycle`` prints, for PD+SMC-FNN and
PD+LM-FNN on the circles mission (3 m/s gust, seed 0), the RMSE and, over the
last 20 s, the period of tau_n,z (autocorrelation), the amplitude of e_z, the
peak-to-peak of tau_n,z, and the PD's share in z in the first 5 s and the last
10 s, for boundary layers phi = 0 (the paper's sgn), 0.05, 0.1, 0.2 m/s
(docs/results.md). The runs are one study (variant x phi), run by the engine."""
from __future__ import annotations

import sys

import numpy as np

from cosim.study.definition import Study, parse_study
from fnn_controller.variants import variants

from .experiments import measure
from .metrics import oscillation_period, pd_share, rmse

__all__ = ["study", "limit_cycle", "main", "FIGURES"]

_POSITION = ["Quadrotor.x", "Quadrotor.y", "Quadrotor.z"]
_REFERENCE = ["reference.x", "reference.y", "reference.z"]
# the type-1 FNN's learning variants (the paper's two)
VARIANTS = tuple(v.name for v in variants().values() if v.fnn == "type1" and v.training is not None)
PHIS = (0.0, 0.05, 0.1, 0.2)  # m/s, on every axis
LATE = 20.0  # s: the limit cycle's window, the end of the mission
FIGURES = ("rmse_m", "period_s", "autocorrelation", "e_z_amplitude_m", "tau_n_z_peak_to_peak",
           "pd_share_first_5s", "pd_share_last_10s")


def study(variants=VARIANTS, phis=PHIS) -> Study:
    """Variant x boundary layer on the circles, seed 0."""
    return parse_study({"scenario": "circles", "name": "limit_cycle", "sweep": {"seeds": [0], "grid": {
        "controller.variant": list(variants), "controller.position.phi": [[phi] * 3 for phi in phis]}}})


def limit_cycle(sc, run) -> dict[str, float]:
    """The figures of one run (a study's metrics function)."""
    t, late = run.time, run.time >= sc.duration - LATE
    e_z = run["reference.z"] - run["Quadrotor.z"]
    tau_n, tau_c = run["controller.tau_n_z"], run["controller.tau_c_z"]
    period, height = oscillation_period(tau_n[late], sc.step)
    share = pd_share(tau_c, tau_n)
    return {"rmse_m": rmse(run, _POSITION, _REFERENCE), "period_s": period, "autocorrelation": height,
            "e_z_amplitude_m": float(np.ptp(e_z[late]) / 2), "tau_n_z_peak_to_peak": float(np.ptp(tau_n[late])),
            "pd_share_first_5s": float(share[t < 5].mean()), "pd_share_last_10s": float(share[t >= t[-1] - 10].mean())}


def main() -> int:
    rows = measure(study(), metrics=limit_cycle, metric_names=FIGURES,
                   record=_POSITION + _REFERENCE + ["controller.tau_c_z", "controller.tau_n_z"]).rows
    print("| variant | phi (m/s) | RMSE (m) | period of tau_n,z (s) | its autocorrelation | e_z amplitude (m) "
          "| tau_n,z peak to peak (m/s) | PD share in z, first 5 s | last 10 s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for f in rows:
        print(f"| {f['controller.variant']} | {f['controller.position.phi'][0]:g} | {f['rmse_m']:.4f} | "
              f"{f['period_s']:.2f} | {f['autocorrelation']:.2f} | {f['e_z_amplitude_m']:.3f} | "
              f"{f['tau_n_z_peak_to_peak']:.3f} | {f['pd_share_first_5s']:.2f} | {f['pd_share_last_10s']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
