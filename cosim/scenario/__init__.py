"""Scenarios: the TOML file a user writes, declared once with pydantic
(:mod:`.schema`, :mod:`.tables`) and loaded, checked and kept
(:mod:`.definition`: :func:`load_scenario`); the registry of component
kinds, sections, models and shipped files that packages register
(:mod:`.registry`); signal tables (:mod:`.signal_table`), SSV parameter sets
(:mod:`.parameter_set`: the file a scenario's ``parameter_set`` names) and
the assembly of a scenario into a master (:func:`build_master`).

May import the foundation modules, :mod:`cosim.fmi` and :mod:`cosim.loop`;
it knows no study, SSP archive or linearization.
"""
from ..surface import lazy_surface

_SURFACE = {
    "Scenario": "definition",
    "load_scenario": "definition",
    "parse_scenario": "definition",
    "apply_overrides": "definition",
    "shipped_scenarios": "definition",
    "scenario_path": "definition",
    "scenario_json_schema": "definition",
    "build_master": "assembly",
    "read_parameter_set": "parameter_set",
    "register_component_kind": "registry",
    "register_section": "registry",
    "register_fmu_model": "registry",
    "register_scenarios": "registry",
    "register_studies": "registry",
    "SignalTable": "signal_table",
}
__all__ = list(_SURFACE)
__getattr__, __dir__ = lazy_surface(__name__, _SURFACE)
