"""What a scenario may name, registered by the packages that provide it.

The engine knows no model, component or mission by name. Applications
register:

* :class:`ComponentKind` -- a kind of Python component, named by
  ``[components.NAME] kind = "..."``; it may also own a short top-level
  section (an *alias*: ``[trajectory]`` for ``[components.reference]``);
* :class:`Section` -- a top-level table that is no component (e.g. a
  shorthand that sets FMU parameters, or the signals a metric compares);
* :class:`RegisteredModel` -- a model the engine builds into an FMU on demand, named
  by ``[fmus.NAME] model = "..."``;
* folders of shipped scenario files, loadable by name;
* :class:`Case` -- a named set of scenario overrides a study may name
  (``[cases.NAME]``): e.g. a controller variant, an option row;
* a cache folder (:func:`register_cache`), where the engine may keep what
  it derived from files and code that have not changed since: the plugins
  installed, validated scenarios (:mod:`cosim.scenario_cache`). Without
  one, everything is derived again in every process.

Registration happens when the providing package is imported, and packages
installed with an entry point in the group ``cosim.plugins`` (a callable
that registers) are imported the first time a registry is read, so a
scenario file finds its kinds without the caller importing anything.
Which entry points are installed is read once and kept in the cache folder
(``plugins/``) for as long as the distributions' metadata folders on
``sys.path`` are the same, each with its modification time (installing,
upgrading or removing a distribution makes, renames, rewrites or removes
its metadata folder): reading every installed distribution's metadata, and
importing :mod:`importlib.metadata`, took longer than validating a scenario.
"""
from __future__ import annotations

import os
import re
import sys
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

from ..cache import cache_folder, register_cache

__all__ = ["ComponentKind", "Section", "RegisteredModel", "Case", "BuildContext", "register_component_kind", "build_fmu_models", "write_fmu_models",
           "register_section", "register_fmu_model", "register_scenarios", "register_studies", "register_case", "register_cases", "component_kinds",
           "sections", "fmu_models", "cases", "aliases", "scenario_folders", "study_folders", "files_by_name", "scoped", "with_connections", "version",
           "register_table_fmu", "table_fmu", "register_cache", "cache_folder", "signature", "PLUGIN_GROUP"]

PLUGIN_GROUP = "cosim.plugins"


@dataclass(frozen=True)
class BuildContext:
    """What a component factory may look at while the master is built: the
    scenario and the FMU components already made (by instance name), e.g.
    to take a plant's parameters as a controller's nominal model."""

    scenario: Any
    fmus: Mapping[str, Any]


@dataclass(frozen=True)
class ComponentKind:
    """A kind of Python component.

    ``parameters()`` returns the declaration of its table (a
    :class:`cosim.scenario.schema.Table`: the keys, their types and checks, in its own
    words), loaded when a scenario is first read (so registering imports
    nothing heavy); ``build(name,
    parameters, context)`` returns the component (a
    :class:`~cosim.component.PythonComponent`, or an
    :class:`~cosim.fmi.fmu.FmuComponent`) from the table's values as
    the document gave them. ``alias`` is a top-level section that stands
    for ``[components.<instance>]`` of this kind; several kinds may share
    one alias section, whose ``kind`` key then picks among them
    (``[trajectory] kind = "two_circles"``). ``reads_files``: validating
    its table reads a file the table names (not only the table's text), so
    a scenario holding one is validated every time it is read
    (:mod:`cosim.scenario_cache`).
    """

    name: str
    build: Callable[[str, Mapping[str, Any], BuildContext], Any]
    parameters: Callable[[], type]
    description: str = ""
    alias: str | None = None
    instance: str | None = None
    reads_files: bool = False  # its table names files that validating it reads: never served from a cache


@dataclass(frozen=True)
class Section:
    """A top-level scenario table that is no component.

    ``parameters()`` returns the declaration of the table (a
    :class:`cosim.scenario.schema.Table`, loaded when a scenario is first read);
    ``apply(where, table, fmus)`` takes the validated table and returns the
    section's value (``Scenario.sections[name]``); it may set FMU parameters
    in ``fmus`` (``{instance: {"parameters": {...}, ...}}``), raising
    :class:`~cosim.errors.ScenarioError` naming ``where.key`` for what only
    the whole scenario can tell (an FMU it names that does not exist).
    ``reads_files``: as :attr:`ComponentKind.reads_files`.
    """

    name: str
    parameters: Callable[[], type]
    apply: Callable[[str, Any, dict[str, dict[str, Any]]], Any]
    description: str = ""
    reads_files: bool = False  # as ComponentKind.reads_files


@dataclass(frozen=True)
class RegisteredModel:
    """A model built into an FMU on demand.

    ``build(fmi_version)`` returns the path of the FMU (cached by the
    builder). ``check_parameter(name, value)``, if given, refuses an unknown
    name with ``KeyError`` and an inadmissible value with ``ValueError``,
    both naming the variable, so a scenario is checked before any build.
    ``build_with(values, fmi_version)``, if given, returns the path of an FMU
    of the model whose start values (its modelDescription's and its
    binary's) are ``values`` (parameter or input name -> value): a
    self-contained FMU, which runs a scenario's values in a tool that
    ignores the values an SSP archive binds (:func:`cosim.ssp.export.export_ssp`).
    ``definition()``, if given, returns the CasADi definition the FMU is
    generated from (its ``functions`` ``init``, ``step``, ``out`` and its
    ``states``, ``inputs``, ``outputs``, ``parameters`` in vector order, as
    :class:`fmu_models.export.model.FmuModel` has them): the calibrator
    differentiates it instead of the FMU (:mod:`cosim.calibration.symbolic`).
    """

    name: str
    build: Callable[[int], Path]
    check_parameter: Callable[[str, float], None] | None = None
    build_with: Callable[[Mapping[str, float], int], Path] | None = None
    definition: Callable[[], Any] | None = None


@dataclass(frozen=True)
class Case:
    """A named set of scenario overrides: a row of a table, a variant, an option.

    ``overrides`` are dotted keys as ``--set`` takes them; ``connect`` are
    connections added to the scenario's (those it already has are kept
    once); ``seeds`` the case's own seeds (``None``: the study's)."""

    name: str
    overrides: Mapping[str, Any] = field(default_factory=dict)
    connect: tuple[str, ...] = ()
    label: str = ""
    seeds: tuple[int, ...] | None = None

    def applied_to(self, raw: Mapping[str, Any]) -> dict[str, Any]:
        """The dotted overrides that fly this case on the scenario document ``raw``."""
        out = dict(self.overrides)
        if self.connect:
            out["connections"] = with_connections(raw.get("connections", []), self.connect)
        return out

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "label": self.label, "overrides": dict(self.overrides),
                "connect": list(self.connect), "seeds": None if self.seeds is None else list(self.seeds)}


def with_connections(existing: Sequence[str], added: Sequence[str]) -> list[str]:
    """``existing`` and then those of ``added`` it lacks."""
    return list(existing) + [c for c in added if c not in existing]


_KINDS: dict[str, ComponentKind] = {}
_SECTIONS: dict[str, Section] = {}
_MODELS: dict[str, RegisteredModel] = {}
_CASES: dict[str, Case] = {}
_CASE_SOURCES: list[Callable[[], Iterable[Case]]] = []  # cases registered when cases are first read
_SCENARIO_FOLDERS: list[Path] = []
_STUDY_FOLDERS: list[Path] = []
_TABLE_FMU: list[Callable[[Any, int], Path]] = []  # at most one: the builder of the signal table's FMU
_plugins_loaded = False
_VERSION = [0]  # bumped by every change of the registry (the scenario's declaration is rebuilt)


def _register(table: dict, key: str, entry: Any, what: str) -> None:
    if table.get(key, entry) != entry:
        raise ValueError(f"{what} {key!r} is registered twice, differently")
    if key not in table:
        _VERSION[0] += 1
    table[key] = entry


def version() -> int:
    """A number that changes whenever something is registered or unregistered."""
    _load_plugins()
    return _VERSION[0]


def register_component_kind(kind: ComponentKind) -> ComponentKind:
    if kind.alias is not None and kind.alias in _SECTIONS:
        raise ValueError(f"alias section [{kind.alias}] of kind {kind.name!r} is already a section")
    _register(_KINDS, kind.name, kind, "component kind")
    return kind


def register_section(section: Section) -> Section:
    if any(k.alias == section.name for k in _KINDS.values()):
        raise ValueError(f"section [{section.name}] is already an alias of a component kind")
    _register(_SECTIONS, section.name, section, "section")
    return section


def register_fmu_model(model: RegisteredModel) -> RegisteredModel:
    _register(_MODELS, model.name, model, "FMU model")
    return model


def build_fmu_models(fmi_versions: Sequence[int]) -> list[tuple[str, int, Path]]:
    """Build every registered model in each of ``fmi_versions``, side by side:
    ``(name, version, path)`` in registration order, each version's FMUs
    after the previous version's (the second links the objects the first
    compiled).

    One thread per FMU, so every build is queued at once: a builder that
    stages one model at a time and runs the largest compile waiting first
    (:mod:`fmu_models.export.build`) keeps every core compiling from its
    first model staged to the end, where a thread per core staged a model
    and then waited for its own compiles (the largest, staged late,
    compiled alone at the end). ``fnn-cosim build-fmu`` and the test
    session's first build (tests/conftest.py) use it."""
    from concurrent.futures import ThreadPoolExecutor

    builds = [(name, model, version) for version in fmi_versions for name, model in fmu_models().items()]
    with ThreadPoolExecutor(max(1, len(builds))) as pool:
        paths = list(pool.map(lambda b: b[1].build(b[2]), builds))
    return [(name, version, path) for (name, _, version), path in zip(builds, paths)]


def write_fmu_models(out: Path, fmi_versions: Sequence[int]) -> Iterator[Path]:
    """Every registered model built in each of ``fmi_versions``
    (:func:`build_fmu_models`) and copied into the folder ``out`` (made) as
    ``fmi<version>/<name>.fmu``; yields each file written, in the order
    built (``fnn-cosim build-fmu``)."""
    import shutil

    for name, version, path in build_fmu_models(fmi_versions):
        target = Path(out) / f"fmi{version}" / f"{name}.fmu"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, target)
        yield target


def register_table_fmu(build: Callable[[Any, int], Path]) -> None:
    """The builder of the signal table's FMU form (``kind = "signal_table"``,
    :mod:`cosim.scenario.signal_table`): ``build(table, fmi_version)`` returns the path of an
    FMU playing ``table`` (a :class:`cosim.scenario.signal_table.TableData`) from its own
    resources; the engine builds no FMU itself. One per process: a second,
    different one is refused."""
    if _TABLE_FMU and _TABLE_FMU[0] != build:
        raise ValueError("a table FMU builder is registered twice, differently")
    if not _TABLE_FMU:
        _TABLE_FMU.append(build)
        _VERSION[0] += 1


def table_fmu() -> Callable[[Any, int], Path] | None:
    """The registered table FMU builder (:func:`register_table_fmu`), or ``None``."""
    _load_plugins()
    return _TABLE_FMU[0] if _TABLE_FMU else None


def register_case(case: Case) -> Case:
    _sourced_cases()
    _register(_CASES, case.name, case, "case")
    return case


def register_cases(source: Callable[[], Iterable[Case]]) -> None:
    """Cases registered when cases are first read (:func:`cases`):
    ``source()`` returns them, in order. A run names no case: what defines
    the cases (their module, their classes) is loaded only for a study."""
    _CASE_SOURCES.append(source)


def _sourced_cases() -> None:
    while _CASE_SOURCES:
        for case in _CASE_SOURCES.pop(0)():
            _register(_CASES, case.name, case, "case")


def register_scenarios(folder: str | Path) -> None:
    """A folder of ``*.toml`` scenario files, loadable by their stem."""
    folder = Path(folder)
    if folder not in _SCENARIO_FOLDERS:
        _SCENARIO_FOLDERS.append(folder)


def register_studies(folder: str | Path) -> None:
    """A folder of ``*.toml`` study files, loadable by their stem
    (:func:`cosim.study.definition.study_path`), as :func:`register_scenarios` for scenarios."""
    folder = Path(folder)
    if folder not in _STUDY_FOLDERS:
        _STUDY_FOLDERS.append(folder)


# register_cache and cache_folder (imported above, part of this module's API): where the engine may keep
# derived data is held by cosim.cache, which every module keeping data there reads (an FMU component's
# description too, and cosim.fmi.fmu may not import this module: cosim.scenario.signal_table, which it imports, does).


def _path_signature() -> list[list[Any]]:
    """The distributions' metadata folders in each folder of ``sys.path``,
    each with its modification time: what installing, upgrading or removing
    a distribution changes (its metadata folder made, renamed with the
    version, rewritten or removed)."""
    out: list[list[Any]] = []
    for entry in sys.path:
        try:
            with os.scandir(entry or ".") as found:
                out.append([entry, sorted([e.name, e.stat().st_mtime_ns] for e in found
                                          if e.name.endswith((".dist-info", ".egg-info")))])
        except NotADirectoryError:  # a zip file: its own modification time
            out.append([entry, os.stat(entry).st_mtime_ns])
        except OSError:  # nothing there
            out.append([entry, None])
    return out


def _plugin_entries() -> list[tuple[str, str]]:
    """``(name, "module:attribute")`` of every installed entry point of
    :data:`PLUGIN_GROUP`: kept in the cache folder while the distributions'
    metadata folders on ``sys.path`` are unchanged (:func:`_path_signature`),
    else read from the distributions' metadata."""
    from ..cache import drop, key_of, read, write

    signature = _path_signature()
    key = key_of(signature)  # one entry per sys.path (python -m and the fnn-cosim script see different ones)
    known = read("plugins", key)
    if isinstance(known, dict) and known.get("path") == signature:
        try:
            return [(name, value) for name, value in known["entries"] if isinstance(name, str) and isinstance(value, str)]
        except (KeyError, TypeError, ValueError):  # not what this function keeps: read the metadata
            drop("plugins", key)
    from importlib.metadata import entry_points  # slow to import: only when not kept

    entries = [(e.name, e.value) for e in entry_points(group=PLUGIN_GROUP)]
    write("plugins", key, {"path": signature, "entries": entries})
    return entries


# an entry point's value, as the packaging specification writes it: module[:attribute.path] [extras]
_ENTRY_VALUE = re.compile(r"^(?P<module>[\w.]+)\s*(?::\s*(?P<attr>[\w.]+)\s*)?(?:\[.*\]\s*)?$")


def _load_entry(value: str) -> Any:
    """The object an entry point's value names (what ``EntryPoint.load`` does)."""
    from importlib import import_module

    match = _ENTRY_VALUE.match(value)
    if match is None:
        raise ValueError(f"entry point {value!r} of {PLUGIN_GROUP}: expected 'module:attribute'")
    obj = import_module(match["module"])
    for part in (match["attr"] or "").split(".") if match["attr"] else ():
        obj = getattr(obj, part)
    return obj


def _load_plugins() -> None:
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    for _, value in _plugin_entries():
        _load_entry(value)()


def signature() -> list[str]:
    """What is registered, by name and by the code that provides it
    (``module:qualified name`` of every callable), the same in every process
    that registers the same things: part of a cache key."""
    _load_plugins()

    def code(fn: Any) -> str:
        fn = getattr(fn, "func", fn)  # a functools.partial: its function
        return f"{getattr(fn, '__module__', '')}:{getattr(fn, '__qualname__', type(fn).__qualname__)}"

    out = [f"kind {k.name} {code(k.build)} {code(k.parameters)} {k.alias} {k.instance} {k.reads_files}"
           for k in _KINDS.values()]
    out += [f"section {s.name} {code(s.parameters)} {code(s.apply)} {s.reads_files}" for s in _SECTIONS.values()]
    out += [f"model {m.name} {code(m.build)} {code(m.check_parameter)}" for m in _MODELS.values()]
    return out


def component_kinds() -> dict[str, ComponentKind]:
    _load_plugins()
    return dict(_KINDS)


def aliases() -> dict[str, tuple[ComponentKind, ...]]:
    """Alias section -> the kinds that share it."""
    out: dict[str, tuple[ComponentKind, ...]] = {}
    for kind in component_kinds().values():
        if kind.alias is not None:
            out[kind.alias] = out.get(kind.alias, ()) + (kind,)
    return out


def sections() -> dict[str, Section]:
    _load_plugins()
    return dict(_SECTIONS)


def fmu_models() -> dict[str, RegisteredModel]:
    _load_plugins()
    return dict(_MODELS)


def cases() -> dict[str, Case]:
    """The registered cases, in registration order."""
    _load_plugins()
    _sourced_cases()
    return dict(_CASES)


def scenario_folders() -> list[Path]:
    _load_plugins()
    return list(_SCENARIO_FOLDERS)


def study_folders() -> list[Path]:
    _load_plugins()
    return list(_STUDY_FOLDERS)


def files_by_name(folders: list[Path]) -> dict[str, Path]:
    """The ``*.toml`` files of ``folders`` by stem, the first folder's first
    (the shipped scenarios and studies)."""
    out: dict[str, Path] = {}
    for folder in folders:
        for path in sorted(folder.glob("*.toml")):
            out.setdefault(path.stem, path)
    return out


@contextmanager
def scoped():
    """Registrations made inside the ``with`` block are undone at its end
    (tests that register toys leave the process's registry as they found it)."""
    _load_plugins()
    _sourced_cases()
    saved = (dict(_KINDS), dict(_SECTIONS), dict(_MODELS), dict(_CASES), list(_SCENARIO_FOLDERS), list(_STUDY_FOLDERS))
    try:
        yield
    finally:
        for table, before in zip((_KINDS, _SECTIONS, _MODELS, _CASES), saved[:4]):
            table.clear()
            table.update(before)
        _SCENARIO_FOLDERS[:] = saved[4]
        _STUDY_FOLDERS[:] = saved[5]
        _VERSION[0] += 1


def _register_engine_kinds() -> None:
    """The engine's own component kind: the signal table (:mod:`cosim.scenario.signal_table`),
    imported only when a scenario builds or declares one."""
    def build(name: str, parameters: Mapping[str, Any], context: BuildContext) -> Any:
        from .signal_table import build as build_table

        return build_table(name, parameters, context, table_fmu())

    def parameters() -> type:
        from .signal_table import TableSpec

        return TableSpec

    register_component_kind(ComponentKind("signal_table", build, parameters,
                                          "a recorded CSV or Parquet table played as outputs (docs/cosim.md, "
                                          "'The signal table')", reads_files=True))


_register_engine_kinds()
