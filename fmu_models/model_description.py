"""modelDescription.xml of a model, generated from its variable table.

The ModelStructure is read off the CasADi Jacobian: which states and inputs
each derivative and output depends on, and how (``constant`` where the
partial derivative is a number, ``fixed`` where it depends on parameters
only, ``dependent`` otherwise).
"""
from __future__ import annotations

from functools import lru_cache
from xml.sax.saxutils import quoteattr

import casadi as ca

from . import __version__
from .codegen import value_references
from .model import FmuModel
from .variables import UNITS

__all__ = ["fmi2_model_description", "derivative_unit", "dependency_kinds", "SOURCE_FILES_FMI2"]

SOURCE_FILES_FMI2 = ("fmu_core.c", "fmi2_functions.c", "model_generated.c")

_DERIVATIVE_UNIT = {"m": "m/s", "m/s": "m/s2", "rad": "rad/s", "rad/s": "rad/s2", "1": "1"}


def derivative_unit(unit: str) -> str:
    try:
        return _DERIVATIVE_UNIT[unit]
    except KeyError:
        raise ValueError(f"no derivative unit known for {unit!r}; add it to _DERIVATIVE_UNIT") from None


def _fmt(value: float) -> str:
    return repr(float(value))


@lru_cache(maxsize=None)
def dependency_kinds(model: FmuModel) -> dict[str, list[tuple[str, str]]]:
    """For each derivative ``der(name)`` and output: [(known name, kind)]."""
    s = model.symbols
    f = model.functions
    t, x, u, p = s["t"], s["x"], s["u"], s["p"]
    unknowns = ca.vertcat(f["ode"](t, x, u, p), f["out"](t, x, u, p))
    knowns = ca.vertcat(x, u)
    jac = ca.jacobian(unknowns, knowns)
    variable_part = ca.vertcat(t, x, u)
    known_names = [v.name for v in model.states + model.inputs]
    rows = [f"der({v.name})" for v in model.states] + [v.name for v in model.outputs]
    result: dict[str, list[tuple[str, str]]] = {}
    for r, row in enumerate(rows):
        result[row] = []
        for c, name in enumerate(known_names):
            if not jac.sparsity().has_nz(r, c):
                continue
            entry = jac[r, c]
            if ca.depends_on(entry, variable_part):
                kind = "dependent"
            elif ca.depends_on(entry, p):
                kind = "fixed"
            else:
                kind = "constant"
            result[row].append((name, kind))
    return result


def _unit_definitions(units: set[str]) -> str:
    lines = ["  <UnitDefinitions>"]
    for name in sorted(units):
        exps = " ".join(f'{k}="{e}"' for k, e in UNITS[name].items())
        lines.append(f'    <Unit name={quoteattr(name)}><BaseUnit {exps}/></Unit>' if exps
                     else f'    <Unit name={quoteattr(name)}><BaseUnit/></Unit>')
    lines.append("  </UnitDefinitions>")
    return "\n".join(lines)


def _used_units(model: FmuModel) -> set[str]:
    units = {v.unit for v in model.all_variables} | {"s"}
    units |= {derivative_unit(v.unit) for v in model.states}
    return units


def fmi2_model_description(model: FmuModel, guid: str) -> str:
    """FMI 2.0 modelDescription.xml: Model Exchange and Co-Simulation in one FMU."""
    refs = value_references(model)
    ordered = sorted(refs, key=refs.get)  # ModelVariables in value-reference order
    index = {name: i + 1 for i, name in enumerate(ordered)}  # 1-based, as FMI 2.0 counts
    by_name = {v.name: v for v in model.all_variables}

    sv = []
    for name in ordered:
        vr = refs[name]
        if name == "time":
            sv.append(f'    <ScalarVariable name="time" valueReference="{vr}" causality="independent" '
                      f'variability="continuous" description="simulation time"><Real unit="s"/></ScalarVariable>')
            continue
        if name.startswith("der("):
            state = by_name[name[4:-1]]
            sv.append(f'    <ScalarVariable name={quoteattr(name)} valueReference="{vr}" causality="local" '
                      f'variability="continuous" initial="calculated" '
                      f'description={quoteattr("time derivative of " + state.name)}>'
                      f'<Real unit={quoteattr(derivative_unit(state.unit))} derivative="{index[state.name]}"/>'
                      f'</ScalarVariable>')
            continue
        v = by_name[name]
        head = f'    <ScalarVariable name={quoteattr(v.name)} valueReference="{vr}" '
        desc = f"description={quoteattr(v.description)}"
        if v.causality in ("state", "output"):
            sv.append(head + f'causality="output" variability="continuous" initial="calculated" {desc}>'
                      f'<Real unit={quoteattr(v.unit)}/></ScalarVariable>')
        elif v.causality == "input":
            sv.append(head + f'causality="input" variability="continuous" {desc}>'
                      f'<Real unit={quoteattr(v.unit)} start="{_fmt(v.start)}"/></ScalarVariable>')
        else:
            bounds = "".join(f' {k}="{_fmt(b)}"' for k, b in (("min", v.min), ("max", v.max))
                             if b not in (float("inf"), -float("inf")))
            sv.append(head + f'causality="parameter" variability="fixed" initial="exact" {desc}>'
                      f'<Real unit={quoteattr(v.unit)} start="{_fmt(v.start)}"{bounds}/></ScalarVariable>')

    deps = dependency_kinds(model)

    def unknown(name: str, dependencies: list[tuple[str, str]]) -> str:
        idx = " ".join(str(index[k]) for k, _ in dependencies)
        kinds = " ".join(kind for _, kind in dependencies)
        return f'      <Unknown index="{index[name]}" dependencies="{idx}" dependenciesKind="{kinds}"/>'

    outputs = []
    for name in ordered:
        if name in by_name and by_name[name].causality == "state":
            outputs.append(unknown(name, [(name, "constant")]))  # a state as output: itself
        elif name in by_name and by_name[name].causality == "output":
            outputs.append(unknown(name, deps[name]))
    derivatives = [unknown(f"der({v.name})", deps[f"der({v.name})"]) for v in model.states]
    initial = [f'      <Unknown index="{index[name]}"/>' for name in ordered
               if name.startswith("der(") or (name in by_name and by_name[name].causality in ("state", "output"))]

    sources = "\n".join(f'      <File name="{f}"/>' for f in SOURCE_FILES_FMI2)
    capabilities = ('canGetAndSetFMUstate="true" canSerializeFMUstate="true" '
                    'providesDirectionalDerivative="true" canNotUseMemoryManagementFunctions="true"')
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{model.identifier}" guid="{guid}"
  description={quoteattr(model.description)}
  generationTool="fnn-cosim {__version__} with CasADi {ca.__version__}"
  variableNamingConvention="structured" numberOfEventIndicators="0">
  <ModelExchange modelIdentifier="{model.identifier}" {capabilities}>
    <SourceFiles>
{sources}
    </SourceFiles>
  </ModelExchange>
  <CoSimulation modelIdentifier="{model.identifier}" canHandleVariableCommunicationStepSize="true" {capabilities}>
    <SourceFiles>
{sources}
    </SourceFiles>
  </CoSimulation>
{_unit_definitions(_used_units(model))}
  <LogCategories>
    <Category name="logEvents" description="informational messages (with debug logging on)"/>
    <Category name="logStatusError" description="refused calls and values, failed steps (always logged)"/>
  </LogCategories>
  <DefaultExperiment startTime="0" stopTime="10" stepSize="0.01"/>
  <ModelVariables>
{chr(10).join(sv)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{chr(10).join(outputs)}
    </Outputs>
    <Derivatives>
{chr(10).join(derivatives)}
    </Derivatives>
    <InitialUnknowns>
{chr(10).join(initial)}
    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""
