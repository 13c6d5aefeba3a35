"""The project's FMU models as the engine's registered models
(:class:`cosim.scenario.registry.RegisteredModel`): the models of ``fmu_models``' catalog
and every controller variant's FMU, whole and split. A model is imported
(and its CasADi functions built) only when a scenario checks one of its
parameters or needs an FMU of it that is not built yet: an FMU already built
is found by the sources that define it (:func:`fmu_models.built.built_fmu`).
"""
from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Mapping

from cosim.scenario import registry

__all__ = ["fmu_model", "controller_fmu_model", "variant_sources"]


def fmu_model(identifier: str, load, sources=tuple) -> registry.RegisteredModel:
    """The model ``load()`` returns, registered as ``identifier``; imported
    (and built) only when a scenario checks one of its parameters or needs
    an FMU of it not built yet (:func:`fmu_models.built.built_fmu`;
    ``sources()``: the files beyond ``fmu_models`` and ``fnn_controller``
    that define it)."""

    def build(version: int):
        from fmu_models.built import built_fmu

        return built_fmu(identifier, version, load, sources())

    def check_parameter(name: str, value: float) -> None:
        model = load()
        try:
            var = model.variable(name)
        except KeyError:
            known = ", ".join(v.name for v in model.parameters + model.inputs)
            raise KeyError(f"{model.identifier} has no parameter {name!r}; parameters and inputs: {known}") from None
        if var.causality not in ("parameter", "input"):
            article = "an" if var.causality[0] in "aeiou" else "a"
            raise KeyError(f"{name!r} is {article} {var.causality} of {model.identifier}, not a parameter")
        var.check(value)

    def build_with(values: Mapping[str, float], version: int):
        # found by its sources and values as build's FMU is (an SSP export: 0.1-0.3 s of CPU an FMU to load
        # the model and generate its C again, CasADi imported)
        from fmu_models.built import built_fmu

        return built_fmu(identifier, version, lambda: load().with_defaults(values), sources(), values)

    return registry.RegisteredModel(identifier, build, check_parameter, build_with, definition=load)


def variant_sources(name: str) -> list[Path]:
    """The files of the modules that define variant ``name``'s laws (one
    registered outside ``fnn_controller`` changes its FMU by its own module)."""
    import sys

    from fnn_controller.variants import variant

    v = variant(name)
    modules = {f.__module__ for f in (v.axis_law, v.initial_axis, v.axis_state_bounds)}
    return [Path(sys.modules[m].__file__) for m in sorted(modules) if getattr(sys.modules.get(m), "__file__", None)]


def controller_fmu_model(name: str) -> registry.RegisteredModel:
    """The controller FMU of variant ``name`` as a registered model (built on demand)."""
    from fnn_controller.fmu_names import fmu_identifier

    return fmu_model(fmu_identifier(name), partial(_controller_model, name), partial(variant_sources, name))


def _controller_model(name: str):
    from fnn_controller.controller_fmu import controller_model  # CasADi: only to build the FMU

    return controller_model(name)
