"""From a scenario to a master: the FMUs it names built or found, instantiated
and checked against the scenario (their parameters, their sample periods),
its Python components made by their registered kinds or factories, and the
:class:`~cosim.loop.master.Master` that runs them (:func:`build_master`); an FMU's
error told in the scenario's words (:func:`fmu_error_in_scenario`). The
scenario itself, its declaration and its document: :mod:`cosim.scenario.definition`.
"""
from __future__ import annotations

import importlib
import math
from pathlib import Path
from typing import Any, Mapping

from . import registry
from ..errors import CosimError, FmuError, ScenarioError
from ..fmi.description import start_value_rule
from ..names import nearest_told
from .definition import Scenario
from ..time_grid import runs_at

__all__ = ["build_master", "fmu_file", "fmu_file_or_model", "fmu_error_in_scenario", "check_fmu_file", "fmu_component", "fmu_values"]


def fmu_file_or_model(name_or_path: str | Path, fmi_version: int, where: str) -> Path:
    """An FMU file as given, else the registered model of that name built as
    FMI ``fmi_version`` (on demand, cached); a one-line ``ScenarioError``
    naming ``where`` and the models otherwise."""
    if Path(name_or_path).exists():
        return Path(name_or_path)
    models = registry.fmu_models()
    if str(name_or_path) in models:
        return models[str(name_or_path)].build(fmi_version)
    raise ScenarioError(f"{where} {str(name_or_path)!r}: no such FMU file, and no model of that name "
                        f"(models: {', '.join(models)})")


def fmu_file(spec: Mapping[str, Any]) -> Path:
    """The FMU file of an ``[fmus.X]`` entry (a registered model is built on demand)."""
    if "path" in spec:
        return Path(spec["path"])
    return registry.fmu_models()[spec["model"]].build(spec["fmi_version"])


def check_fmu_file(scenario: Scenario, fmu) -> None:
    """What the scenario says of an FMU file (its FMI version, its
    parameters and their declared ranges, the step of a sampled-data FMU)
    against what the file declares; a value the FMU refuses although its
    description allows it is refused at start-up, quoting the FMU
    (:func:`fmu_error_in_scenario`)."""
    spec = scenario.fmus[fmu.name]
    version = spec.get("fmi_version")
    if version is not None and fmu.fmi_version != version:
        raise ScenarioError(f"fmus.{fmu.name}.fmi_version = {version}: the FMU file {fmu.path} is FMI "
                            f"{fmu.model_description.fmiVersion}")
    for key, value in spec["parameters"].items():
        var = fmu.variables.get(key)
        if var is None or var.causality not in ("parameter", "input"):
            raise ScenarioError(f"fmus.{fmu.name}.parameters.{key}: the FMU file {fmu.path} has no parameter {key!r}"
                                + nearest_told(key, [n for n, v in fmu.variables.items()
                                                 if v.causality in ("parameter", "input")]))
        low = float(var.min) if var.min is not None else -math.inf
        high = float(var.max) if var.max is not None else math.inf
        if not low <= float(value) <= high:
            raise ScenarioError(f"fmus.{fmu.name}.parameters.{key} = {value!r}: outside the range [{low:g}, {high:g}] "
                                f"the FMU file {fmu.path} declares")
    for key, value in spec.get("start", {}).items():
        var = fmu.variables.get(key)
        why = "is a parameter: give it in 'parameters'" if getattr(var, "causality", None) == "parameter" else \
            start_value_rule(var)
        if why:
            raise ScenarioError(f"fmus.{fmu.name}.start.{key} = {value!r}: {key!r} {why} (the FMU file {fmu.path})"
                                + (nearest_told(key, fmu.variables) if var is None else ""))
    if fmu.model_exchange:
        try:
            fmu.solver.substeps(scenario.step)
        except ValueError as exc:
            raise ScenarioError(f"fmus.{fmu.name}.solver.step = {fmu.solver.step!r}: {exc}") from None
    elif "solver" in spec:
        raise ScenarioError(f"fmus.{fmu.name}.solver: the FMU runs in {fmu.interface}; a solver is for Model Exchange")
    _check_sample_period(fmu, spec["parameters"], scenario.step, f"fmus.{fmu.name}.parameters")


def _check_sample_period(fmu, parameters: Mapping[str, Any], step: float, where: str) -> None:
    """A sampled-data FMU (one that declares its period parameter,
    :attr:`~cosim.fmi.fmu.FmuComponent.sample_period`) takes one
    communication step only, the period it runs with (``parameters``' value,
    else the file's start value): refuse another step before anything runs,
    naming ``where.<parameter>``."""
    name = fmu.sample_period
    if name is None:
        return
    given = name in parameters
    value = parameters[name] if given else fmu.variables[name].start
    if value is None:  # no value to compare: the FMU's own doStep is the check
        return
    period = float(value)
    if not runs_at(step, period):
        told = f"{value!r}" if given else f"{period!r} (the file's start value)"
        raise ScenarioError(f"{where}.{name} = {told}: a sampled-data FMU runs at its period; the communication "
                            f"step is {step!r} s")


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
    if exc.instance not in scenario.fmus:  # an FMU a component kind built (e.g. the controller's FMU form)
        return ScenarioError(f"{exc.instance} (its FMU {exc.path}): {exc.reason}")
    return ScenarioError(f"fmus.{exc.instance}.path = {str(exc.path)!r}: {exc.reason}")


def fmu_component(name: str, spec: Mapping[str, Any], path: Path):
    """The :class:`~cosim.fmi.fmu.FmuComponent` of an ``[fmus.X]``
    entry (its seeding, interface and solver) for the FMU file ``path``."""
    from ..fmi.fmu import FmuComponent

    solver = None
    if "solver" in spec:
        from ..fmi.model_exchange import SolverSettings  # only then: a Co-Simulation run loads no solver

        solver = SolverSettings(**spec["solver"])
    return FmuComponent(name, path, seed_parameter=spec.get("seed_parameter"), seed_stream=spec.get("seed_stream", 0),
                        interface=spec.get("interface"), solver=solver)


def _make_fmus(scenario: Scenario, fmu_files: Mapping[str, Path]) -> list:
    fmus = []
    try:
        for name, spec in scenario.fmus.items():
            fmu = fmu_component(name, spec, fmu_files.get(name) or fmu_file(spec))
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
    where = f"components.{name}.factory = {spec['factory']!r}"
    module, _, attr = spec["factory"].partition(":")
    try:
        factory = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    except Exception as exc:  # the module itself failed to import (the user's code)
        raise ScenarioError(f"{where}: importing {module} failed: {type(exc).__name__}: {exc}") from None
    if not callable(factory):
        raise ScenarioError(f"{where}: {type(factory).__name__} {attr!r} is not callable")
    try:
        component = factory(name=name, **dict(spec["parameters"]))
    except CosimError:
        raise
    except Exception as exc:  # the user's own code refused its parameters, or failed
        raise ScenarioError(f"{where}: calling it with name={name!r} and {dict(spec['parameters'])!r} failed: "
                            f"{type(exc).__name__}: {exc}") from None
    from ..fmi.fmu import FmuComponent

    for port in (() if isinstance(component, FmuComponent) else ("inputs", "outputs", "step", "start")):
        if not hasattr(component, port):
            raise ScenarioError(f"{where}: it returned a {type(component).__name__}, not a component "
                                f"(no {port!r}; cosim.component.PythonComponent)")
    return component


def fmu_values(scenario: Scenario) -> dict[str, dict[str, Any]]:
    """What a run sets on each ``[fmus]`` instance before it starts: its
    parameters, then its start values (the master's ``fmu_parameters``)."""
    return {name: {**spec["parameters"], **spec.get("start", {})} for name, spec in scenario.fmus.items()}


class _WatchedScenario:
    """``scenario`` as a component factory sees it (:class:`registry.BuildContext`),
    noting in ``reads`` the ``[fmus]`` instances whose entry it looked at (all
    of them for the document or the sections, which hold their values)."""

    def __init__(self, scenario: Scenario, reads: set[str]):
        self._scenario, self._reads = scenario, reads

    def __getattr__(self, key: str) -> Any:
        if key in ("raw", "sections"):
            self._reads.update(self._scenario.fmus)
        value = getattr(self._scenario, key)
        return _WatchedFmus(value, self._reads) if key == "fmus" else value


class _WatchedFmus(Mapping):
    def __init__(self, fmus: Mapping[str, Any], reads: set[str]):
        self._fmus, self._reads = fmus, reads

    def __getitem__(self, name: str) -> Any:
        value = self._fmus[name]  # a missing name reads nothing
        self._reads.add(name)
        return value

    def __iter__(self):
        self._reads.update(self._fmus)  # a loop may read any entry
        return iter(self._fmus)

    def __len__(self) -> int:
        return len(self._fmus)

    def __contains__(self, name: object) -> bool:
        return name in self._fmus


def build_master(scenario: Scenario, fmu_files: Mapping[str, Path] | None = None, reads: set[str] | None = None):
    """A :class:`~cosim.loop.master.Master` for ``scenario`` (FMUs built on demand
    and instantiated at once, so a file that cannot run is refused here). A
    component kind may build an :class:`~cosim.fmi.fmu.FmuComponent` (with its
    ``parameters`` and ``seed_parameter``); it then runs as an FMU.

    ``fmu_files`` may give, per instance, an FMU file or an extracted FMU
    directory to use instead (sweeps extract once and share it). ``reads``,
    if given, collects the ``[fmus]`` instances whose entry (parameters,
    start values) a component factory read: the master serves the values of
    the others as they come (:class:`cosim.study.runner.MasterCache`).
    """
    from ..loop.master import Master

    from ..fmi.fmu import FmuComponent

    fmus = _make_fmus(scenario, dict(fmu_files or {}))
    try:
        seen = _WatchedScenario(scenario, reads) if reads is not None else scenario
        context = registry.BuildContext(seen, {f.name: f for f in fmus})
        built = [_make_component(name, spec, context) for name, spec in scenario.components.items()]
        # a kind may build its component as an FMU (e.g. a controller in FMU form)
        python = [c for c in built if not isinstance(c, FmuComponent)]
        for fmu in (c for c in built if isinstance(c, FmuComponent)):
            fmus.append(fmu)
            fmu.instantiate()
            _check_sample_period(fmu, fmu.base_parameters, scenario.step, fmu.name)  # the kind set its parameters
        return Master(fmus, python, scenario.connections, scenario.step, scenario.record, scenario.envelope,
                      fmu_values(scenario), ordering=scenario.ordering, coupling=scenario.coupling)
    except BaseException:
        for fmu in fmus:
            fmu.close()
        raise
