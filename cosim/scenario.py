"""Scenarios: TOML files describing a co-simulation, validated before anything runs.

Schema (every key optional unless marked; units SI; see ``docs/cosim.md``)::

    name = "circles"                     # str, default: the file name
    description = "..."                  # str
    connections = ["A.out -> B.in", ...] # required; brace groups expand: "A.{x,y} -> B.{x,y}"

    [simulation]
    duration = 50.0                      # s, > 0, a whole number of steps
    step = 0.01                          # s, > 0
    seed = 0                             # int >= 0: the controller's f_ij(0)
    start_time = 0.0                     # s

    [fmus.<Name>]                        # one table per FMU instance, at least one
    model = "Quadrotor"                  # a model of fmu_models.catalog (built on demand), or
    path = "other.fmu"                   #   an FMU file (relative to the scenario file)
    fmi_version = 2                      # 2 or 3: the version built (catalog models, default 2) or the
                                         #   version the file must have (FMU files, default: any)
    parameters = { z_0 = -15.0 }         # checked against the model's variables and ranges

    [wind]                               # shorthand for the WindGust FMU's parameters
    fmu = "WindGust"                     # the instance it configures
    speed = 3.0                          # m/s            -> v_w
    direction = [-1.0, -1.0, 0.0]        # 1, non-zero    -> dir_x, dir_y, dir_z
    switch_times = [17.0, 34.0]          # s, increasing  -> t_switch_1, t_switch_2
    ramp_time = 0.0                      # s              -> ramp_time
    turbulence = 0.0                     # m/s RMS        -> turbulence
    turbulence_seed = 0                  # int            -> turbulence_seed

    [trajectory]                         # the Python component "reference"
    kind = "two_circles"                 # hover | two_circles | figure_eight
    radius = 10.0                        # ... the parameters of that kind

    [controller]                         # the Python component "controller"
    variant = "pd+lm"                    # pd | pd+smc | pd+lm
    psi_ref = 0.0                        # rad
    [controller.position]                # fnn_controller.PositionParams fields (kp, kd, ...)
    [controller.geometric]               # fnn_controller.GeometricParams fields (k_v, ...)

    [components.<name>]                  # any other Python component
    factory = "package.module:Class"     # called with name=<name> and **parameters
    parameters = { ... }

    [record]
    signals = ["Quadrotor.x", ...]       # what the results CSV holds (after time)
    block_rows = 100                     # rows per flushed block

    [envelope]                           # divergence bounds, [low, high] per signal
    "Quadrotor.phi" = [-1.4, 1.4]

    [metrics]                            # what the summary computes (optional)
    position = ["Quadrotor.x", "Quadrotor.y", "Quadrotor.z"]
    reference = ["reference.x", "reference.y", "reference.z"]

Errors are :class:`~cosim.errors.ScenarioError` naming the key and value.
"""
from __future__ import annotations

import copy
import importlib
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from .config import check_number
from .errors import ScenarioError

__all__ = ["Scenario", "load_scenario", "parse_scenario", "shipped_scenarios", "scenario_path",
           "apply_overrides", "build_master", "fmu_error_in_scenario", "WIND_KEYS"]

_TOP = {"name", "description", "connections", "simulation", "fmus", "wind", "trajectory", "controller",
        "components", "record", "envelope", "metrics"}
_SIMULATION = {"duration", "step", "seed", "start_time"}
_FMU = {"model", "path", "fmi_version", "parameters"}
WIND_KEYS = {"speed": "v_w", "ramp_time": "ramp_time", "turbulence": "turbulence",
             "turbulence_seed": "turbulence_seed"}
_WIND = {"fmu", "direction", "switch_times", *WIND_KEYS}
_CONTROLLER = {"variant", "psi_ref", "position", "geometric"}
_RECORD = {"signals", "block_rows"}
_METRICS = {"position", "reference"}


@dataclass
class Scenario:
    """A validated scenario (plain data; :func:`build_master` makes it runnable)."""

    name: str
    description: str
    duration: float
    step: float
    seed: int
    start_time: float
    fmus: dict[str, dict[str, Any]]  # name -> {"model" | "path", "fmi_version", "parameters"}
    connections: list[str]
    trajectory: dict[str, Any] | None
    controller: dict[str, Any] | None
    components: dict[str, dict[str, Any]]
    record: list[str]
    block_rows: int
    envelope: dict[str, tuple[float, float]]
    position_signals: list[str]
    reference_signals: list[str]
    wind_fmu: str | None = None
    source: Path | None = None
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    def wind_parameter(self, key: str = "speed") -> str:
        """The run-level parameter name (``Fmu.var``) of a ``[wind]`` key."""
        if self.wind_fmu is None:
            raise ScenarioError(f"scenario {self.name!r} has no [wind] section")
        return f"{self.wind_fmu}.{WIND_KEYS[key]}"


def _unknown(where: str, table: Mapping[str, Any], known: set[str]) -> None:
    extra = sorted(set(table) - known)
    if extra:
        raise ScenarioError(f"{where}{extra[0]}: unknown key; known keys: {', '.join(sorted(known))}")


def _table(where: str, value: Any) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise ScenarioError(f"{where} = {value!r}: expected a table")
    return dict(value)


def _string(where: str, value: Any) -> str:
    if not isinstance(value, str):
        raise ScenarioError(f"{where} = {value!r}: expected a string")
    return value


def _strings(where: str, value: Any) -> list[str]:
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


def _check_fmu_parameters(where: str, model_name: str, params: dict[str, Any]) -> None:
    from fmu_models.catalog import MODELS

    model = MODELS[model_name]
    for key, value in params.items():
        check_number(f"{where}.{key}", value)
        try:
            var = model.variable(key)
        except KeyError:
            known = ", ".join(v.name for v in model.parameters + model.inputs)
            raise ScenarioError(f"{where}.{key}: {model_name} has no parameter {key!r}; "
                                f"parameters and inputs: {known}") from None
        if var.causality not in ("parameter", "input"):
            raise ScenarioError(f"{where}.{key}: {key!r} is a{'n' if var.causality[0] in 'aeiou' else ''} "
                                f"{var.causality} of {model_name}, not a parameter")
        try:
            var.check(float(value))
        except ValueError as exc:
            raise ScenarioError(f"{where}.{key}: {exc}") from None


def parse_scenario(raw: Mapping[str, Any], source: Path | None = None, name: str | None = None) -> Scenario:
    """Validate a scenario given as a mapping (a parsed TOML document)."""
    from fmu_models.catalog import MODELS

    raw = dict(raw)
    _unknown("", raw, _TOP)
    sim = _table("simulation", raw.get("simulation", {}))
    _unknown("simulation.", sim, _SIMULATION)
    duration = float(check_number("simulation.duration", sim.get("duration", 50.0), positive=True))
    step = float(check_number("simulation.step", sim.get("step", 0.01), positive=True))
    n = round(duration / step)
    if n < 1 or abs(n * step - duration) > 1e-9 * max(1.0, duration):
        raise ScenarioError(f"simulation.duration = {duration!r}: not a whole number of steps of {step!r} s")
    seed = check_number("simulation.seed", sim.get("seed", 0), integer=True, nonnegative=True)
    start_time = float(check_number("simulation.start_time", sim.get("start_time", 0.0)))

    fmus_raw = _table("fmus", raw.get("fmus", {}))
    if not fmus_raw:
        raise ScenarioError("fmus: at least one [fmus.<Name>] table is required")
    fmus: dict[str, dict[str, Any]] = {}
    for inst, spec in fmus_raw.items():
        where = f"fmus.{inst}"
        spec = _table(where, spec)
        _unknown(where + ".", spec, _FMU)
        if ("model" in spec) == ("path" in spec):
            raise ScenarioError(f"{where}: give exactly one of 'model' (a catalog model) or 'path' (an FMU file)")
        # A catalog model is built in the version asked (2 by default); an FMU
        # file is what it is, and a version given for it must match (checked
        # when the file is read, in build_master).
        version = spec.get("fmi_version", 2 if "model" in spec else None)
        if version is not None:
            check_number(f"{where}.fmi_version", version, integer=True)
            if version not in (2, 3):
                raise ScenarioError(f"{where}.fmi_version = {version!r}: expected 2 or 3")
        params = _table(f"{where}.parameters", spec.get("parameters", {}))
        entry: dict[str, Any] = {"fmi_version": version, "parameters": params}
        if "model" in spec:
            model = _string(f"{where}.model", spec["model"])
            if model not in MODELS:
                raise ScenarioError(f"{where}.model = {model!r}: unknown model; known: {', '.join(sorted(MODELS))}")
            _check_fmu_parameters(f"{where}.parameters", model, params)
            entry["model"] = model
        else:
            path = Path(_string(f"{where}.path", spec["path"]))
            if not path.is_absolute() and source is not None:
                path = source.parent / path
            if not path.exists():
                raise ScenarioError(f"{where}.path = {spec['path']!r}: no such file ({path})")
            for key, value in params.items():
                check_number(f"{where}.parameters.{key}", value)
            entry["path"] = path
        fmus[inst] = entry

    wind_fmu = None
    if "wind" in raw:
        wind = _table("wind", raw["wind"])
        _unknown("wind.", wind, _WIND)
        wind_fmu = _string("wind.fmu", wind.get("fmu", "WindGust"))
        if wind_fmu not in fmus:
            raise ScenarioError(f"wind.fmu = {wind_fmu!r}: no such FMU in [fmus]; FMUs: {', '.join(fmus)}")
        params = fmus[wind_fmu]["parameters"]
        for key, target in WIND_KEYS.items():
            if key in wind:
                params[target] = check_number(f"wind.{key}", wind[key], nonnegative=True,
                                              integer=key == "turbulence_seed")
        if "direction" in wind:
            d = wind["direction"]
            if not isinstance(d, list) or len(d) != 3:
                raise ScenarioError(f"wind.direction = {d!r}: expected a list of 3 numbers")
            d = [check_number(f"wind.direction[{i}]", v) for i, v in enumerate(d)]
            if math.hypot(*d) == 0:
                raise ScenarioError(f"wind.direction = {d!r}: must not be the zero vector")
            params.update(dir_x=d[0], dir_y=d[1], dir_z=d[2])
        if "switch_times" in wind:
            s = wind["switch_times"]
            if not isinstance(s, list) or len(s) != 2:
                raise ScenarioError(f"wind.switch_times = {s!r}: expected a list of 2 times (s)")
            s = [check_number(f"wind.switch_times[{i}]", v, nonnegative=True) for i, v in enumerate(s)]
            if s[1] < s[0]:
                raise ScenarioError(f"wind.switch_times = {s!r}: the second switch must not come before the first")
            params.update(t_switch_1=s[0], t_switch_2=s[1])
        if "model" in fmus[wind_fmu]:
            _check_fmu_parameters(f"fmus.{wind_fmu}.parameters (from [wind])", fmus[wind_fmu]["model"], params)

    trajectory = None
    if "trajectory" in raw:
        from .trajectory import TRAJECTORIES

        trajectory = _table("trajectory", raw["trajectory"])
        kind = _string("trajectory.kind", trajectory.get("kind", ""))
        if kind not in TRAJECTORIES:
            raise ScenarioError(f"trajectory.kind = {kind!r}: expected one of {', '.join(TRAJECTORIES)}")
        from dataclasses import fields

        known = {f.name for f in fields(TRAJECTORIES[kind])}
        _unknown("trajectory.", {k: v for k, v in trajectory.items() if k != "kind"}, known)
        for key, value in trajectory.items():
            if key != "kind":
                check_number(f"trajectory.{key}", value)
        try:
            TRAJECTORIES[kind](**{k: float(v) for k, v in trajectory.items() if k != "kind"})
        except ValueError as exc:
            raise ScenarioError(f"trajectory: {exc}") from None

    controller = None
    if "controller" in raw:
        controller = _table("controller", raw["controller"])
        _unknown("controller.", controller, _CONTROLLER)
        from .controller import ControllerComponent

        # builds the parameter dataclasses: every gain is checked here
        for key in ("position", "geometric"):
            _table(f"controller.{key}", controller.get(key, {}))
        ControllerComponent(controller.get("variant", "pd+lm"), controller.get("position"),
                            controller.get("geometric"),
                            float(check_number("controller.psi_ref", controller.get("psi_ref", 0.0))))

    components = {}
    for cname, spec in _table("components", raw.get("components", {})).items():
        spec = _table(f"components.{cname}", spec)
        _unknown(f"components.{cname}.", spec, {"factory", "parameters"})
        factory = _string(f"components.{cname}.factory", spec.get("factory"))
        if factory.count(":") != 1:
            raise ScenarioError(f"components.{cname}.factory = {factory!r}: expected 'package.module:callable'")
        components[cname] = {"factory": factory,
                             "parameters": _table(f"components.{cname}.parameters", spec.get("parameters", {}))}

    if "connections" not in raw:
        raise ScenarioError("connections: required (a list of 'A.out -> B.in' strings)")
    connections = _strings("connections", raw["connections"])

    rec = _table("record", raw.get("record", {}))
    _unknown("record.", rec, _RECORD)
    record = _strings("record.signals", rec.get("signals", []))
    block_rows = check_number("record.block_rows", rec.get("block_rows", 100), integer=True, positive=True)

    envelope = {}
    for signal, bounds in _table("envelope", raw.get("envelope", {})).items():
        if not isinstance(bounds, list) or len(bounds) != 2:
            raise ScenarioError(f"envelope.{signal} = {bounds!r}: expected [low, high]")
        low, high = (float(check_number(f"envelope.{signal}[{i}]", b)) for i, b in enumerate(bounds))
        if not low < high:
            raise ScenarioError(f"envelope.{signal} = {bounds!r}: low must be below high")
        envelope[signal] = (low, high)

    metrics = _table("metrics", raw.get("metrics", {}))
    _unknown("metrics.", metrics, _METRICS)
    position = _strings("metrics.position", metrics.get("position", []))
    reference = _strings("metrics.reference", metrics.get("reference", []))
    if len(position) != len(reference):
        raise ScenarioError(f"metrics: position has {len(position)} signals but reference has {len(reference)}")

    name = raw.get("name", name or (source.stem if source else "scenario"))
    return Scenario(
        name=_string("name", name), description=_string("description", raw.get("description", "")),
        duration=duration, step=step, seed=seed, start_time=start_time, fmus=fmus, connections=connections,
        trajectory=trajectory, controller=controller, components=components, record=record,
        block_rows=block_rows, envelope=envelope, position_signals=position, reference_signals=reference,
        wind_fmu=wind_fmu, source=source, raw=copy.deepcopy(raw),
    )


def shipped_scenarios() -> dict[str, Path]:
    """The scenarios shipped in ``cosim/scenarios``, by name."""
    root = resources.files("cosim") / "scenarios"
    return {Path(str(p)).stem: Path(str(p)) for p in root.iterdir() if str(p).endswith(".toml")}


def scenario_path(name_or_path: str | Path) -> Path:
    """A path as given, or the shipped scenario of that name."""
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
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    return parse_scenario(apply_overrides(raw, overrides or {}), source=path)


def _fmu_file(name: str, spec: Mapping[str, Any]) -> Path:
    if "path" in spec:
        return Path(spec["path"])
    from fmu_models.build import cached_fmu
    from fmu_models.catalog import MODELS

    return cached_fmu(MODELS[spec["model"]], spec["fmi_version"])


def _check_fmu_file(scenario: Scenario, fmu) -> None:
    """What the scenario says of an FMU file (its FMI version, its
    parameters) against what the file declares."""
    spec = scenario.fmus[fmu.name]
    version = spec.get("fmi_version")
    if version is not None and fmu.fmi_version != version:
        raise ScenarioError(f"fmus.{fmu.name}.fmi_version = {version}: the FMU file {fmu.path} is FMI "
                            f"{fmu.model_description.fmiVersion}")
    for key in spec["parameters"]:
        var = fmu.variables.get(key)
        if var is None or var.causality not in ("parameter", "input"):
            raise ScenarioError(f"fmus.{fmu.name}.parameters.{key}: the FMU file {fmu.path} has no parameter {key!r}")


def fmu_error_in_scenario(scenario: Scenario, exc) -> ScenarioError:
    """An :class:`~cosim.errors.FmuError` told in the scenario's words: the
    key that brought the FMU (or the parameter it refused), the file, the cause."""
    spec = scenario.fmus.get(exc.instance, {})
    if getattr(exc, "variable", None) is not None:
        said = exc.log or exc.reason
        return ScenarioError(f"fmus.{exc.instance}.parameters.{exc.variable} = {exc.value!r}: refused by the FMU "
                             f"{exc.path}: {said}")
    if "model" in spec:
        return ScenarioError(f"fmus.{exc.instance}.model = {spec['model']!r} ({exc.path}): {exc.reason}")
    return ScenarioError(f"fmus.{exc.instance}.path = {str(exc.path)!r}: {exc.reason}")


def build_master(scenario: Scenario, fmu_files: Mapping[str, Path] | None = None):
    """A :class:`~cosim.master.Master` for ``scenario`` (FMUs built on demand).

    ``fmu_files`` may give, per instance, an FMU file or an extracted FMU
    directory to use instead (the sweeps extract once and share it).
    """
    from .controller import ControllerComponent
    from .errors import FmuError
    from .fmu import FmuComponent
    from .master import Master
    from .trajectory import ReferenceComponent, make_trajectory

    fmu_files = dict(fmu_files or {})
    fmus = []
    try:
        for name, spec in scenario.fmus.items():
            fmu = FmuComponent(name, fmu_files.get(name) or _fmu_file(name, spec))
            fmus.append(fmu)
            fmu.instantiate()  # a file that cannot run is refused now, before anything is written
            _check_fmu_file(scenario, fmu)
    except FmuError as exc:
        for fmu in fmus:
            fmu.close()
        raise fmu_error_in_scenario(scenario, exc) from None
    except ScenarioError:
        for fmu in fmus:
            fmu.close()
        raise
    python = []
    if scenario.trajectory is not None:
        params = {k: float(v) for k, v in scenario.trajectory.items() if k != "kind"}
        python.append(ReferenceComponent(make_trajectory(scenario.trajectory["kind"], **params)))
    if scenario.controller is not None:
        c = scenario.controller
        python.append(ControllerComponent(c.get("variant", "pd+lm"), c.get("position"), c.get("geometric"),
                                          float(c.get("psi_ref", 0.0))))
    for cname, spec in scenario.components.items():
        module, _, attr = spec["factory"].partition(":")
        try:
            factory = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as exc:
            raise ScenarioError(f"components.{cname}.factory = {spec['factory']!r}: {exc}") from None
        python.append(factory(name=cname, **spec["parameters"]))
    return Master(fmus, python, scenario.connections, scenario.step, scenario.record, scenario.envelope,
                  {name: spec["parameters"] for name, spec in scenario.fmus.items()})
