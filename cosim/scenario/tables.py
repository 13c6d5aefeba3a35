"""The declaration of a scenario file (pydantic, :mod:`cosim.scenario.schema`): the
generic tables (:class:`Simulation`, :class:`FmuSpec`, :class:`Record`, the
components and the envelope), assembled with the component kinds' tables and
the sections the registry holds (:func:`scenario_model`), and what a
validated document derives (:func:`derived_state`, the data a
:class:`cosim.scenario.definition.Scenario` holds).

Imported only when a document is validated or its JSON Schema asked for: a
scenario served from the cache (:func:`cosim.scenario.definition.load_scenario`) needs
no pydantic. What each key means, with an example: ``docs/cosim.md``; its
type, unit and range: the declarations below.
"""
from __future__ import annotations

import functools
import json
import math
from pathlib import Path
from typing import Annotated, Any, Mapping, Union

from pydantic import (AfterValidator, BeforeValidator, Discriminator, Field, Tag, ValidationError, WrapValidator,
                      create_model, model_validator)

from . import registry
from ..cache import Memo
from ..errors import ScenarioError
from ..fmi.model_exchange import COUPLINGS, JACOBIANS, METHODS
from ..loop.plan import ORDERINGS  # the master's (docs/cosim.md)
from ..limits import MAX_STEPS
from ..limits import SEED_LIMIT
from ..time_grid import whole_steps
from .schema import (Count, NonNegativeInt, Number, Positive, Names, Table, json_schema, one_of, refuse,
                     scenario_error, where)

__all__ = ["Simulation", "Solver", "FmuSpec", "Record", "ConnectionTable", "FactoryComponent", "scenario_model",
           "scenario_json_schema", "check_fmu_parameters", "derived_state"]


# ---- the generic tables -----------------------------------------------------------------------

class Simulation(Table):
    """``[simulation]``: the run's time grid, seed, ordering and Model Exchange coupling."""

    duration: Positive = Field(50.0, description="length of the run [s], a whole number of steps")
    step: Positive = Field(0.01, description="communication step [s]")
    seed: Annotated[int, Field(strict=True, ge=0, le=SEED_LIMIT)] = Field(
        0, description="the run's seed: every component's start(), every FMU's seed_parameter (exact to 2^53)")
    start_time: Number = Field(0.0, description="time of the first communication point [s]")
    ordering: one_of(ORDERINGS) = Field("feedthrough", description="how a step orders the blocks "
                                                                   "(docs/cosim.md)")
    coupling: one_of(COUPLINGS) = Field(
        "tight", description="Model Exchange FMUs connected to each other: 'tight', one solver over all their states "
                             "(the connections inside its right-hand side); 'loose', each alone with its inputs held "
                             "over a step (docs/cosim.md, \"Model Exchange\")")

    @model_validator(mode="after")
    def _whole_steps(self):
        n = whole_steps(self.duration, self.step)
        if n is None:
            raise refuse(f"not a whole number of steps of {self.step!r} s", key="duration", value=self.duration)
        if n > MAX_STEPS:
            raise refuse(f"{n} steps of {self.step!r} s; at most {MAX_STEPS} a run", key="duration",
                         value=self.duration)
        # a double has about 16 digits: far from 0, t0 + n h can no longer tell one step from the next
        end = abs(self.start_time) + self.duration
        if math.ulp(end) > 1e-6 * self.step:
            if math.ulp(self.duration) > 1e-6 * self.step:
                raise refuse(f"too small to be told apart at t = {self.duration:g} s (a double has about 16 digits)",
                             key="step", value=self.step)
            raise refuse(f"at this time a step of {self.step!r} s is lost in rounding (a double has about 16 "
                         f"digits); start nearer 0", key="start_time", value=self.start_time)
        return self


INTERFACES = ("CoSimulation", "ModelExchange")


class Solver(Table):
    """``[fmus.<Name>.solver]``: how the master integrates a Model Exchange
    FMU (:mod:`cosim.fmi.me_system`; the FMUs of one system take one solver: the
    same method, the tightest tolerance, the smallest step and event limit)."""

    method: one_of(METHODS) = Field("cvode", description="'cvode' (variable step BDF with root finding, "
                                                                    "SUNDIALS) or 'euler' (fixed step)")
    relative_tolerance: Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, lt=1)] = Field(
        None, description="CVODE's relative tolerance (default: the FMU's default experiment's, else 1e-5); each "
                          "state's absolute tolerance is it times the state's nominal")
    step: Positive = Field(None, description="Euler's step [s] (a whole fraction of the communication step; default: "
                                             "the communication step), or CVODE's largest step")
    max_events: Count = Field(1000, description="events allowed in one communication step before the model is taken "
                                                "to chatter")
    jacobian: one_of(JACOBIANS) = Field("difference", description="CVODE's Newton matrix: 'difference' (its own "
                                                                  "difference quotients) or 'directional' (the FMUs' "
                                                                  "directional derivatives through the connections)")


class ConnectionTable(Table):
    """A connection written as a table (``connections`` entry): its
    ``connect`` string and either a unit conversion or the unchecked marker
    (docs/cosim.md, "Units")."""

    connect: Annotated[str, Field(strict=True)] = Field(..., description="'A.out -> B.in' (brace groups expand)")
    factor: Number = Field(None, description="destination = factor * source + offset (default 1)")
    offset: Number = Field(None, description="destination = factor * source + offset (default 0)")
    units: one_of(("unchecked",)) = Field(None, description="'unchecked': the units are not compared")

    @model_validator(mode="after")
    def _conversion_or_unchecked(self):
        converts = self.factor is not None or self.offset is not None
        if converts == (self.units is not None):
            raise refuse("give a conversion (factor, offset) or units = 'unchecked', not both and not neither")
        if self.factor == 0:
            raise refuse("a conversion's factor must not be 0", key="factor", value=self.factor)
        return self


def _connection_tag(value: Any) -> str | None:
    return "table" if isinstance(value, (Mapping, ConnectionTable)) else "string" if isinstance(value, str) else None


ConnectionEntry = Annotated[Union[Annotated[Annotated[str, Field(strict=True)], Tag("string")],
                                  Annotated[ConnectionTable, Tag("table")]], Discriminator(_connection_tag)]


def _source(info) -> Path | None:
    return (info.context or {}).get("source")


class FmuSpec(Table):
    """``[fmus.<Name>]``: an FMU instance, a registered model or a file."""

    model: str = Field(None, description="a registered model, built on demand")
    path: str = Field(None, description="an FMU file (relative to the scenario file)")
    fmi_version: one_of((2, 3), "expected 2 or 3", int) = Field(
        None, description="2 or 3: the version built (a model, default 2) or the version the file must have")
    parameters: dict[str, Number] = Field(default_factory=dict, description="start values of parameters and inputs")
    parameter_set: str = Field(None, description="an SSP parameter set file (.ssv, e.g. fnn-cosim calibrate's "
                                                 "parameters.ssv): its values, under 'parameters' (which win); "
                                                 "relative to the scenario file's folder, else to the current one")
    start: dict[str, Union[bool, Number]] = Field(
        default_factory=dict, description="start values of the other variables the standard lets an importer set "
                                          "(initial = exact or approx: a state's initial value, ...)")
    interface: one_of(INTERFACES) = Field(None, description="the FMI interface it runs with; default: Co-Simulation "
                                                            "where the FMU has it, else Model Exchange")
    solver: Solver = Field(None, description="Model Exchange: how the master integrates it")
    seed_parameter: str = Field(None, description="a parameter set to the run's seed at every start")
    seed_stream: NonNegativeInt = Field(None, description="with seed_parameter: the run's random stream k")

    @model_validator(mode="after")
    def _one_source(self, info):
        if (self.model is None) == (self.path is None):
            raise refuse("give exactly one of 'model' (a registered model) or 'path' (an FMU file)")
        both = sorted(set(self.parameters) & set(self.start))
        if both:
            raise refuse(f"{both[0]!r} is given in both 'parameters' and 'start': a parameter goes in 'parameters', "
                         f"any other variable in 'start'", key="start")
        if self.solver is not None and self.interface == "CoSimulation":
            raise refuse("a solver is for an FMU run as Model Exchange; this one has interface = 'CoSimulation'",
                         key="solver")
        if self.seed_stream is not None and self.seed_parameter is None:
            raise refuse("only an FMU with a seed_parameter is seeded", key="seed_stream", value=self.seed_stream)
        if self.model is not None:
            models = registry.fmu_models()
            if self.model not in models:
                raise refuse(f"unknown model; known: {', '.join(sorted(models)) or '(none registered)'}",
                             key="model", value=self.model)
        else:
            path = self.resolved(_source(info))
            if not path.exists():
                raise refuse(f"no such file ({path})", key="path", value=self.path)
            if not (path.is_file() or path.is_dir()):  # /dev/zero, a FIFO: nothing an FMU is read from
                raise refuse(f"not a regular file or an extracted FMU's folder ({path})", key="path",
                             value=self.path)
        _check_model_parameters(self.model, self.parameters)
        if self.parameter_set is not None:
            _check_model_parameters(self.model, self.set_values(_source(info)), "parameter_set")
        return self

    def set_values(self, source: Path | None) -> dict[str, float]:
        """The values of ``parameter_set`` (none without one): the file from
        the scenario file's folder if it is there, else from the current folder."""
        if self.parameter_set is None:
            return {}
        from .parameter_set import read_parameter_set

        path = Path(self.parameter_set)
        if not path.is_absolute() and source is not None and (source.parent / path).is_file():
            path = source.parent / path
        return read_parameter_set(path)

    def resolved(self, source: Path | None) -> Path:
        """The FMU file, relative paths taken from the scenario file's folder."""
        path = Path(self.path)
        return source.parent / path if not path.is_absolute() and source is not None else path


def _check_model_parameters(model: str | None, params: Mapping[str, float], key: str = "parameters") -> None:
    """A registered model's parameters: known names, values in their declared ranges."""
    entry = registry.fmu_models().get(model)
    if entry is None or entry.check_parameter is None:
        return
    for name, value in params.items():
        try:
            entry.check_parameter(name, float(value))
        except (KeyError, ValueError) as exc:
            raise refuse(exc.args[0], key=f"{key}.{name}") from None


def check_fmu_parameters(where_: str, fmu: Mapping[str, Any], params: Mapping[str, Any]) -> None:
    """For a section that sets FMU parameters: ``params`` known to ``fmu``'s
    registered model and in range, else a :class:`ScenarioError` naming ``where_.<name>``."""
    for name, value in params.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ScenarioError(f"{where_}.{name} = {value!r}: expected a finite number")
    try:
        _check_model_parameters(fmu.get("model"), params, key="")
    except Exception as exc:  # PydanticCustomError: told in the section's words
        ctx = getattr(exc, "context", None) or {}
        raise ScenarioError(f"{where_}{ctx.get('key', '')}: {ctx.get('message', exc)}") from None


class Record(Table):
    """``[record]``: what the results hold."""

    signals: Names | None = Field(None, description="recorded signals, 'Component.variable', each once; "
                                                  "without it, every output of every component")
    block_rows: Count = Field(100, description="rows per block flushed to the results file")


def _bounds(value: Any) -> Any:
    if not isinstance(value, list) or len(value) != 2:
        raise refuse("expected [low, high]", value=value)
    return value


def _low_below_high(value: list[float]) -> tuple[float, float]:
    if not value[0] < value[1]:
        raise refuse("low must be below high", value=value)
    return (value[0], value[1])


Bounds = Annotated[list[Number], BeforeValidator(_bounds), AfterValidator(_low_below_high),
                   Field(min_length=2, max_length=2)]


class FactoryComponent(Table):
    """``[components.<name>] factory = "package.module:callable"``: any
    callable, given ``name`` and every other key of the table."""

    model_config = {**Table.model_config, "extra": "allow"}
    factory: Annotated[str, Field(strict=True, pattern=r"^[\w.]+:[\w.]+$",
                                  description="'package.module:callable', called with name=<name> and the "
                                              "table's other keys")]

    @classmethod
    def known_keys(cls) -> list[str]:
        return ["factory"]

    @model_validator(mode="before")
    @classmethod
    def _a_table_of_known_keys(cls, data: Any) -> Any:  # any other key is the factory's parameter
        if not isinstance(data, Mapping):
            raise refuse("expected a table", value=data)
        factory = data.get("factory")
        if isinstance(factory, str) and factory.count(":") != 1:
            raise refuse("expected 'package.module:callable'", key="factory", value=factory)
        return data


# ---- the whole scenario, assembled from the registry -------------------------------------------

@functools.lru_cache(maxsize=None)
def _kind_table(kind: registry.ComponentKind, tag_required: bool) -> type[Table]:
    """A component table of ``kind``: its parameters and its ``kind`` key
    (built once per kind: the components' union and a short section's type
    share it)."""
    kind_field = (one_of((kind.name,)), ... if tag_required else kind.name)
    model = create_model(f"Component_{_identifier(kind.name)}", __base__=kind.parameters(),
                         __doc__=kind.description or None, kind=kind_field)
    model.selector = "kind"
    return model


def _identifier(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name)


def _tag(value: Any) -> str | None:
    if isinstance(value, Mapping):
        if ("kind" in value) == ("factory" in value):
            return None
        return str(value["kind"]) if "kind" in value else "factory"
    return getattr(value, "kind", None) or ("factory" if hasattr(value, "factory") else None)


def _component_union(kinds) -> Any:
    members = [Annotated[_kind_table(k, True), Tag(k.name)] for k in kinds]
    members.append(Annotated[FactoryComponent, Tag("factory")])
    return Annotated[Union[tuple(members)], Discriminator(_tag)]


def _alias_type(kinds) -> Any:
    if len(kinds) == 1:
        return _kind_table(kinds[0], False)
    members = [Annotated[_kind_table(k, True), Tag(k.name)] for k in kinds]
    return Annotated[Union[tuple(members)], Discriminator(lambda v: str(v.get("kind", "")) if isinstance(v, Mapping)
                                                          else getattr(v, "kind", None))]


class _ScenarioBase(Table):
    """What every scenario holds; the registry adds its aliases and sections."""

    @model_validator(mode="after")
    def _consistent(self):
        if not self.fmus:
            raise refuse("at least one [fmus.<Name>] table is required", key="fmus")
        for alias, kinds in registry.aliases().items():
            instance = kinds[0].instance or alias
            if getattr(self, alias, None) is not None and instance in self.components:
                raise refuse("a component of that name is already given by its short section",
                             key=f"components.{instance}")
        return self


_MODELS: dict[int, type[Table]] = {}

TABLES_KEPT = 512  # validated tables a declaration keeps (_kept): a study's cases and grid points, and more


def _kept(table: Any, memo: Memo, reads_files: Any = lambda value: False) -> Any:
    """``table``'s type, its validated value kept in ``memo`` by the
    document's text of it (and the scenario file, which relative paths
    start from): the runs of a study differ in a few drawn values, and each
    of their documents is validated whole (one path, the same errors), but a
    table validated before, unchanged, is not validated again. Only a table
    that was accepted is kept: a refused one is validated, and refused,
    every time. ``reads_files(value)``: validating ``value`` reads files (an
    FMU by path, a parameter set, a signal table), which may change between
    two validations: never kept. A value JSON does not hold exactly (a TOML
    date) is validated every time too. One validated value serves many
    scenarios: the tables are frozen (:class:`~cosim.scenario.schema.Table`),
    and :func:`derived_state` copies the lists and tables it takes from them."""

    def validate(value: Any, handler, info) -> Any:
        if reads_files(value):
            return handler(value)
        try:  # no default=: a value JSON does not hold raises, and is validated every time (no argument: the
            key = (id(table), json.dumps(value), str(_source(info)))  # module's encoder, not a new one per call)
        except (TypeError, ValueError):
            return handler(value)
        found = memo.get(key)
        if found is None:
            found = handler(value)
            memo.put(key, found)
        return found

    return Annotated[table, WrapValidator(validate)]


def _names_files(spec: Any) -> bool:
    """An ``[fmus.<Name>]`` table whose validation reads a file (its FMU by path, its parameter set)."""
    return not isinstance(spec, Mapping) or "path" in spec or "parameter_set" in spec


def _kind_reads_files(value: Any) -> bool:
    kind = registry.component_kinds().get(value.get("kind")) if isinstance(value, Mapping) else None
    return not isinstance(value, Mapping) or (kind is not None and kind.reads_files)


def scenario_model() -> type[Table]:
    """The declaration of a scenario file: the generic tables and what the
    registry holds now (component kinds, their short sections, sections);
    a declaration keeps the tables it accepted (:func:`_kept`)."""
    version = registry.version()
    if version not in _MODELS:
        kinds = list(registry.component_kinds().values())
        memo = Memo(TABLES_KEPT)
        fields: dict[str, Any] = {
            "name": (Annotated[str, Field(strict=True)], Field(None, description="default: the file's name")),
            "description": (Annotated[str, Field(strict=True)], ""),
            "connections": (_kept(list[ConnectionEntry], memo), Field(default_factory=list, description=(
                "'A.out -> B.in' strings (brace groups expand: 'A.{x,y} -> B.{x,y}'), or tables "
                "{ connect = 'A.out -> B.in', factor = .., offset = .. } (a unit conversion) or "
                "{ connect = .., units = 'unchecked' }"))),
            "simulation": (_kept(Simulation, memo), Field(default_factory=Simulation)),
            "fmus": (dict[str, _kept(FmuSpec, memo, _names_files)], Field(default_factory=dict,
                                                                            description="the FMU instances")),
            "components": (dict[str, _kept(_component_union(kinds), memo, _kind_reads_files)],
                           Field(default_factory=dict, description="the Python components")),
            "record": (_kept(Record, memo), Field(default_factory=Record)),
            "envelope": (_kept(dict[str, Bounds], memo), Field(default_factory=dict,
                                                  description="divergence bounds [low, high] per signal")),
        }
        for alias, members in registry.aliases().items():
            files = any(kind.reads_files for kind in members)
            fields[alias] = (_kept(_alias_type(members), memo, lambda value, files=files: files),
                             Field(None, description=f"short for [components.{members[0].instance or alias}]"))
        for name, section in registry.sections().items():
            fields[name] = (_kept(section.parameters(), memo, lambda value, s=section: s.reads_files),
                            Field(None, description=section.description or None))
        _MODELS.clear()
        _MODELS[version] = create_model("Scenario", __base__=_ScenarioBase, **fields)
    return _MODELS[version]


def scenario_json_schema() -> dict[str, Any]:
    """The JSON Schema of a scenario file (``fnn-cosim schema scenario``)."""
    return json_schema(scenario_model(), "fnn-cosim scenario",
                       "A co-simulation scenario (TOML): FMUs, Python components, connections, recording "
                       "(docs/cosim.md)")


def _validated(raw: Mapping[str, Any], source: Path | None):
    """The scenario document validated, or the one-line error (the component
    union's words for a missing or unknown kind)."""
    try:
        return scenario_model().model_validate(dict(raw), context={"source": source})
    except ValidationError as exc:
        err = dict(exc.errors(include_url=False)[0])
        if err["loc"][:1] == ("connections",) and len(err["loc"]) > 1:
            if err["type"] in ("union_tag_invalid", "union_tag_not_found"):
                raise ScenarioError(f"{where(err['loc'])} = {err.get('input')!r}: expected a string "
                                    f"'A.out -> B.in' or a table {{ connect = 'A.out -> B.in', ... }}") from None
            err["loc"] = err["loc"][:2] + err["loc"][3:]  # the entry's form (string, table) is no key
            raise scenario_error(err) from None
        if err["type"] in ("union_tag_invalid", "union_tag_not_found"):
            raise _kind_error(err) from None
        loc = list(err["loc"])
        # a component's table is a union keyed by its kind: pydantic names the member; the document does not
        if loc[:1] == ["components"] and len(loc) > 2:
            del loc[2]
        elif len(loc) > 1 and len(registry.aliases().get(loc[0], ())) > 1:
            del loc[1]
        err["loc"] = tuple(loc)
        raise scenario_error(err) from None


def _kind_error(err: Mapping[str, Any]) -> ScenarioError:
    loc, value = where(err["loc"]), err.get("input")
    if not isinstance(value, Mapping):
        return ScenarioError(f"{loc} = {value!r}: expected a table")
    if err["loc"][0] == "components":
        kind = value.get("kind")
        if err["type"] == "union_tag_not_found":
            return ScenarioError(f"{loc}: give exactly one of 'kind' (a registered component kind) or "
                                 f"'factory' ('package.module:callable')")
        if not isinstance(kind, str):
            return ScenarioError(f"{loc}.kind = {kind!r}: expected a string")
        known = ", ".join(sorted(registry.component_kinds())) or "(none registered)"
        return ScenarioError(f"{loc}.kind = {kind!r}: unknown component kind; known: {known}")
    names = ", ".join(k.name for k in registry.aliases()[err["loc"][0]])
    return ScenarioError(f"{loc}.kind = {value.get('kind', '')!r}: expected one of {names}")


def _plain(model: Table) -> dict[str, Any]:
    """A table as the keys the document gave (defaults left out)."""
    return model.model_dump(exclude_unset=True, exclude={"kind", "factory"})


def derived_state(document: dict[str, Any], source: Path | None, name: str | None) -> dict[str, Any]:
    """What a scenario holds, derived from its validated ``document``: plain
    data (a :class:`Scenario` is made of it, :meth:`Scenario._adopt`)."""
    model = _validated(document, source)
    state: dict[str, Any] = {"name": model.name if model.name is not None else (name or (source.stem if source else
                                                                                          "scenario")),
                             "description": model.description}
    sim = model.simulation
    for key in ("duration", "step", "seed", "start_time", "ordering", "coupling"):
        state[key] = getattr(sim, key)
    fmus: dict[str, dict[str, Any]] = {}
    for instance, spec in model.fmus.items():
        # the values as the document wrote them (an integer stays one, as an error quotes it)
        entry: dict[str, Any] = {"parameters": spec.set_values(source)
                                 | dict(document["fmus"][instance].get("parameters", {}))}
        if spec.model is not None:
            entry.update(model=spec.model, fmi_version=spec.fmi_version or 2)
        else:
            entry.update(path=spec.resolved(source), fmi_version=spec.fmi_version)
        if spec.seed_parameter is not None:
            entry["seed_parameter"] = spec.seed_parameter
        if spec.seed_stream is not None:
            entry["seed_stream"] = spec.seed_stream
        if spec.start:
            entry["start"] = dict(document["fmus"][instance]["start"])
        if spec.interface is not None:
            entry["interface"] = spec.interface
        if spec.solver is not None:
            entry["solver"] = _plain(spec.solver)
        fmus[instance] = entry
    components: dict[str, dict[str, Any]] = {}
    for alias, kinds in registry.aliases().items():
        table = getattr(model, alias, None)
        if table is not None:
            kind = next(k for k in kinds if k.name == table.kind)
            components[kind.instance or alias] = {"kind": kind.name, "parameters": _plain(table)}
    for instance, table in model.components.items():
        if isinstance(table, FactoryComponent):
            components[instance] = {"factory": table.factory, "parameters": dict(table.model_extra or {})}
        else:
            components[instance] = {"kind": table.kind, "parameters": _plain(table)}
    sections = {}
    for key, section in registry.sections().items():
        value = getattr(model, key, None)
        if value is not None:
            sections[key] = section.apply(key, value, fmus)
    state.update(fmus=fmus, components=components, sections=sections,
                 connections=[c if isinstance(c, str) else c.model_dump(exclude_none=True) for c in model.connections],
                 record=None if model.record.signals is None else list(model.record.signals), block_rows=model.record.block_rows,
                 envelope={k: list(v) for k, v in model.envelope.items()})
    return state
