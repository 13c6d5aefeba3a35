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
"""
from __future__ import annotations

import math
from typing import Any, Mapping

from cosim.config import check_number
from cosim.errors import ScenarioError
from cosim.scenario import Scenario, check_fmu_parameters, refuse_unknown, string, strings
from fnn_controller.variants import DEFAULT_VARIANT

__all__ = ["WIND_KEYS", "parse_wind", "parse_metrics", "wind_parameter", "metric_signals", "controller_variant"]

WIND_KEYS = {"speed": "v_w", "ramp_time": "ramp_time", "turbulence": "turbulence",
             "turbulence_seed": "turbulence_seed"}
_WIND = {"fmu", "direction", "switch_times", *WIND_KEYS}
_METRICS = {"position", "reference"}


def _direction(value: Any) -> dict[str, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise ScenarioError(f"wind.direction = {value!r}: expected a list of 3 numbers")
    d = [check_number(f"wind.direction[{i}]", v) for i, v in enumerate(value)]
    if math.hypot(*d) == 0:
        raise ScenarioError(f"wind.direction = {d!r}: must not be the zero vector")
    return dict(dir_x=d[0], dir_y=d[1], dir_z=d[2])


def _switch_times(value: Any) -> dict[str, float]:
    if not isinstance(value, list) or len(value) != 2:
        raise ScenarioError(f"wind.switch_times = {value!r}: expected a list of 2 times (s)")
    s = [check_number(f"wind.switch_times[{i}]", v, nonnegative=True) for i, v in enumerate(value)]
    if s[1] < s[0]:
        raise ScenarioError(f"wind.switch_times = {s!r}: the second switch must not come before the first")
    return dict(t_switch_1=s[0], t_switch_2=s[1])


def parse_wind(where: str, wind: Mapping[str, Any], fmus: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Set the WindGust FMU's parameters from ``[wind]``; returns ``{"fmu": instance}``."""
    refuse_unknown(f"{where}.", wind, _WIND)
    instance = string(f"{where}.fmu", wind.get("fmu", "WindGust"))
    if instance not in fmus:
        raise ScenarioError(f"{where}.fmu = {instance!r}: no such FMU in [fmus]; FMUs: {', '.join(fmus)}")
    params = fmus[instance]["parameters"]
    for key, target in WIND_KEYS.items():
        if key in wind:
            params[target] = check_number(f"{where}.{key}", wind[key], nonnegative=True,
                                          integer=key == "turbulence_seed")
    if "direction" in wind:
        params.update(_direction(wind["direction"]))
    if "switch_times" in wind:
        params.update(_switch_times(wind["switch_times"]))
    check_fmu_parameters(f"fmus.{instance}.parameters (from [{where}])", fmus[instance], params)
    return {"fmu": instance}


def parse_metrics(where: str, metrics: Mapping[str, Any], fmus) -> dict[str, list[str]]:
    refuse_unknown(f"{where}.", metrics, _METRICS)
    position = strings(f"{where}.position", metrics.get("position", []))
    reference = strings(f"{where}.reference", metrics.get("reference", []))
    if len(position) != len(reference):
        raise ScenarioError(f"{where}: position has {len(position)} signals but reference has {len(reference)}")
    return {"position": position, "reference": reference}


def wind_parameter(scenario: Scenario, key: str = "speed") -> str:
    """The run-level parameter name (``Fmu.var``) of a ``[wind]`` key."""
    wind = scenario.sections.get("wind")
    if wind is None:
        raise ScenarioError(f"scenario {scenario.name!r} has no [wind] section")
    return f"{wind['fmu']}.{WIND_KEYS[key]}"


def metric_signals(scenario: Scenario) -> tuple[list[str], list[str]]:
    """The position and reference signals of ``[metrics]`` (empty without it)."""
    metrics = scenario.sections.get("metrics", {})
    return list(metrics.get("position", [])), list(metrics.get("reference", []))


def controller_variant(scenario: Scenario, instance: str = "controller") -> str | None:
    """The variant the scenario's controller flies (``None`` without one)."""
    spec = scenario.components.get(instance)
    if spec is None or spec.get("kind") != "fnn_controller":
        return None
    return spec["parameters"].get("variant", DEFAULT_VARIANT)
