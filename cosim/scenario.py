"""Scenarios: TOML files describing a co-simulation, validated before anything runs.

The engine reads the generic sections; every other top-level table is either
an alias of a registered component kind or a registered section
(:mod:`cosim.registry`). Schema (every key optional unless marked; units SI;
see ``docs/cosim.md``)::

    name = "circles"                     # str, default: the file name
    description = "..."                  # str
    connections = ["A.out -> B.in", ...] # required; brace groups expand: "A.{x,y} -> B.{x,y}"

    [simulation]
    duration = 50.0                      # s, > 0, a whole number of steps
    step = 0.01                          # s, > 0
    seed = 0                             # int >= 0: every component's start(), every FMU's seed_parameter
    start_time = 0.0                     # s
    ordering = "feedthrough"             # or "exchange": see cosim.master and docs/cosim.md

    [fmus.<Name>]                        # one table per FMU instance, at least one
    model = "Plant"                      # a registered model (built on demand), or
    path = "other.fmu"                   #   an FMU file (relative to the scenario file)
    fmi_version = 2                      # 2 or 3: the version built (models, default 2) or the
                                         #   version the file must have (FMU files, default: any)
    parameters = { x_0 = 1.0 }           # checked against the model's variables and ranges
    seed_parameter = "seed"              # a parameter set to the run's seed at every start
    seed_stream = 1                      # int >= 0, with seed_parameter: the run's random stream k
                                         #   (cosim.fmu_component.stream_seed; default 0, the run's seed itself):
                                         #   FMUs on different streams draw independent numbers

    [components.<name>]                  # a Python component
    kind = "step_source"                 # a registered component kind, or
    factory = "package.module:callable"  #   any callable (name=<name>, **parameters)
    amplitude = 1.0                      # every other key is a parameter of the component

    [<alias>]                            # a registered kind's short section (e.g. [source] for
                                         #   [components.source]); its `kind` key picks among
                                         #   the kinds sharing the alias

    [<section>]                          # a registered section (e.g. one that sets FMU parameters)

    [record]
    signals = ["Plant.x", ...]           # what the results CSV holds (after time)
    block_rows = 100                     # rows per flushed block

    [envelope]                           # divergence bounds, [low, high] per signal
    "Plant.x" = [-10.0, 10.0]

Errors are :class:`~cosim.errors.ScenarioError` naming the key and value.
"""
from __future__ import annotations

import copy
import importlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from . import registry
from .config import check_number
from .errors import FmuError, ScenarioError

__all__ = ["Scenario", "load_scenario", "parse_scenario", "shipped_scenarios", "scenario_path",
           "apply_overrides", "build_master", "fmu_file", "fmu_error_in_scenario", "check_fmu_parameters", "check_fmu_file",
           "table", "string", "strings", "refuse_unknown", "read_toml"]

GENERIC = ("name", "description", "connections", "simulation", "fmus", "components", "record", "envelope")
_SIMULATION = {"duration", "step", "seed", "start_time", "ordering"}
_FMU = {"model", "path", "fmi_version", "parameters", "seed_parameter", "seed_stream"}
_RECORD = {"signals", "block_rows"}


@dataclass
class Scenario:
    """A validated scenario (plain data; :func:`build_master` makes it runnable).

    ``fmus``: instance -> ``{"model" | "path", "fmi_version", "parameters"}``;
    ``components``: instance -> ``{"kind" | "factory", "parameters"}``;
    ``sections``: the value each registered section's parser returned.
    """

    name: str
    description: str
    duration: float
    step: float
    seed: int
    start_time: float
    ordering: str
    fmus: dict[str, dict[str, Any]]
    components: dict[str, dict[str, Any]]
    connections: list[str]
    record: list[str]
    block_rows: int
    envelope: dict[str, tuple[float, float]]
    sections: dict[str, Any] = field(default_factory=dict)
    source: Path | None = None
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def n_steps(self) -> int:
        return int(round(self.duration / self.step))


# ---- small validators, shared with the sections of applications ---------------------

def refuse_unknown(where: str, values: Mapping[str, Any], known) -> None:
    """Refuse the first key of ``values`` not in ``known``; ``where`` ends with a dot (or is empty)."""
    extra = sorted(set(values) - set(known))
    if extra:
        raise ScenarioError(f"{where}{extra[0]}: unknown key; known keys: {', '.join(sorted(known))}")


def table(where: str, value: Any) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise ScenarioError(f"{where} = {value!r}: expected a table")
    return dict(value)


def string(where: str, value: Any) -> str:
    if not isinstance(value, str):
        raise ScenarioError(f"{where} = {value!r}: expected a string")
    return value


def strings(where: str, value: Any) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ScenarioError(f"{where} = {value!r}: expected a list of strings")
    return list(value)


def apply_overrides(raw: dict[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``raw`` with dotted keys set, e.g. ``{"simulation.duration": 5.0}``."""
    out = copy.deepcopy(raw)
    for dotted, value in overrides.items():
        keys = dotted.split(".")
        node = out
        for k in keys[:-1]:
            nxt = node.setdefault(k, {})
            if not isinstance(nxt, dict):
                raise ScenarioError(f"override {dotted}: {k!r} is not a table")
            node = nxt
        node[keys[-1]] = value
    return out


def check_fmu_parameters(where: str, fmu: Mapping[str, Any], params: Mapping[str, Any]) -> None:
    """Every value a finite number; for a registered model, a known parameter
    or input in its range (an FMU file is checked when it is read)."""
    for key, value in params.items():
        check_number(f"{where}.{key}", value)
    model = registry.fmu_models().get(fmu.get("model"))
    if model is None or model.check_parameter is None:
        return
    for key, value in params.items():
        try:
            model.check_parameter(key, float(value))
        except KeyError as exc:
            raise ScenarioError(f"{where}.{key}: {exc.args[0]}") from None
        except ValueError as exc:
            raise ScenarioError(f"{where}.{key}: {exc}") from None


# ---- one parser per generic section -------------------------------------------------

def _parse_simulation(raw: Mapping[str, Any]) -> dict[str, Any]:
    sim = table("simulation", raw.get("simulation", {}))
    refuse_unknown("simulation.", sim, _SIMULATION)
    duration = float(check_number("simulation.duration", sim.get("duration", 50.0), positive=True))
    step = float(check_number("simulation.step", sim.get("step", 0.01), positive=True))
    n = round(duration / step)
    if n < 1 or abs(n * step - duration) > 1e-9 * max(1.0, duration):
        raise ScenarioError(f"simulation.duration = {duration!r}: not a whole number of steps of {step!r} s")
    from .master import ORDERINGS

    ordering = string("simulation.ordering", sim.get("ordering", "feedthrough"))
    if ordering not in ORDERINGS:
        raise ScenarioError(f"simulation.ordering = {ordering!r}: expected one of {', '.join(ORDERINGS)}")
    return {"duration": duration, "step": step,
            "seed": check_number("simulation.seed", sim.get("seed", 0), integer=True, nonnegative=True),
            "start_time": float(check_number("simulation.start_time", sim.get("start_time", 0.0))),
            "ordering": ordering}


def _parse_fmu(where: str, spec: Any, source: Path | None) -> dict[str, Any]:
    spec = table(where, spec)
    refuse_unknown(where + ".", spec, _FMU)
    if ("model" in spec) == ("path" in spec):
        raise ScenarioError(f"{where}: give exactly one of 'model' (a registered model) or 'path' (an FMU file)")
    # A registered model is built in the version asked (2 by default); an FMU
    # file is what it is, and a version given for it must match (checked
    # when the file is read, in build_master).
    version = spec.get("fmi_version", 2 if "model" in spec else None)
    if version is not None:
        check_number(f"{where}.fmi_version", version, integer=True)
        if version not in (2, 3):
            raise ScenarioError(f"{where}.fmi_version = {version!r}: expected 2 or 3")
    entry: dict[str, Any] = {"fmi_version": version, "parameters": table(f"{where}.parameters",
                                                                         spec.get("parameters", {}))}
    if "seed_parameter" in spec:
        entry["seed_parameter"] = string(f"{where}.seed_parameter", spec["seed_parameter"])
    if "seed_stream" in spec:
        stream = spec["seed_stream"]
        check_number(f"{where}.seed_stream", stream, integer=True, nonnegative=True)
        if "seed_parameter" not in spec:
            raise ScenarioError(f"{where}.seed_stream = {stream!r}: only an FMU with a seed_parameter is seeded")
        entry["seed_stream"] = int(stream)
    if "model" in spec:
        entry["model"] = string(f"{where}.model", spec["model"])
        models = registry.fmu_models()
        if entry["model"] not in models:
            raise ScenarioError(f"{where}.model = {entry['model']!r}: unknown model; known: "
                                f"{', '.join(sorted(models)) or '(none registered)'}")
    else:
        path = Path(string(f"{where}.path", spec["path"]))
        if not path.is_absolute() and source is not None:
            path = source.parent / path
        if not path.exists():
            raise ScenarioError(f"{where}.path = {spec['path']!r}: no such file ({path})")
        entry["path"] = path
    check_fmu_parameters(f"{where}.parameters", entry, entry["parameters"])
    return entry


def _parse_fmus(raw: Mapping[str, Any], source: Path | None) -> dict[str, dict[str, Any]]:
    fmus_raw = table("fmus", raw.get("fmus", {}))
    if not fmus_raw:
        raise ScenarioError("fmus: at least one [fmus.<Name>] table is required")
    return {inst: _parse_fmu(f"fmus.{inst}", spec, source) for inst, spec in fmus_raw.items()}


def _component(where: str, kind_name: str, parameters: dict[str, Any]) -> dict[str, Any]:
    kinds = registry.component_kinds()
    kind = kinds.get(kind_name)
    if kind is None:
        raise ScenarioError(f"{where}.kind = {kind_name!r}: unknown component kind; known: "
                            f"{', '.join(sorted(kinds)) or '(none registered)'}")
    if kind.check is not None:
        kind.check(where, parameters)
    return {"kind": kind_name, "parameters": parameters}


def _parse_alias(section: str, value: Any) -> tuple[str, dict[str, Any]]:
    """``[alias]`` -> (instance name, component entry)."""
    kinds = registry.aliases()[section]
    params = table(section, value)
    if "kind" in params or len(kinds) > 1:
        choice = string(f"{section}.kind", params.pop("kind", ""))
        names = [k.name for k in kinds]
        if choice not in names:
            raise ScenarioError(f"{section}.kind = {choice!r}: expected one of {', '.join(names)}")
        kind = kinds[names.index(choice)]
    else:
        kind = kinds[0]
    return kind.instance or section, _component(section, kind.name, params)


def _parse_components(raw: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    components: dict[str, dict[str, Any]] = {}
    for section in registry.aliases():
        if section in raw:
            name, entry = _parse_alias(section, raw[section])
            components[name] = entry
    for name, spec in table("components", raw.get("components", {})).items():
        where = f"components.{name}"
        spec = table(where, spec)
        if name in components:
            raise ScenarioError(f"{where}: a component of that name is already given by its short section")
        if ("kind" in spec) == ("factory" in spec):
            raise ScenarioError(f"{where}: give exactly one of 'kind' (a registered component kind) or "
                                f"'factory' ('package.module:callable')")
        params = {k: v for k, v in spec.items() if k not in ("kind", "factory")}
        if "kind" in spec:
            components[name] = _component(where, string(f"{where}.kind", spec["kind"]), params)
        else:
            factory = string(f"{where}.factory", spec["factory"])
            if factory.count(":") != 1:
                raise ScenarioError(f"{where}.factory = {factory!r}: expected 'package.module:callable'")
            components[name] = {"factory": factory, "parameters": params}
    return components


def _parse_record(raw: Mapping[str, Any]) -> tuple[list[str], int]:
    rec = table("record", raw.get("record", {}))
    refuse_unknown("record.", rec, _RECORD)
    return (strings("record.signals", rec.get("signals", [])),
            check_number("record.block_rows", rec.get("block_rows", 100), integer=True, positive=True))


def _parse_envelope(raw: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
    envelope = {}
    for signal, bounds in table("envelope", raw.get("envelope", {})).items():
        if not isinstance(bounds, list) or len(bounds) != 2:
            raise ScenarioError(f"envelope.{signal} = {bounds!r}: expected [low, high]")
        low, high = (float(check_number(f"envelope.{signal}[{i}]", b)) for i, b in enumerate(bounds))
        if not low < high:
            raise ScenarioError(f"envelope.{signal} = {bounds!r}: low must be below high")
        envelope[signal] = (low, high)
    return envelope


def parse_scenario(raw: Mapping[str, Any], source: Path | None = None, name: str | None = None) -> Scenario:
    """Validate a scenario given as a mapping (a parsed TOML document)."""
    raw = dict(raw)
    extra_sections = registry.sections()
    refuse_unknown("", raw, set(GENERIC) | set(registry.aliases()) | set(extra_sections))
    simulation = _parse_simulation(raw)
    fmus = _parse_fmus(raw, source)
    sections = {key: section.parse(key, table(key, raw[key]), fmus)
                for key, section in extra_sections.items() if key in raw}
    components = _parse_components(raw)
    if "connections" not in raw:
        raise ScenarioError("connections: required (a list of 'A.out -> B.in' strings)")
    record, block_rows = _parse_record(raw)
    name = raw.get("name", name or (source.stem if source else "scenario"))
    return Scenario(
        name=string("name", name), description=string("description", raw.get("description", "")),
        **simulation, fmus=fmus, components=components, connections=strings("connections", raw["connections"]),
        record=record, block_rows=block_rows, envelope=_parse_envelope(raw), sections=sections, source=source,
        raw=copy.deepcopy(raw),
    )


# ---- files ----------------------------------------------------------------------------

def shipped_scenarios() -> dict[str, Path]:
    """The scenarios of the registered folders, by name."""
    out: dict[str, Path] = {}
    for folder in registry.scenario_folders():
        for path in sorted(folder.glob("*.toml")):
            out.setdefault(path.stem, path)
    return out


def scenario_path(name_or_path: str | Path) -> Path:
    """A path as given, or the registered scenario of that name."""
    path = Path(name_or_path)
    if path.exists():
        return path
    shipped = shipped_scenarios()
    if str(name_or_path) in shipped:
        return shipped[str(name_or_path)]
    raise ScenarioError(f"scenario {str(name_or_path)!r}: no such file, and not a shipped scenario "
                        f"({', '.join(sorted(shipped))})")


def load_scenario(name_or_path: str | Path, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Read, override (dotted keys) and validate a scenario file."""
    path = scenario_path(name_or_path)
    return parse_scenario(apply_overrides(read_toml(path), overrides or {}), source=path)


def read_toml(path: Path) -> dict[str, Any]:
    """A TOML file as a mapping, or a :class:`ScenarioError` naming the file and the fault."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None


# ---- from scenario to master ---------------------------------------------------------------

def fmu_file(spec: Mapping[str, Any]) -> Path:
    """The FMU file of an ``[fmus.X]`` entry (a registered model is built on demand)."""
    if "path" in spec:
        return Path(spec["path"])
    return registry.fmu_models()[spec["model"]].build(spec["fmi_version"])


def check_fmu_file(scenario: Scenario, fmu) -> None:
    """What the scenario says of an FMU file (its FMI version, its
    parameters and their declared ranges) against what the file declares; a
    value the FMU refuses although its description allows it is refused at
    start-up, quoting the FMU (:func:`fmu_error_in_scenario`)."""
    spec = scenario.fmus[fmu.name]
    version = spec.get("fmi_version")
    if version is not None and fmu.fmi_version != version:
        raise ScenarioError(f"fmus.{fmu.name}.fmi_version = {version}: the FMU file {fmu.path} is FMI "
                            f"{fmu.model_description.fmiVersion}")
    for key, value in spec["parameters"].items():
        var = fmu.variables.get(key)
        if var is None or var.causality not in ("parameter", "input"):
            raise ScenarioError(f"fmus.{fmu.name}.parameters.{key}: the FMU file {fmu.path} has no parameter {key!r}")
        low = float(var.min) if var.min is not None else -math.inf
        high = float(var.max) if var.max is not None else math.inf
        if not low <= float(value) <= high:
            raise ScenarioError(f"fmus.{fmu.name}.parameters.{key} = {value!r}: outside the range [{low:g}, {high:g}] "
                                f"the FMU file {fmu.path} declares")


def fmu_error_in_scenario(scenario: Scenario, exc: FmuError) -> ScenarioError:
    """An :class:`~cosim.errors.FmuError` told in the scenario's words: the
    key that brought the FMU (or the parameter it refused), the file, the cause."""
    spec = scenario.fmus.get(exc.instance, {})
    if getattr(exc, "setting", None) is not None:  # the scenario's own setting does not fit the file
        key, value = exc.setting
        return ScenarioError(f"fmus.{exc.instance}.{key} = {value!r}: {exc.cause} file {exc.path}")
    if getattr(exc, "variable", None) is not None:
        said = exc.log or exc.reason
        return ScenarioError(f"fmus.{exc.instance}.parameters.{exc.variable} = {exc.value!r}: refused by the FMU "
                             f"{exc.path}: {said}")
    if "model" in spec:
        return ScenarioError(f"fmus.{exc.instance}.model = {spec['model']!r} ({exc.path}): {exc.reason}")
    return ScenarioError(f"fmus.{exc.instance}.path = {str(exc.path)!r}: {exc.reason}")


def _make_fmus(scenario: Scenario, fmu_files: Mapping[str, Path]) -> list:
    from .fmu_component import FmuComponent

    fmus = []
    try:
        for name, spec in scenario.fmus.items():
            fmu = FmuComponent(name, fmu_files.get(name) or fmu_file(spec), seed_parameter=spec.get("seed_parameter"),
                               seed_stream=spec.get("seed_stream", 0))
            fmus.append(fmu)
            fmu.instantiate()  # a file that cannot run is refused now, before anything is written
            check_fmu_file(scenario, fmu)
    except FmuError as exc:
        for fmu in fmus:
            fmu.close()
        raise fmu_error_in_scenario(scenario, exc) from None
    except BaseException:
        for fmu in fmus:
            fmu.close()
        raise
    return fmus


def _make_component(name: str, spec: Mapping[str, Any], context: registry.BuildContext):
    if "kind" in spec:
        return registry.component_kinds()[spec["kind"]].build(name, spec["parameters"], context)
    module, _, attr = spec["factory"].partition(":")
    try:
        factory = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ScenarioError(f"components.{name}.factory = {spec['factory']!r}: {exc}") from None
    return factory(name=name, **spec["parameters"])


def build_master(scenario: Scenario, fmu_files: Mapping[str, Path] | None = None):
    """A :class:`~cosim.master.Master` for ``scenario`` (FMUs built on demand
    and instantiated at once, so a file that cannot run is refused here). A
    component kind may build an :class:`~cosim.fmu_component.FmuComponent` (with its
    ``parameters`` and ``seed_parameter``); it then runs as an FMU.

    ``fmu_files`` may give, per instance, an FMU file or an extracted FMU
    directory to use instead (sweeps extract once and share it).
    """
    from .master import Master

    from .fmu_component import FmuComponent

    fmus = _make_fmus(scenario, dict(fmu_files or {}))
    try:
        context = registry.BuildContext(scenario, {f.name: f for f in fmus})
        built = [_make_component(name, spec, context) for name, spec in scenario.components.items()]
        # a kind may build its component as an FMU (e.g. a controller in FMU form)
        python = [c for c in built if not isinstance(c, FmuComponent)]
        for fmu in (c for c in built if isinstance(c, FmuComponent)):
            fmus.append(fmu)
            fmu.instantiate()
        return Master(fmus, python, scenario.connections, scenario.step, scenario.record, scenario.envelope,
                      {name: spec["parameters"] for name, spec in scenario.fmus.items()},
                      ordering=scenario.ordering)
    except BaseException:
        for fmu in fmus:
            fmu.close()
        raise
