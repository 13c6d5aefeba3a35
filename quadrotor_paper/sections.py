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
"""
from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import Field, model_validator

from cosim.errors import ScenarioError
from cosim.scenario import Scenario, check_fmu_parameters
from cosim.schema import NonNegative, NonNegativeInt, Strings, Table, numbers, refuse
from fmu_models.models.estimator_outputs import counts_of

__all__ = ["WIND_KEYS", "Wind", "Metrics", "apply_wind", "apply_metrics", "metric_signals", "estimation_spec"]

WIND_KEYS = {"speed": "v_w", "ramp_time": "ramp_time", "turbulence": "turbulence",
             "turbulence_seed": "turbulence_seed"}


class Wind(Table):
    """``[wind]``: the WindGust FMU's parameters by the paper's names (section 5.3)."""

    fmu: Annotated[str, Field(strict=True)] = Field("WindGust", description="the FMU instance it configures")
    speed: NonNegative = Field(None, description="gust speed v_w [m/s]")
    direction: numbers(3, "numbers") = Field(None, description="gust direction (normalized; not zero)")
    switch_times: numbers(2, "times (s)", ge=0.0) = Field(
        None, description="the gust reverses at the first and back at the second [s], in order")
    ramp_time: NonNegative = Field(None, description="duration of each reversal [s] (0: a step)")
    turbulence: NonNegative = Field(None, description="turbulence RMS [m/s]")
    turbulence_seed: NonNegativeInt = Field(None, description="seed of the turbulence")

    @model_validator(mode="after")
    def _physical(self):
        if self.direction is not None and math.hypot(*self.direction) == 0:
            raise refuse("must not be the zero vector", key="direction", value=self.direction)
        if self.switch_times is not None and self.switch_times[1] < self.switch_times[0]:
            raise refuse("the second switch must not come before the first", key="switch_times",
                         value=self.switch_times)
        return self


def apply_wind(where: str, wind: Wind, fmus: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Set the WindGust FMU's parameters from ``[wind]``; returns ``{"fmu": instance}``."""
    if wind.fmu not in fmus:
        raise ScenarioError(f"{where}.fmu = {wind.fmu!r}: no such FMU in [fmus]; FMUs: {', '.join(fmus)}")
    params: dict[str, float] = {}
    for key, target in WIND_KEYS.items():
        if key in wind.model_fields_set:
            params[target] = getattr(wind, key)
    if "direction" in wind.model_fields_set:
        params.update(dict(zip(("dir_x", "dir_y", "dir_z"), wind.direction)))
    if "switch_times" in wind.model_fields_set:
        params.update(dict(zip(("t_switch_1", "t_switch_2"), wind.switch_times)))
    check_fmu_parameters(f"fmus.{wind.fmu}.parameters (from [{where}])", fmus[wind.fmu], params)
    fmus[wind.fmu]["parameters"].update(params)
    return {"fmu": wind.fmu}


class Metrics(Table):
    """``[metrics]``: the signals the tracking error is taken between."""

    position: Strings = Field(default_factory=list, description="the vehicle's position signals")
    reference: Strings = Field(default_factory=list, description="the reference's, in the same order")
    estimator: Annotated[str, Field(strict=True)] = Field(
        None, description="the Estimator FMU instance whose estimate is measured (NEES, NIS, RMSE)")
    settle: NonNegative = Field(5.0, description="time after the start and after each change of the true wind "
                                                 "before the wind estimate is judged [s]")

    @model_validator(mode="after")
    def _pairs(self):
        if len(self.position) != len(self.reference):
            raise refuse(f"position has {len(self.position)} signals but reference has {len(self.reference)}")
        return self


def apply_metrics(where: str, metrics: Metrics, fmus) -> dict[str, Any]:
    out: dict[str, Any] = {"position": list(metrics.position), "reference": list(metrics.reference)}
    if metrics.estimator is not None:
        if metrics.estimator not in fmus:
            raise ScenarioError(f"{where}.estimator = {metrics.estimator!r}: no such FMU in [fmus]; "
                                f"FMUs: {', '.join(fmus)}")
        if not metrics.position:
            raise ScenarioError(f"{where}.estimator = {metrics.estimator!r}: needs position (the truth's instance)")
        out.update(estimator=metrics.estimator, settle=metrics.settle)
    return out


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
