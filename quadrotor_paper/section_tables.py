"""The declarations of the ``[wind]`` and ``[metrics]`` sections
(:mod:`quadrotor_paper.sections` describes them) and how a validated one
applies to a scenario: imported when a scenario is validated (one served
from the cache needs neither, nor pydantic).
"""
from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import Field, model_validator

from cosim.errors import ScenarioError
from cosim.scenario.tables import check_fmu_parameters
from cosim.scenario.schema import NonNegative, NonNegativeInt, Strings, Table, numbers, refuse

from .sections import WIND_KEYS

__all__ = ["Wind", "Metrics", "apply_wind", "apply_metrics"]


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
