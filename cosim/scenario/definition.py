"""Scenarios: TOML files describing a co-simulation, validated before anything runs.

Every table is declared once (:mod:`cosim.scenario.schema`, pydantic): the generic
ones in :mod:`cosim.scenario.tables` (:class:`Simulation`, :class:`FmuSpec`,
:class:`Record`, the components and the envelope), the component kinds'
tables and the sections by the applications that register them
(:mod:`cosim.scenario.registry`). :func:`scenario_model` assembles the declaration of
a whole scenario from the registry; it validates every file and is the JSON
Schema editors read (``fnn-cosim schema scenario``). Those names are also
this module's, imported when first asked for: a scenario served from the
cache (:func:`load_scenario`) imports no pydantic.

A :class:`Scenario` is immutable and holds one copy of its data: the
document it was read from (``raw`` gives a fresh copy to change and parse
again; workers receive it); its views (``fmus``, ``components``, ...) are
read-only and derived from it. Errors are :class:`~cosim.errors.ScenarioError`
naming the key and the value, in one line. From a scenario to a master:
:mod:`cosim.scenario.assembly`.
"""
from __future__ import annotations

import copy
import hashlib
import json
import re
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

from . import registry
from ..cache import code_unchanged, drop, keep_code, key_of, read, write
from ..errors import ScenarioError, shown_text
from ..files import is_ssp, read_text, read_toml, toml_text
from ..limits import MAX_NESTING

__all__ = ["Scenario", "Simulation", "FmuSpec", "Record", "ConnectionTable", "scenario_model", "scenario_json_schema",
           "load_scenario", "parse_scenario", "shipped_scenarios", "scenario_path", "apply_overrides",
           "check_fmu_parameters"]

# the declaration's names, from cosim.scenario.tables when first asked for (PEP 562)
_DECLARED = ("Simulation", "Solver", "FmuSpec", "Record", "ConnectionTable", "FactoryComponent", "scenario_model",
             "scenario_json_schema", "check_fmu_parameters", "INTERFACES")


def __getattr__(name: str):
    if name in _DECLARED:
        from . import tables as scenario_tables

        return getattr(scenario_tables, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _state(document: dict[str, Any], source: Path | None, name: str | None) -> dict[str, Any]:
    """What a scenario holds, derived from its validated ``document``
    (:func:`cosim.scenario.tables.derived_state`)."""
    from .tables import derived_state

    return derived_state(document, source, name)



# ---- the scenario ----------------------------------------------------------------------------------

_LEAVES = frozenset((str, float, int, bool, type(None)))


def _frozen(value: Any) -> Any:
    """A read-only view of nested tables (lists become tuples)."""
    if type(value) in _LEAVES:  # the common cases first: an ABC's isinstance is slow
        return value
    if type(value) is dict or isinstance(value, Mapping):
        return MappingProxyType({k: _frozen(v) for k, v in value.items()})
    if isinstance(value, list):
        return tuple(_frozen(v) for v in value)
    return value

class Scenario:
    """A validated scenario: immutable, one copy of its data.

    ``raw`` is a fresh copy of the document (change it and parse it again:
    :func:`apply_overrides`, :func:`parse_scenario`); the rest are read-only
    views derived from it when it was validated: ``fmus`` (instance ->
    ``{"model" | "path", "fmi_version", "parameters", "seed_parameter",
    "seed_stream"}``, the sections' parameters applied), ``components``
    (instance -> ``{"kind" | "factory", "parameters"}``), ``sections`` (the
    value each registered section gave), the simulation's fields, ``record``,
    ``block_rows``, ``envelope``, ``connections``.
    """

    __slots__ = ("__weakref__", "_document", "source", "name", "description", "duration", "step", "seed", "start_time", "ordering",
                 "coupling", "fmus", "components", "connections", "record", "block_rows", "envelope", "sections")

    def __init__(self, raw: Mapping[str, Any], source: Path | None = None, name: str | None = None):
        text = json.dumps(raw)
        document = json.loads(text)  # the one copy (a TOML document is JSON data)
        self._adopt(document, source, _state(document, source, name), text)

    @classmethod
    def _of(cls, document: dict[str, Any], source: Path | None, state: Mapping[str, Any]) -> "Scenario":
        """The scenario of ``document`` (a copy of its own), whose validation
        gave ``state`` (:func:`_state`)."""
        scenario = object.__new__(cls)
        scenario._adopt(document, source, state)
        return scenario

    def _adopt(self, document: dict[str, Any], source: Path | None, state: Mapping[str, Any],
               text: str | None = None) -> None:
        """Hold ``state``, and ``document`` as its JSON ``text`` (made here when not given)."""
        set_ = object.__setattr__
        set_(self, "_document", json.dumps(document) if text is None else text)
        set_(self, "source", source)
        for key in ("name", "description", "duration", "step", "seed", "start_time", "ordering", "coupling",
                    "block_rows"):
            set_(self, key, state[key])
        set_(self, "fmus", _frozen(state["fmus"]))
        set_(self, "components", _frozen(state["components"]))
        set_(self, "sections", _frozen(state["sections"]))
        set_(self, "connections", tuple(c if isinstance(c, str) else MappingProxyType(dict(c))
                                        for c in state["connections"]))
        # None: no record.signals, every output is recorded (cosim.loop.plan.every_output)
        set_(self, "record", None if state["record"] is None else tuple(state["record"]))
        # no bound on the rows here: a run streams them (cosim.loop.recorder); only a run asked to keep every row
        # in memory (Master.run(keep=None)) is bounded, when it starts
        set_(self, "envelope", MappingProxyType({k: tuple(v) for k, v in state["envelope"].items()}))

    def __setattr__(self, key, value):
        raise AttributeError(f"a Scenario is immutable: change its document (raw) and parse it again, not {key!r}")

    @property
    def raw(self) -> dict[str, Any]:
        """A fresh copy of the document (changing it changes no scenario)."""
        return json.loads(self._document)

    @property
    def n_steps(self) -> int:
        return int(round(self.duration / self.step))

    def __repr__(self) -> str:
        return f"Scenario({self.name!r}, source={str(self.source) if self.source else None!r})"


# an FMU instance's parameter or start value, the rest being one variable name as FMI writes it
# (FMI 2.0 section 2.2.9: a.b[2,3], der(x), 'x y'), unquoted: cosim.names
_VARIABLE_KEY = re.compile(r"(fmus)\.([A-Za-z_][A-Za-z0-9_-]*)\.(parameters|start)\.([^\"\s].*)")


def dotted_key(dotted: str, where: str | None = None) -> list[str]:
    """The parts of a dotted key as TOML writes one: ``simulation.duration``,
    ``envelope."Quadrotor.phi"`` (a part holding a dot is quoted); at most
    :data:`~cosim.limits.MAX_NESTING` of them. ``where`` names the key in a
    refusal (default: ``key '...'``). After ``fmus.<instance>.parameters.``
    (or ``.start.``) the rest is one variable name as the FMU writes it,
    dots, brackets and quotes included (``fmus.V.start.a.b[2,3]``,
    ``fmus.V.parameters.'x y'``); a TOML-quoted one is read as TOML reads it."""
    where = where or f"key {shown_text(dotted)!r}"
    variable = _VARIABLE_KEY.fullmatch(dotted.strip())
    if variable:  # fmus.V.parameters.<an FMI name, dots, brackets and quotes as the FMU writes it>
        return list(variable.groups())
    if '"' not in dotted and "'" not in dotted:
        parts = dotted.split(".")
        if all(parts):
            parts = [p.strip() for p in parts]
            return _few_parts(parts, where)
    import tomllib  # a quoted part only: a run's --set keys are plain

    try:
        node: Any = tomllib.loads(f"{dotted} = 0")
    except (tomllib.TOMLDecodeError, ValueError, RecursionError):
        raise ScenarioError(f"{where}: not a dotted key (parts joined by dots; a part holding a dot or a "
                            f"space is quoted: envelope.\"Quadrotor.phi\")") from None
    parts = []
    while isinstance(node, dict) and len(node) == 1:
        key, node = next(iter(node.items()))
        parts.append(key)
    return _few_parts(parts, where)


def _few_parts(parts: list[str], where: str) -> list[str]:
    if len(parts) > MAX_NESTING:
        raise ScenarioError(f"{where}: {len(parts)} parts; at most {MAX_NESTING}")
    return parts


def apply_overrides(raw: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """A new document: ``raw`` with dotted keys set, e.g. ``{"simulation.duration": 5.0}``
    (:func:`dotted_key`). ``raw`` is left as it was: the result's tables
    along each key are new, and the rest is ``raw``'s, shared rather than
    copied (a study's run applies a few keys to a whole document;
    a :class:`Scenario` copies the document it validates). Change the
    result only along its keys, or copy it first."""
    out = dict(raw)
    own = {id(out)}  # the tables of out made here, not raw's
    for dotted, value in overrides.items():
        keys = dotted_key(dotted)
        node = out
        for k in keys[:-1]:
            if k not in node:
                nxt = node[k] = {}
            else:
                nxt = node[k]
                if not isinstance(nxt, dict):
                    raise ScenarioError(f"{dotted} = {value!r}: {k!r} is not a table")
                if id(nxt) not in own:
                    nxt = node[k] = dict(nxt)
            own.add(id(nxt))
            node = nxt
        node[keys[-1]] = copy.deepcopy(value)
    return out


def parse_scenario(raw: Mapping[str, Any], source: Path | None = None, name: str | None = None) -> Scenario:
    """Validate a scenario given as a mapping (a parsed TOML document)."""
    if not isinstance(raw, Mapping):
        raise ScenarioError(f"document = {raw!r}: expected a table")
    return Scenario(raw, source, name)


# ---- files ----------------------------------------------------------------------------

def shipped_scenarios() -> dict[str, Path]:
    """The scenarios of the registered folders, by name."""
    return registry.files_by_name(registry.scenario_folders())


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
    """Read, override and validate a scenario: ``name_or_path`` a shipped
    scenario's name (``"circles"``) or a TOML file; ``overrides`` dotted keys
    (``{"wind.speed": 3.0}``, as ``--set`` takes them) applied before the
    document is validated.

    A document validated before, by the same code, is not validated again:
    what its validation gave is kept in the registered cache folder
    (:func:`_kept_state`)."""
    path = scenario_path(name_or_path)
    folder = registry.cache_folder()
    if folder is None:
        return Scenario(json.loads(json.dumps(apply_overrides(read_toml(path), overrides or {}))), path)
    document = json.loads(json.dumps(apply_overrides(_read_document(folder, path), overrides or {})))
    key = _state_key(document, path)
    state = _kept_state(folder, key)
    if state is not None:
        try:
            return Scenario._of(document, path, state)
        except (KeyError, TypeError, ValueError, AttributeError):  # not what this module keeps: validated again
            drop("scenarios", key, folder)
    state = _state(document, path, None)
    if _keepable(document, state):
        write("scenarios", key, {"code": keep_code(folder), "state": state}, folder)
    return Scenario._of(document, path, state)


def _read_document(folder: Path, path: Path) -> dict[str, Any]:
    """:func:`~cosim.files.read_toml` of ``path``, its parse kept in ``folder``
    by the text's digest (the same text is the same document: a file read
    before is not parsed again, and no TOML parser is imported). The file
    is read, and refused, as ``read_toml`` reads it; a document JSON does
    not give back exactly is parsed every time."""
    if is_ssp(path):
        return read_toml(path)  # its refusal
    text = read_text(path, "scenario")
    key = hashlib.sha256(text.encode()).hexdigest()
    document = read("documents", key, folder)
    if isinstance(document, dict):
        return document
    document = toml_text(text, path)
    try:
        if _same(json.loads(json.dumps(document)), document):
            write("documents", key, document, folder)
    except (TypeError, ValueError):  # a value JSON does not hold
        pass
    return document


# A scenario's validation is kept (cosim.cache) when it depends on nothing but
# its document and the code: keyed by the document, its file's path (its name
# and relative paths come from it) and what is registered; valid while every
# module loaded when it was validated is unchanged. A document that names a
# file validation reads (an FMU by path, a parameter set, a component or
# section that reads files) is validated every time. A refused document is
# never kept: every error is the validation's own, every time.
_STATE_FORMAT = 1


def _state_key(document: Mapping[str, Any], source: Path) -> str:
    return key_of(_STATE_FORMAT, document, str(source), registry.signature())


def _kept_state(folder: Path, key: str) -> dict[str, Any] | None:
    kept_entry = read("scenarios", key, folder)
    if not isinstance(kept_entry, dict) or not code_unchanged(folder, kept_entry.get("code")):
        return None
    state = kept_entry.get("state")
    return state if isinstance(state, dict) else None


def _keepable(document: Mapping[str, Any], state: Mapping[str, Any]) -> bool:
    """Whether ``state`` may be kept: no file read to validate ``document``,
    and JSON gives it back exactly (types included)."""
    if any(isinstance(spec, Mapping) and ("path" in spec or "parameter_set" in spec)
           for spec in (document.get("fmus") or {}).values()):
        return False
    kinds, sections = registry.component_kinds(), registry.sections()
    if any(kinds[c["kind"]].reads_files for c in state["components"].values() if "kind" in c) or \
            any(sections[name].reads_files for name in state["sections"]):
        return False
    try:
        return _same(json.loads(json.dumps(state)), state)
    except (TypeError, ValueError):  # a value JSON does not hold (a Path, ...)
        return False


def _same(a: Any, b: Any) -> bool:
    """Equal, and of the same types all the way down (``1 != 1.0`` here)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b or (a != a and b != b)  # NaN is NaN
