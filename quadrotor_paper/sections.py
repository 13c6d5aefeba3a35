"""The paper's scenario sections: ``[wind]``, the shorthand for the WindGust
FMU's parameters, and ``[metrics]``, the signals the tracking error is taken
between; and how the rest of the application reads them.

``[wind]`` (every key optional)::

    fmu = "WindGust"                     # the FMU instance it configures
    speed = 3.0                          # m/s            -> v_w
    direction = [-1.0, -1.0, 0.0]        # 1, non-zero    -> dir_x, dir_y, dir_z
    switch_times = [17.0, 34.0]          # s, increasing  -> t_switch_1, t_switch_2
    ramp_time = 0.0                      # s              -> ramp_time
    turbulence = 0.0                     # m/s RMS        -> turbulence
    turbulence_seed = 0                  # int            -> turbulence_seed

``[metrics]``::

    position = ["Quadrotor.x", "Quadrotor.y", "Quadrotor.z"]
    reference = ["reference.x", "reference.y", "reference.z"]
    estimator = "Estimator"     # optional: the Estimator FMU instance whose estimate is measured
    settle = 5.0                # s: wind estimate judged this long after the start and each change

With ``estimator``, the study metrics add the estimate's consistency and
accuracy (:func:`quadrotor_paper.experiments.estimation_metrics`), against
the truth of the plant instance that ``position`` names.

Their declarations and how a validated one applies: :mod:`.section_tables`
(pydantic, imported when a scenario is validated).
"""
from __future__ import annotations

from cosim.scenario.definition import Scenario
from fmu_models.models.estimator_outputs import counts_of

__all__ = ["WIND_KEYS", "metric_signals", "estimation_spec"]

WIND_KEYS = {"speed": "v_w", "ramp_time": "ramp_time", "turbulence": "turbulence",
             "turbulence_seed": "turbulence_seed"}

def metric_signals(scenario: Scenario) -> tuple[list[str], list[str]]:
    """The position and reference signals of ``[metrics]`` (empty without it)."""
    metrics = scenario.sections.get("metrics", {})
    return list(metrics.get("position", [])), list(metrics.get("reference", []))


def estimation_spec(scenario: Scenario) -> tuple[str, str, float, tuple[str, ...]] | None:
    """``(estimator instance, truth instance, settle s, the estimator's
    counts)`` of ``[metrics]``, or ``None`` when it names no estimator. The
    counts are those its model outputs (:func:`counts_of`: the magnetometer's
    refusals too for the filter with the magnetometer)."""
    metrics = scenario.sections.get("metrics", {})
    if metrics.get("estimator") is None:
        return None
    model = scenario.fmus.get(metrics["estimator"], {}).get("model")
    return metrics["estimator"], metrics["position"][0].split(".")[0], float(metrics["settle"]), counts_of(model)
