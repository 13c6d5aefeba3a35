"""Feed-forward on the circles mission: ``python -m quadrotor_paper.feed_forward``
prints, for the option rows with feed-forward (:mod:`quadrotor_paper.options`)
and the best one without its acceleration term and with the default tilt
limit, the RMSE at 1, 3 and 5 m/s
(seed 0, one setting for every wind), and at 3 m/s where the squared error
sits: the first 3 s (the reference leaves hover at 2.5 m/s at t = 0), the
6 s around each gust reversal (17 s, 34 s), the rest; the RMSE from 3 s on;
the largest error (docs/results.md). The runs are one study (a case per
row, the wind speeds its grid), run by the engine like every other."""
from __future__ import annotations

import sys
from typing import Any, Mapping

import numpy as np

from cosim.study.definition import Study, parse_study
from fmu_models.catalog import model
from fnn_controller import GeometricParams

from .experiments import measure
from .metrics import euclidean_error, rmse
from .sections import metric_signals
from .options import OPTIONS

__all__ = ["ROWS", "study", "error_budget", "main"]

TILT_MAX_DEFAULT = GeometricParams().tilt_max  # rad: the default the best row's 45 degrees replaces
ROWS: tuple[tuple[str, Mapping[str, Any]], ...] = (  # (option, extra overrides): the ablation of the best row
    ("pd-ff", {}), ("pd-ff-acc", {}), ("lm-ff-bl", {}), ("lm-ff-acc-bl", {}), ("lm-best", {}),
    ("lm-best", {"controller.position.accel_feedforward": 0.0}),
    ("lm-best", {"controller.geometric.tilt_max": TILT_MAX_DEFAULT}),
)
WINDS = (1.0, 3.0, 5.0)  # m/s
BUDGET_WIND = 3.0  # m/s: where the error budget is printed
START = 3.0  # s: the start transient
REVERSAL = 3.0  # s either side of a gust reversal
FIGURES = ("rmse_m", "start", "reversals", "rest", "rmse_after_start", "max")


def _shown(extra: Mapping[str, Any]) -> str:
    return ", ".join(f"{k.rpartition('.')[2]} = {v:g}" for k, v in extra.items()) or "–"


def study() -> Study:
    """The rows as cases (an option's overrides and connections, then the
    row's extra overrides), the wind speeds as the grid, seed 0."""
    cases = {}
    for name, extra in ROWS:
        opt = OPTIONS[name]
        cases[f"{name} ({_shown(extra)})"] = {"set": {**opt.overrides, **extra}, "connect": list(opt.connect),
                                              "label": name}
    return parse_study({"scenario": "circles", "name": "feed_forward", "cases": cases,
                        "sweep": {"seeds": [0], "grid": {"wind.speed": list(WINDS)}}})


def error_budget(sc, result) -> dict[str, float]:
    """Shares of the integral of e² (m²s): start, reversals, rest; RMSE after
    the start; max error; and the RMSE (a study's metrics function)."""
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
    return {"rmse_m": rmse(result, position, reference), "start": float(np.sum(e[start] ** 2)) / total,
            "reversals": float(np.sum(e[reversal] ** 2)) / total, "rest": float(np.sum(e[~start & ~reversal] ** 2)) / total,
            "rmse_after_start": float(np.sqrt(np.mean(e[~start] ** 2))), "max": float(e.max())}


def main() -> int:
    rows = measure(study(), metrics=error_budget, metric_names=FIGURES).rows
    print("| option | variant | extra | RMSE 1 / 3 / 5 m/s (m) | at 3 m/s: e² in first 3 s | around reversals "
          "| rest | RMSE from 3 s (m) | max error (m) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for (name, extra), case in zip(ROWS, dict.fromkeys(r["case"] for r in rows)):
        mine = [r for r in rows if r["case"] == case]
        budget = next(r for r in mine if r["wind.speed"] == BUDGET_WIND)
        values = " / ".join(f"{r['rmse_m']:.3f}" for r in mine)
        print(f"| {name} | {OPTIONS[name].overrides['controller.variant']} | {_shown(extra)} | {values} | "
              f"{budget['start']:.2f} | {budget['reversals']:.2f} | {budget['rest']:.2f} | "
              f"{budget['rmse_after_start']:.3f} | {budget['max']:.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
