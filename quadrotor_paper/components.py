"""What the paper's application adds to the engine's registry: the FMU models
of ``fmu_models``, the trajectories and the flight controller as component
kinds (with their short sections ``[trajectory]`` and ``[controller]``), the
``[wind]`` and ``[metrics]`` sections, the cases studies name (a case per
controller variant, the option rows) and the shipped scenarios.

Both kinds build FMUs: a ``[trajectory]`` is its reference FMU
(``ReferenceTwoCircles``, ...) with the trajectory's parameters, a
``[controller]`` the controller FMU of its variant (unless ``form =
"python"``), so a shipped mission is FMUs only and runs in the master's
compiled loop. :func:`fmu_entry` states each as an ``[fmus]`` entry, which is
what the component is built from and what an all-FMU scenario
(:mod:`quadrotor_paper.portable`) lists.

:func:`register` runs when :mod:`quadrotor_paper` is imported, and through
the ``cosim.plugins`` entry point whenever the engine reads a scenario.
Nothing heavy is imported here: the builders import what they build.
"""
from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any, Mapping

from cosim.scenario import registry
from cosim.errors import ScenarioError

from .models import controller_fmu_model, fmu_model, variant_sources

__all__ = ["register", "fmu_entry", "TRAJECTORY_INSTANCE", "CONTROLLER_INSTANCE"]

TRAJECTORY_INSTANCE = "reference"
CONTROLLER_INSTANCE = "controller"


def _trajectory_table(name: str):
    """The declaration of a trajectory's table: its dataclass's fields (the
    reference FMU's parameters, whose ranges the dataclass checks)."""
    from cosim.scenario.schema import dataclass_table

    from .trajectories import TRAJECTORIES

    return dataclass_table(TRAJECTORIES[name])


def _trajectory_kind(name: str) -> registry.ComponentKind:
    def build(instance: str, params: Mapping[str, Any], context) -> Any:
        from cosim.fmi.fmu import FmuComponent
        from cosim.scenario.assembly import fmu_file

        entry = _trajectory_entry(name, params)
        return FmuComponent(instance, fmu_file(entry), parameters=entry["parameters"])

    return registry.ComponentKind(name, build, partial(_trajectory_table, name),
                                  f"reference trajectory {name} (its reference FMU)",
                                  alias="trajectory", instance=TRAJECTORY_INSTANCE)


def _trajectory_entry(kind: str, params: Mapping[str, Any]) -> dict[str, Any]:
    """The reference FMU of a trajectory of ``kind`` (FMI 2.0), the given
    parameters by their FMU names, the values the trajectory checked."""
    from .trajectories import make_trajectory

    trajectory = make_trajectory(kind, **{k: float(v) for k, v in params.items()})
    return {"model": trajectory.model.identifier, "fmi_version": 2,
            "parameters": {trajectory.fmu_name(k): getattr(trajectory, k) for k in params}}


def fmu_entry(instance: str, spec: Mapping[str, Any], context) -> dict[str, Any]:
    """The ``[fmus]`` entry (model, FMI version, parameters, seed parameter)
    a scenario's component ``instance`` (``spec``: its kind and parameters)
    runs as: its reference FMU for a trajectory, the controller FMU for the
    controller (FMI 2.0 whatever its ``form``; ``context`` gives the plant
    its nominal vehicle is taken from). Any other component has no FMU: a
    one-line :class:`~cosim.errors.ScenarioError` naming it."""
    from .trajectories import TRAJECTORIES

    kind, params = spec.get("kind"), spec.get("parameters", {})
    if kind in TRAJECTORIES:
        return _trajectory_entry(kind, params)
    if kind == "signal_table":  # the engine's table, as its table FMU with the table inside
        from cosim.scenario.signal_table import fmu_entry as table_entry

        return table_entry(instance, params, context, registry.table_fmu())
    if kind == "fnn_controller":
        from .controller_component import ControllerComponent

        python = {k: v for k, v in params.items() if k not in ("form", "fmi_version")}
        return ControllerComponent.from_parameters(instance, {**python, "form": "python"}, context).fmu_entry(2)
    raise ScenarioError(f"components.{instance}: a {kind or spec.get('factory')!r} component has no FMU form; "
                        f"an all-FMU scenario (SSP) cannot hold it")


def _controller_table():
    from .controller_component import controller_table

    return controller_table()


def _controller_kind() -> registry.ComponentKind:
    def build(instance: str, params: Mapping[str, Any], context) -> Any:
        from .controller_component import ControllerComponent

        # a scenario's [controller] values, validated with the whole document: read as they are
        return ControllerComponent.from_parameters(instance, params, context, validated=True)

    return registry.ComponentKind("fnn_controller", build, _controller_table,
                                  "PD + FNN position control and geometric velocity control (paper Fig. 2)",
                                  alias="controller", instance=CONTROLLER_INSTANCE)


def _split_model(which: str, *args):
    """A loop of the split controller (:mod:`fnn_controller.split`), imported when first asked for."""
    from fnn_controller import split

    return getattr(split, which)(*args)


_registered = False


def register() -> None:
    """Register the models, kinds, sections and scenarios (once per process)."""
    global _registered
    if _registered:
        return
    _registered = True
    from fmu_models.cache import cache_root
    from fmu_models.catalog import MODEL_NAMES, model as catalog_model
    from fnn_controller.variants import variant_names

    from fnn_controller.fmu_names import INNER_IDENTIFIER, outer_identifier

    from .trajectories import TRAJECTORIES

    for identifier in MODEL_NAMES:
        registry.register_fmu_model(fmu_model(identifier, partial(catalog_model, identifier)))
    for name in variant_names():  # the controller of each variant as an FMU, whole and as its outer loop
        registry.register_fmu_model(controller_fmu_model(name))
        registry.register_fmu_model(fmu_model(outer_identifier(name), partial(_split_model, "outer_model", name),
                                              partial(variant_sources, name)))
    registry.register_fmu_model(fmu_model(INNER_IDENTIFIER, partial(_split_model, "inner_model")))  # its inner loop, for every variant
    for name in TRAJECTORIES:
        registry.register_component_kind(_trajectory_kind(name))
    registry.register_component_kind(_controller_kind())
    registry.register_cases(_cases)
    registry.register_section(registry.Section("wind", partial(_section, "Wind"), partial(_section, "apply_wind"),
                                               "shorthand for the WindGust FMU's parameters"))
    registry.register_section(registry.Section("metrics", partial(_section, "Metrics"),
                                               partial(_section, "apply_metrics"), "signals of the tracking error"))
    registry.register_scenarios(Path(__file__).parent / "scenarios")
    registry.register_studies(Path(__file__).parent / "studies")
    registry.register_table_fmu(_table_fmu)
    registry.register_cache(cache_root)  # the FMUs' cache folder also keeps the engine's derived data


def _cases() -> list[registry.Case]:
    """A case per variant (a table's row), then the option rows (:mod:`.options`,
    imported when a study first reads the cases)."""
    from fnn_controller.variants import variant_names

    from .options import OPTIONS, variant_case

    return [*(variant_case(name) for name in variant_names()), *OPTIONS.values()]


def _section(name: str, *args):
    """A name of :mod:`.section_tables` (the sections' tables, their
    appliers), called with ``args``, or itself without: imported when a
    scenario's sections are first declared or applied (a scenario served
    from the cache needs neither)."""
    from . import section_tables

    value = getattr(section_tables, name)
    return value(*args) if args else value


def _table_fmu(table, fmi_version: int) -> Path:
    """The engine's signal table as an FMU (fmu_models' generic table FMU)."""
    from fmu_models.models.signal_table import build_table_fmu

    return build_table_fmu(table, fmi_version)
