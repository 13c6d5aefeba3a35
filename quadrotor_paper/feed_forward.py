"""Feed-forward on the circles mission: ``python -m quadrotor_paper.feed_forward``
prints, for the option rows with feed-forward (:mod:`quadrotor_paper.options`)
and the best one without its acceleration term and with the default tilt
limit, the RMSE at 1, 3 and 5 m/s
(seed 0, one setting for every wind), and at 3 m/s where the squared error
sits: the first 3 s (the reference leaves hover at 2.5 m/s at t = 0), the
6 s around each gust reversal (17 s, 34 s), the rest; the RMSE from 3 s on;
the largest error (docs/results.md)."""
from __future__ import annotations

import sys
from typing import Any, Mapping

import numpy as np

from cosim.scenario import build_master, load_scenario
from fmu_models.catalog import model
from fnn_controller import GeometricParams

from .metrics import euclidean_error, rmse
from .missions import metric_signals
from .options import OPTIONS, Option, scenario_overrides

__all__ = ["ROWS", "fly", "error_budget", "main"]

TILT_MAX_DEFAULT = GeometricParams().tilt_max  # rad: the default the best row's 45 degrees replaces
ROWS: tuple[tuple[str, Mapping[str, Any]], ...] = (  # (option, extra overrides): the ablation of the best row
    ("pd-ff", {}), ("pd-ff-acc", {}), ("lm-ff-bl", {}), ("lm-ff-acc-bl", {}), ("lm-best", {}),
    ("lm-best", {"controller.position.accel_feedforward": 0.0}),
    ("lm-best", {"controller.geometric.tilt_max": TILT_MAX_DEFAULT}),
)
START = 3.0  # s: the start transient
REVERSAL = 3.0  # s either side of a gust reversal


def fly(opt: Option, wind: float, extra: Mapping[str, Any] | None = None, seed: int = 0):
    """One circles run of ``opt`` (and ``extra`` overrides) at ``wind`` m/s: (scenario, result)."""
    base = load_scenario("circles")
    position, reference = metric_signals(base)
    overrides = {**scenario_overrides(opt, base), **(extra or {}), "controller.variant": opt.variant,
                 "wind.speed": wind, "record.signals": position + reference}
    sc = load_scenario("circles", overrides)
    with build_master(sc) as master:
        return sc, master.run(sc.duration, seed=seed)


def error_budget(sc, result) -> dict[str, float]:
    """Shares of the integral of e² (m²s): start, reversals, rest; RMSE after the start; max error."""
    position, reference = metric_signals(sc)
    e, t = euclidean_error(result, position, reference), result.time
    gust = sc.sections["wind"]["fmu"]
    switches = [sc.fmus[gust]["parameters"].get(k, model(sc.fmus[gust]["model"]).variable(k).start)
                for k in ("t_switch_1", "t_switch_2")]
    start = t < START
    reversal = np.zeros_like(start)
    for ts in switches:
        reversal |= np.abs(t - ts) < REVERSAL
    reversal &= ~start
    total = float(np.sum(e ** 2))
    return {"start": float(np.sum(e[start] ** 2)) / total, "reversals": float(np.sum(e[reversal] ** 2)) / total,
            "rest": float(np.sum(e[~start & ~reversal] ** 2)) / total,
            "rmse_after_start": float(np.sqrt(np.mean(e[~start] ** 2))), "max": float(e.max())}


def main() -> int:
    print("| option | variant | extra | RMSE 1 / 3 / 5 m/s (m) | at 3 m/s: e² in first 3 s | around reversals "
          "| rest | RMSE from 3 s (m) | max error (m) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, extra in ROWS:
        opt = OPTIONS[name]
        values, budget = [], {}
        for wind in (1.0, 3.0, 5.0):
            sc, result = fly(opt, wind, extra)
            values.append(rmse(result, *metric_signals(sc)))
            if wind == 3.0:
                budget = error_budget(sc, result)
        shown = ", ".join(f"{k.rpartition('.')[2]} = {v:g}" for k, v in extra.items()) or "–"
        print(f"| {name} | {opt.variant} | {shown} | {' / '.join(f'{v:.3f}' for v in values)} | "
              f"{budget['start']:.2f} | {budget['reversals']:.2f} | {budget['rest']:.2f} | "
              f"{budget['rmse_after_start']:.3f} | {budget['max']:.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
