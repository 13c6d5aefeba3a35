"""What the estimator FMU publishes beside its estimate, named once for the
model (:mod:`fmu_models.models.estimator`) and for whoever reads its
outputs (the application's metrics), without building it (no CasADi).

* :data:`COVARIANCE_BLOCKS`: the 3-state blocks whose full covariance is an
  output (the NEES per block, docs/estimation.md, E15);
* :func:`covariance_output`: the output holding the covariance of two
  states, ``var_<a>`` or ``cov_<a>_<b>`` (a before b in its block);
* :data:`COUNTS`: the gate's counts of refused measurements and restarts (E19-E21);
  :func:`counts_of` the counts of a model (the magnetometer's refusals,
  :data:`MAGNETOMETER_COUNTS`, in :data:`MAGNETOMETER_MODEL`'s only; the
  motion-capture attitude's, :data:`ATTITUDE_FIX_COUNTS`, in
  :data:`ATTITUDE_FIX_MODEL`'s).
"""
from __future__ import annotations

__all__ = ["ATTITUDE_FIX_COUNTS", "ATTITUDE_FIX_MODEL", "COVARIANCE_BLOCKS", "COUNTS", "MAGNETOMETER_COUNTS",
           "MAGNETOMETER_MODEL", "counts_of",
           "covariance_output"]

COVARIANCE_BLOCKS = {"position": ("x", "y", "z"), "velocity": ("u", "v", "w"), "attitude": ("phi", "theta", "psi"),
                     "wind": ("wind_x", "wind_y", "wind_z")}
COUNTS = ("outliers_fix", "outliers_acc", "resets_fix", "resets_acc")
# the filter with the magnetometer's correction (E24) is a model of its own, which also counts its refusals
MAGNETOMETER_MODEL = "EstimatorMag"
MAGNETOMETER_COUNTS = ("outliers_mag",)
# the filter with the motion capture's attitude (E29) is one too, and counts its refusals and restarts
ATTITUDE_FIX_MODEL = "EstimatorMocap"
ATTITUDE_FIX_COUNTS = ("outliers_attitude", "resets_attitude")
_MORE_COUNTS = {MAGNETOMETER_MODEL: MAGNETOMETER_COUNTS, ATTITUDE_FIX_MODEL: ATTITUDE_FIX_COUNTS}


def counts_of(model: str | None) -> tuple[str, ...]:
    """The counts the estimator model ``model`` (a registered model's name;
    ``None`` for an FMU file) outputs: :data:`COUNTS`, the magnetometer's
    refusals for :data:`MAGNETOMETER_MODEL` and the motion-capture attitude's
    refusals and restarts for :data:`ATTITUDE_FIX_MODEL`."""
    return COUNTS + _MORE_COUNTS.get(model, ())


def covariance_output(a: str, b: str, order: tuple[str, ...]) -> str:
    """The output holding the covariance of states ``a`` and ``b`` of one
    block (``order``: the block's states, in the model's order)."""
    if a == b:
        return f"var_{a}"
    a, b = sorted((a, b), key=order.index)
    return f"cov_{a}_{b}"
