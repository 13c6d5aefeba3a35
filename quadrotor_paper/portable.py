"""The paper's missions with every component an FMU, for tools that run FMUs
only (SSP archives, libcosim): each component moves to ``[fmus]`` as the FMU
its kind builds (:func:`quadrotor_paper.components.fmu_entry`: the
trajectory's reference FMU, the controller FMU of its variant, FMI 2.0, which
libcosim runs), so the loop flies exactly as the scenario does (``docs/ssp.md``).
"""
from __future__ import annotations

from cosim.scenario import registry
from cosim.scenario.registry import BuildContext
from cosim.scenario.definition import Scenario, parse_scenario
from cosim.scenario.assembly import fmu_file

__all__ = ["all_fmu"]


def all_fmu(scenario: Scenario) -> Scenario:
    """``scenario`` with its components as FMUs; a component with no FMU form
    is refused, naming it."""
    from cosim.fmi.fmu import FmuComponent

    from .components import fmu_entry

    # the controller's nominal vehicle reads the plant's parameters, as when it is built for a run
    context = BuildContext(scenario, {n: FmuComponent(n, fmu_file(s)) for n, s in scenario.fmus.items()})
    document = scenario.raw  # a new document: the scenario is immutable, and workers read documents
    for name, spec in scenario.components.items():
        document["fmus"][name] = fmu_entry(name, spec, context)
        document.get("components", {}).pop(name, None)
    for alias, kinds in registry.aliases().items():
        if (kinds[0].instance or alias) in scenario.components:
            document.pop(alias, None)
    if not document.get("components", True):
        del document["components"]
    return parse_scenario(document, source=scenario.source, name=scenario.name)
