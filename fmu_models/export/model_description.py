"""modelDescription.xml (FMI 2.0 and 3.0) and the FMI 3.0 buildDescription.xml
of a model, generated from its variable table.

The ModelStructure is read off the CasADi Jacobian: which states and inputs
each derivative and output depends on, and how (``constant`` where the
partial derivative is a number, ``fixed`` where it depends on parameters
only, ``dependent`` otherwise).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Mapping
from xml.sax.saxutils import quoteattr

from fmu_models.lazy_casadi import ca

from .. import __version__
from .codegen import value_references
from .model import FmuModel
from .variables import UNITS

__all__ = ["fmi2_model_description", "fmi3_model_description", "fmi3_build_description",
           "derivative_unit", "dependency_kinds", "clock_reference", "SOURCE_FILES_FMI2", "SOURCE_FILES_FMI3",
           "PERIOD_ANNOTATION", "CLOCK_NAME"]

SOURCE_FILES_FMI2 = ("fmu_core.c", "numpy_random.c", "signal_table.c", "fmi2_functions.c", "model_generated.c",
                     "model_start.c")
SOURCE_FILES_FMI3 = ("fmu_core.c", "numpy_random.c", "signal_table.c", "fmi3_functions.c", "model_generated.c",
                     "model_start.c")

_DERIVATIVE_UNIT = {"m": "m/s", "m/s": "m/s2", "rad": "rad/s", "rad/s": "rad/s2", "1": "1"}


def derivative_unit(unit: str) -> str:
    try:
        return _DERIVATIVE_UNIT[unit]
    except KeyError:
        raise ValueError(f"no derivative unit known for {unit!r}; add it to _DERIVATIVE_UNIT") from None


# A sampled-data model's declaration of its period, for tools (docs/fmi-export.md,
# "Sampled-data period"): the FMI 2.0 <VendorAnnotations><Tool name=...> and the
# FMI 3.0 <Annotations><Annotation type=...> of this name hold
# <SampledData periodParameter="..."/>, the parameter whose value is the one
# communication step the FMU takes. cosim.fmi.fmu reads it (by the same
# name: the engine does not import the exporter).
PERIOD_ANNOTATION = "fnn-cosim.sampled-data"


# The periodic input clock of a sampled-data model in FMI 3.0 (docs/fmi-export.md,
# "Clocks"): it ticks every sample period from the start time; the outputs and
# discrete states are clocked by it. Its value reference is the one after the
# Float64 variables (VR_CLOCK in fmu_core.h).
CLOCK_NAME = "sample_clock"


def clock_reference(model: FmuModel) -> int:
    """The value reference of a sampled-data model's :data:`CLOCK_NAME` (FMI 3.0)."""
    if model.sampled is None:
        raise ValueError(f"model {model.identifier} is continuous: it has no clock")
    return len(value_references(model))


def _period_declaration(model: FmuModel) -> str:
    """The element inside either annotation (the same in FMI 2.0 and 3.0)."""
    return f'<SampledData periodParameter={quoteattr(model.sampled.sample_period)}/>'


def _fmt(value: float) -> str:
    return repr(float(value))


@lru_cache(maxsize=None)
def dependency_kinds(model: FmuModel) -> dict[str, list[tuple[str, str]]]:
    """For each derivative ``der(name)`` and output: [(known name, kind)]
    (a sampled-data model's outputs: on the inputs their first sample reads)."""
    s = model.symbols
    f = model.functions
    t, x, u, p, z = s["t"], s["x"], s["u"], s["p"], s["z"]
    if model.sampled is not None:
        rs = s["rs"]
        step = model.inlined_step  # its laws inlined: the exact structure (fmu_models.export.staged)
        unknowns = (step(t, u, p, z, rs) if model.sampled.n_random_step else step(t, u, p, z))[0]
        variable_part = ca.vertcat(t, u, z, rs)
    else:
        unknowns = ca.vertcat(f["ode"](t, x, u, p), f["out"](t, x, u, p))
        variable_part = ca.vertcat(t, x, u)
    knowns = ca.vertcat(x, u)
    jac = ca.jacobian(unknowns, knowns)
    known_names = [v.name for v in model.states + model.inputs]
    rows = [f"der({v.name})" for v in model.states] + [v.name for v in model.outputs]
    # the entries row by row: the transpose's nonzeros, in its column-major order (one call, where reading each
    # of an EKF's ~1000 entries by (row, column) after testing every pair of the table cost ~0.1 CPU-s)
    by_row = jac.T
    columns, rows_of = by_row.sparsity().get_triplet()
    pairs = list(zip(rows_of, columns))
    entries = by_row.nz[:] if pairs else ca.SX(0, 1)
    # Which entries depend on which symbols: one sparsity sweep over every entry and every symbol at once.
    # ``depends_on`` entry by entry walks the whole expression graph for each of them (the EKFs' ~1000
    # entries: ~6 s of CPU a build); one sweep for the variable part and one for the parameters built the
    # entries' graph twice (~0.3 CPU-s more a build). The structural answer is the same.
    on_variable, on_parameter = _depends_rows(entries, variable_part, p)
    result: dict[str, list[tuple[str, str]]] = {row: [] for row in rows}
    for i, (r, c) in enumerate(pairs):
        kind = "dependent" if i in on_variable else "fixed" if i in on_parameter else "constant"
        result[rows[r]].append((known_names[c], kind))
    return result


def _depends_rows(entries, first, second) -> tuple[set[int], set[int]]:
    """The rows of the column ``entries`` that depend on any of ``first``, and those that depend on any of
    ``second`` (``ca.depends_on`` of each row), from one sparsity pattern of ``entries`` in both."""
    symbols = ca.vertcat(first, second)
    if entries.numel() == 0 or symbols.numel() == 0:
        return set(), set()
    rows, columns = ca.jacobian_sparsity(entries, symbols).get_triplet()
    split = first.numel()
    return ({r for r, c in zip(rows, columns) if c < split}, {r for r, c in zip(rows, columns) if c >= split})


def _unit_definitions(units: dict[str, Mapping[str, float] | None]) -> str:
    """``<UnitDefinitions>`` of ``units`` (name -> BaseUnit attributes; ``None``: no BaseUnit)."""
    lines = ["  <UnitDefinitions>"]
    for name in sorted(units):
        base = units[name]
        exps = " ".join(f'{k}="{_fmt(e) if isinstance(e, float) else e}"' for k, e in (base or {}).items())
        lines.append(f'    <Unit name={quoteattr(name)}/>' if base is None
                     else f'    <Unit name={quoteattr(name)}><BaseUnit {exps}/></Unit>' if exps
                     else f'    <Unit name={quoteattr(name)}><BaseUnit/></Unit>')
    lines.append("  </UnitDefinitions>")
    return "\n".join(lines)


def _used_units(model: FmuModel) -> dict[str, Mapping[str, float] | None]:
    """Every unit the model uses, with its BaseUnit attributes (``None``: none known)."""
    names = {v.unit for v in model.all_variables if v.base_unit is None} | {"s"}
    names |= {derivative_unit(v.unit) for v in model.states}
    units: dict[str, Mapping[str, float] | None] = {n: UNITS[n] for n in names}
    for v in model.all_variables:
        if v.base_unit is not None and v.unit and v.unit not in units:
            units[v.unit] = dict(v.base_unit) if v.base_unit else None
    return units


@dataclass(frozen=True)
class _Entry:
    """One row of ModelVariables; FMI 2.0 and 3.0 differ only in how it is written."""

    name: str
    vr: int
    causality: str  # the FMI causality: independent, output, local, input, parameter
    variability: str
    initial: str | None
    description: str
    unit: str
    start: float | None = None
    state: str | None = None  # for der(x): the name of x
    bounds: tuple[tuple[str, float], ...] = ()


@lru_cache(maxsize=None)
def _model_variables(model: FmuModel) -> tuple[_Entry, ...]:
    """Every variable of ``model`` in value-reference order (time, x, der(x), y, u, p); once per model
    (an FMI 2.0 and an FMI 3.0 modelDescription read it twice each: an EKF's ~300 rows)."""
    refs = value_references(model)
    by_name = {v.name: v for v in model.all_variables}
    entries = []
    for name in sorted(refs, key=refs.get):
        vr = refs[name]
        if name == "time":
            entries.append(_Entry(name, vr, "independent", "continuous", None, "simulation time", "s"))
            continue
        if name.startswith("der("):
            state = by_name[name[4:-1]]
            entries.append(_Entry(name, vr, "local", "continuous", "calculated", "time derivative of " + state.name,
                                  derivative_unit(state.unit), state=state.name))
            continue
        v = by_name[name]
        held = "discrete" if model.sampled is not None else "continuous"  # sample-and-hold outputs
        if v.causality in ("state", "output"):  # a state is exposed as an output
            entries.append(_Entry(name, vr, "output", held, "calculated", v.description, v.unit))
        elif v.causality == "discrete":
            entries.append(_Entry(name, vr, "local", "discrete", "calculated", v.description, v.unit))
        elif v.causality == "input":
            entries.append(_Entry(name, vr, "input", "continuous", None, v.description, v.unit, v.start))
        else:
            bounds = tuple((k, b) for k, b in (("min", v.min), ("max", v.max))
                           if b not in (float("inf"), -float("inf")))
            entries.append(_Entry(name, vr, "parameter", "fixed", "exact", v.description, v.unit, v.start,
                                  bounds=bounds))
    return tuple(entries)


def _model_structure(model: FmuModel):
    """Outputs, state derivatives (both as [(name, [(known, kind)])], in
    value-reference order) and initial unknowns (names) of the ModelStructure."""
    deps = dependency_kinds(model)
    entries = _model_variables(model)
    outputs = [(e.name, [(e.name, "constant")] if model.variable(e.name).causality == "state" else deps[e.name])
               for e in entries if e.causality == "output"]  # a state as output depends on itself
    derivatives = [(f"der({v.name})", deps[f"der({v.name})"]) for v in model.states]
    initial = [e.name for e in entries if e.initial == "calculated" and e.causality != "local"
               or e.name.startswith("der(")]
    return outputs, derivatives, initial


def _unknown(tag: str, key_attribute: str, key, name: str, dependencies=None, indent: int = 6) -> str:
    """A ModelStructure element; ``key`` maps a variable name to its index (FMI 2.0)
    or value reference (FMI 3.0)."""
    head = f'{" " * indent}<{tag} {key_attribute}="{key(name)}"'
    if dependencies is None:
        return head + "/>"
    refs = " ".join(str(key(k)) for k, _ in dependencies)
    kinds = " ".join(kind for _, kind in dependencies)
    return head + f' dependencies="{refs}" dependenciesKind="{kinds}"/>'


def _variable_attributes(e: _Entry) -> str:
    initial = f' initial="{e.initial}"' if e.initial else ""
    return (f'name={quoteattr(e.name)} valueReference="{e.vr}" causality="{e.causality}" '
            f'variability="{e.variability}"{initial} description={quoteattr(e.description)}')


def _value_attributes(e: _Entry, derivative_key) -> str:
    """unit, start, derivative, min, max of a Real (FMI 2.0) or Float64 (FMI 3.0)."""
    text = f"unit={quoteattr(e.unit)}" if e.unit else ""  # "": a table column that has none
    if e.start is not None:
        text += f' start="{_fmt(e.start)}"'
    if e.state is not None:
        text += f' derivative="{derivative_key(e.state)}"'
    return text + "".join(f' {k}="{_fmt(b)}"' for k, b in e.bounds)


def _root_attributes(model: FmuModel) -> str:
    return (f"description={quoteattr(model.description)}\n"
            f'  generationTool="fnn-cosim {__version__} with CasADi {ca.__version__}"')


def _shared_sections(model: FmuModel) -> str:
    """UnitDefinitions, LogCategories and DefaultExperiment (same in FMI 2.0 and 3.0);
    a sampled-data model's step is its sample period."""
    step = model.variable(model.sampled.sample_period).start if model.sampled is not None else 0.01
    return f"""{_unit_definitions(_used_units(model))}
  <LogCategories>
    <Category name="logEvents" description="informational messages (with debug logging on)"/>
    <Category name="logStatusError" description="refused calls and values, failed steps (always logged)"/>
  </LogCategories>
  <DefaultExperiment startTime="0" stopTime="10" stepSize="{_fmt(step)}"/>"""


def fmi2_model_description(model: FmuModel, guid: str) -> str:
    """FMI 2.0 modelDescription.xml: Model Exchange and Co-Simulation in one FMU."""
    entries = _model_variables(model)
    index = {e.name: i + 1 for i, e in enumerate(entries)}  # 1-based, as FMI 2.0 counts
    sv = [f"    <ScalarVariable {_variable_attributes(e)}><Real {_value_attributes(e, index.get)}/></ScalarVariable>"
          for e in entries]
    outputs, derivatives, initial = _model_structure(model)
    outputs = [_unknown("Unknown", "index", index.get, name, deps) for name, deps in outputs]
    derivatives = [_unknown("Unknown", "index", index.get, name, deps) for name, deps in derivatives]
    initial = [_unknown("Unknown", "index", index.get, name) for name in initial]

    sources = "\n".join(f'      <File name="{f}"/>' for f in SOURCE_FILES_FMI2)
    sampled = model.sampled is not None
    capabilities = ('canGetAndSetFMUstate="true" canSerializeFMUstate="true" '
                    f'providesDirectionalDerivative="{str(not sampled).lower()}" '
                    'canNotUseMemoryManagementFunctions="true"')
    model_exchange = "" if sampled else f"""
  <ModelExchange modelIdentifier="{model.identifier}" {capabilities}>
    <SourceFiles>
{sources}
    </SourceFiles>
  </ModelExchange>"""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{model.identifier}" guid="{guid}"
  {_root_attributes(model)}
  variableNamingConvention="structured" numberOfEventIndicators="0">{model_exchange}
  <CoSimulation modelIdentifier="{model.identifier}" canHandleVariableCommunicationStepSize="{str(not sampled).lower()}" {capabilities}>
    <SourceFiles>
{sources}
    </SourceFiles>
  </CoSimulation>
{_shared_sections(model)}{_fmi2_vendor_annotations(model)}
  <ModelVariables>
{chr(10).join(sv)}
  </ModelVariables>
  <ModelStructure>
{_fmi2_section("Outputs", outputs)}{_fmi2_section("Derivatives", derivatives)}{_fmi2_section("InitialUnknowns", initial)}  </ModelStructure>
</fmiModelDescription>
"""


def _fmi2_vendor_annotations(model: FmuModel) -> str:
    """A sampled-data model's period declaration (:data:`PERIOD_ANNOTATION`), else nothing."""
    if model.sampled is None:
        return ""
    return f"""
  <VendorAnnotations>
    <Tool name="{PERIOD_ANNOTATION}">{_period_declaration(model)}</Tool>
  </VendorAnnotations>"""


def _fmi2_section(tag: str, unknowns: list[str]) -> str:
    """An FMI 2.0 ModelStructure list; the schema forbids an empty one, so a
    model without states (or outputs) leaves the element out."""
    if not unknowns:
        return ""
    body = "\n".join(unknowns)
    return f"    <{tag}>\n{body}\n    </{tag}>\n"


def fmi3_model_description(model: FmuModel, instantiation_token: str) -> str:
    """FMI 3.0 modelDescription.xml: Model Exchange and Co-Simulation in one FMU.

    The sources are listed in ``sources/buildDescription.xml``
    (:func:`fmi3_build_description`), not here as in FMI 2.0. Co-Simulation
    declares ``hasEventMode``: a continuous model has no events, so an
    importer that uses Event Mode only ever sees ``fmi3UpdateDiscreteStates``
    report nothing. A sampled-data model is clocked (:data:`CLOCK_NAME`, a
    periodic input clock of the sample period, ``intervalVariability="fixed"``):
    its outputs and discrete states are clocked, and it has Model Exchange
    (a time event per tick), Co-Simulation with Event Mode and early return,
    and Scheduled Execution (one model partition).
    """
    entries = _model_variables(model)
    vr = {e.name: e.vr for e in entries}
    sampled = model.sampled is not None
    clock = clock_reference(model) if sampled else None

    def clocked(e: _Entry) -> str:
        return f' clocks="{clock}"' if sampled and e.variability == "discrete" else ""

    variables = [f"    <Float64 {_variable_attributes(e)}{clocked(e)} {_value_attributes(e, vr.get)}/>"
                 for e in entries]
    if sampled:
        what = f"ticks every {model.sampled.sample_period} s from the start time: one sample"
        variables.append(f'    <Clock name="{CLOCK_NAME}" valueReference="{clock}" causality="input" '
                         f'variability="discrete" intervalVariability="fixed" priority="0" description={quoteattr(what)}/>')
    outputs, derivatives, initial = _model_structure(model)
    if sampled:  # clocked outputs have no initial value to compute: they change at the ticks
        initial = [name for name in initial if name not in {n for n, _ in outputs}]
    structure = ([_unknown("Output", "valueReference", vr.get, name, deps, 4) for name, deps in outputs]
                 + [_unknown("ContinuousStateDerivative", "valueReference", vr.get, name, deps, 4)
                    for name, deps in derivatives]
                 + [_unknown("InitialUnknown", "valueReference", vr.get, name, indent=4) for name in initial])
    derivatives_flag = str(not sampled).lower()
    capabilities = ('canGetAndSetFMUState="true" canSerializeFMUState="true" '
                    f'providesDirectionalDerivatives="{derivatives_flag}" '
                    f'providesAdjointDerivatives="{derivatives_flag}"')
    model_exchange = (f'\n  <ModelExchange modelIdentifier="{model.identifier}" {capabilities} '
                      'needsCompletedIntegratorStep="false"/>')
    cosimulation = 'canHandleVariableCommunicationStepSize="true" hasEventMode="true"'
    if sampled:
        cosimulation += ' mightReturnEarlyFromDoStep="true"'
    scheduled = (f'\n  <ScheduledExecution modelIdentifier="{model.identifier}" canGetAndSetFMUState="true" '
                 'canSerializeFMUState="true"/>' if sampled else "")
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="{model.identifier}" instantiationToken="{instantiation_token}"
  {_root_attributes(model)}
  variableNamingConvention="structured">{model_exchange}
  <CoSimulation modelIdentifier="{model.identifier}" {capabilities}
    {cosimulation}/>{scheduled}
{_shared_sections(model)}
  <ModelVariables>
{chr(10).join(variables)}
  </ModelVariables>
  <ModelStructure>
{chr(10).join(structure)}
  </ModelStructure>{_fmi3_annotations(model)}
</fmiModelDescription>
"""


def _fmi3_annotations(model: FmuModel) -> str:
    """A sampled-data model's period declaration (:data:`PERIOD_ANNOTATION`), else nothing."""
    if model.sampled is None:
        return ""
    return f"""
  <Annotations>
    <Annotation type="{PERIOD_ANNOTATION}">{_period_declaration(model)}</Annotation>
  </Annotations>"""


def fmi3_build_description(model: FmuModel) -> str:
    """FMI 3.0 ``sources/buildDescription.xml``: how to compile the source FMU."""
    sources = "\n".join(f'      <SourceFile name="{f}"/>' for f in SOURCE_FILES_FMI3)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiBuildDescription fmiVersion="3.0">
  <BuildConfiguration modelIdentifier="{model.identifier}"
    description="CasADi-generated model code and the generic FMI 3.0 layer; C99, no dependencies but the C math library">
    <SourceFileSet language="C99">
{sources}
      <IncludeDirectory name="."/>
    </SourceFileSet>
    <Library name="m" external="true" description="C math library (link with -lm where it is not part of libc)"/>
  </BuildConfiguration>
</fmiBuildDescription>
"""
