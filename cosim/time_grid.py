"""A run's time grid ``t_n = t0 + n h``: the rules every part of the engine
applies to it, written once with one tolerance (1e-9 relative, the
tolerance of our FMUs' own check of their period, ``fmu_core.c``'s
``sampled_step``):

* :func:`whole_steps`: a duration that is a whole number of steps;
* :func:`communication_point`: the step at which a time is a communication point;
* :func:`runs_at`: whether a sampled-data part of period ``T`` runs at step ``h``;
* :func:`seed_error`: what is wrong with a run's seed (an FMU's seed
  parameter is a double: every whole number up to 2^53 is exact).
"""
from __future__ import annotations

import math

from .limits import SEED_LIMIT

__all__ = ["TOLERANCE", "whole_steps", "communication_point", "runs_at", "seed_error"]

TOLERANCE = 1e-9  # relative


def whole_steps(duration: float, step: float) -> int | None:
    """The number ``n >= 1`` of steps of ``step`` s in ``duration`` s, or
    ``None`` where ``duration`` is no positive whole number of them."""
    n = round(duration / step) if math.isfinite(duration / step) else 0
    return n if n >= 1 and abs(n * step - duration) <= TOLERANCE * max(1.0, abs(duration)) else None


def communication_point(t: float, t0: float, h: float, n_steps: int) -> int | None:
    """``n`` with ``t = t0 + n h`` and ``0 <= n <= n_steps``: the step of a
    run at which time ``t`` is a communication point; ``None`` if it is none."""
    t = float(t)
    if not math.isfinite(t):
        return None
    n = round((t - t0) / h)
    return n if 0 <= n <= n_steps and abs(t0 + n * h - t) <= TOLERANCE * max(1.0, abs(t)) else None


def runs_at(step: float, period: float) -> bool:
    """Whether a master's communication ``step`` (s) is a sampled-data
    model's ``period`` (s). The one rule for every sampled-data part (an
    FMU's period parameter, the controller's ``position.dt``)."""
    return abs(step - period) <= TOLERANCE * abs(period)


def seed_error(seed) -> str | None:
    """Why ``seed`` is no run's seed (an integer in [0, 2^53]), or ``None``."""
    if isinstance(seed, bool) or not isinstance(seed, int) and not hasattr(seed, "__index__"):
        return f"expected an integer in [0, 2^53 = {SEED_LIMIT}]"
    if not 0 <= int(seed) <= SEED_LIMIT:
        return f"expected an integer in [0, 2^53 = {SEED_LIMIT}]"
    return None
