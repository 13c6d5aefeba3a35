"""The paper's missions with every component an FMU, for tools that run FMUs
only (SSP archives, libcosim): the trajectory becomes its reference FMU
(``ReferenceTwoCircles``, ...) and the controller its controller FMU
(``ControllerPDLM``, ...), with the same parameter values (the controller's
nominal vehicle tied to the plant, its seed bound to the run's seed), so the
loop flies exactly as it does with the Python components (``docs/ssp.md``).
"""
from __future__ import annotations

import copy

from cosim.errors import ScenarioError
from cosim.registry import BuildContext
from cosim.scenario import Scenario, fmu_file

__all__ = ["all_fmu", "REFERENCE_MODELS"]

# trajectory kind -> (reference FMU, the FMU's name of each field that differs)
REFERENCE_MODELS = {
    "hover": ("ReferenceHover", {"x": "x0", "y": "y0", "z": "z0"}),
    "two_circles": ("ReferenceTwoCircles", {}),
    "figure_eight": ("ReferenceFigureEight", {}),
}


def _reference(spec: dict) -> dict:
    model, renamed = REFERENCE_MODELS[spec["kind"]]
    params = {renamed.get(k, k): float(v) for k, v in spec["parameters"].items()}
    return {"model": model, "fmi_version": 2, "parameters": params}


def _controller(name: str, spec: dict, scenario: Scenario) -> dict:
    from cosim.fmu_component import FmuComponent
    from fnn_controller.controller_fmu import fmu_identifier
    from fnn_controller.parametric import parameter_table

    from .controller_component import ControllerComponent

    # the controller's nominal vehicle reads the plant's parameters, as when it is built for a run
    fmus = {n: FmuComponent(n, fmu_file(s)) for n, s in scenario.fmus.items()}
    params = {k: v for k, v in spec["parameters"].items() if k not in ("form", "fmi_version")}
    component = ControllerComponent.from_parameters(name, params, BuildContext(scenario, fmus))
    values = {p.name: p.default for p in parameter_table(component.default_variant, component.position,
                                                          component.geometric)}
    return {"model": fmu_identifier(component.default_variant), "fmi_version": 2,
            "parameters": {**values, "psi_ref": component.psi_ref}, "seed_parameter": "seed"}


def all_fmu(scenario: Scenario) -> Scenario:
    """``scenario`` with its trajectory and controller as FMUs (FMI 2.0, which
    libcosim runs); any other Python component is refused, naming it."""
    out = copy.deepcopy(scenario)
    for name, spec in scenario.components.items():
        kind = spec.get("kind")
        if kind in REFERENCE_MODELS:
            out.fmus[name] = _reference(spec)
        elif kind == "fnn_controller":
            out.fmus[name] = _controller(name, spec, scenario)
        else:
            raise ScenarioError(f"components.{name}: a {kind or spec.get('factory')!r} component has no FMU form; "
                                f"an all-FMU scenario (SSP) cannot hold it")
        del out.components[name]
    return out
