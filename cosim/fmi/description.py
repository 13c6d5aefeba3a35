"""What a modelDescription says, read for the master: its variables as
ports (types by their FMI 3.0 names, FMI 3.0 array shapes, units with
their definitions), which variables take a start value from an importer,
and the name of this project's sampled-data annotation. Pure functions of
fmpy's ``ModelDescription``: no FMU is loaded here."""
from __future__ import annotations

from typing import Mapping

from ..component import TYPES, Port
from .units import Unit, definitions as unit_definitions

__all__ = ["PERIOD_ANNOTATION", "TYPE_OF", "fmu_ports", "shape_of", "start_value_rule"]

# A sampled-data FMU declares the parameter that is its period, the one
# communication step it takes (docs/fmi-export.md, "Sampled-data period"):
#   FMI 2.0  <VendorAnnotations><Tool name="fnn-cosim.sampled-data"><SampledData periodParameter="dt"/>
#   FMI 3.0  <Annotations><Annotation type="fnn-cosim.sampled-data"><SampledData periodParameter="dt"/>
# The name is the exporter's (fmu_models.export.model_description), repeated
# here: the engine reads a declaration, it imports no exporter.
PERIOD_ANNOTATION = "fnn-cosim.sampled-data"

# FMI 2.0's types by their FMI 3.0 names: Real is a 64-bit float, Integer a
# 32-bit int (fmi2Integer); the FMI 3.0 names are themselves (cosim.component.TYPES)
TYPE_OF = {"Real": "Float64", "Integer": "Int32", **{t: t for t in TYPES}}


def start_value_rule(variable) -> str | None:
    """Why ``variable`` takes no start value from an importer, or ``None``
    if it does: an input, or a variable that is not a constant and whose
    ``initial`` is ``exact`` or ``approx`` (FMI 2.0 §2.2.7, FMI 3.0 §2.4.7.5;
    fmpy's ``settable_in_instantiated``), or one the standard lets an
    importer set in Initialization Mode (``settable_in_initialization_mode``)."""
    from fmpy.simulation import settable_in_initialization_mode, settable_in_instantiated

    if variable is None:
        return "is no variable of the FMU"
    if settable_in_instantiated(variable) or settable_in_initialization_mode(variable):
        return None
    if variable.variability == "constant":
        return "is a constant: the standard lets no importer set it"
    return (f"is a{'n' if variable.causality[0] in 'aeiou' else ''} {variable.causality} with initial = "
            f"{variable.initial}: the standard lets an importer set only inputs and variables whose initial is "
            f"exact or approx")


def shape_of(variable) -> tuple[int, ...]:
    """An FMI 3.0 array variable's sizes (``<Dimension start=..>`` or the
    start value of the structural parameter its ``valueReference`` names,
    FMI 3.0 section 2.4.7.8: the shape the FMU has when it is not configured
    otherwise); ``()`` for a scalar."""
    shape = []
    for d in getattr(variable, "dimensions", None) or ():
        size = d.start if d.start is not None else getattr(d.variable, "start", None)
        shape.append(int(size) if size is not None else 0)
    return tuple(shape)


def _port(variable, units: Mapping[str, "Unit"] | None = None) -> Port:
    """A variable as a port; its unit is its own ``unit`` or, failing that,
    its ``declaredType``'s (FMI 2.0 section 2.2.3, FMI 3.0 section 2.4.4),
    with the modelDescription's definition of it (``units``, by name)."""
    declared = getattr(variable, "declaredType", None)
    unit = getattr(variable, "unit", None) or getattr(declared, "unit", None) or None
    return Port(variable.name, unit, TYPE_OF.get(variable.type, variable.type), variable.description or "",
                shape=shape_of(variable), unit_definition=(units or {}).get(unit) if unit else None)


def fmu_ports(model_description) -> dict[str, tuple[Port, ...]]:
    """The variables of a modelDescription as ports, by causality.

    Keys: ``input``, ``output``, ``parameter`` (FMI 2.0 and 3.0 parameters,
    tunable or not), ``local`` (the local variables of type Float64 but the
    state derivatives, which are what a Model Exchange importer integrates),
    ``other`` (the rest: derivatives, independent, calculated parameters).
    """
    derivatives = {d.variable.name for d in model_description.derivatives}
    units = unit_definitions(model_description)
    groups: dict[str, list[Port]] = {"input": [], "output": [], "parameter": [], "local": [], "other": []}
    for v in model_description.modelVariables:
        if v.type == "Clock":  # a clock is no signal: the component activates it (FmuComponent.clock)
            key = "other"
        elif v.causality == "local":
            key = "local" if v.name not in derivatives and TYPE_OF.get(v.type) == "Float64" else "other"
        else:
            key = v.causality if v.causality in groups else "other"
        groups[key].append(_port(v, units))
    return {k: tuple(v) for k, v in groups.items()}
