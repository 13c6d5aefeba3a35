"""SSP 1.0 archives read back: an archive (or its extracted folder, or its
``.ssd`` file) into a :class:`~cosim.scenario.definition.Scenario`, and the SSD checked
against the standard's schema; the names both directions share.

An SSP archive (System Structure and Parameterization, Modelica Association,
version 1.0) is a zip file holding ``SystemStructure.ssd`` (the system: its
components, their connectors, the connections, parameter values, the default
experiment) and the FMUs under ``resources/``. Any SSP tool can load it; the
Open Simulation Platform's libcosim runs it (``docs/ssp.md``).
:mod:`cosim.ssp.export` writes them.

* :func:`load_ssp` reads an archive back into a Scenario (FMUs by path),
  checked by :func:`~cosim.scenario.definition.parse_scenario` like any TOML scenario;
  a bad archive is a one-line :class:`~cosim.errors.ScenarioError` naming the
  element by its path in the SSD. Archives from SSP editors too: nested
  systems flattened (:class:`_Flattening`), ``implementation``, parameter
  mappings, prefixes and system bindings, no step (``docs/ssp.md``,
  "Archives from SSP editors"). The reader uses lxml directly, so that every refusal can name the
  element it comes from.
* :func:`ssd_schema_errors` validates an SSD against the SSP 1.0 XML schemas
  shipped with ``pyssp-standard``.
"""
from __future__ import annotations

import math
import posixpath
import shutil
import tempfile
import urllib.parse
import weakref
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from lxml import etree

from ..scenario import registry
from ..fmi import units
from ..errors import CosimError, FmuError, ScenarioError, one_line, show_folder_as
from ..files import (SSD_NAME, extract_zip, given_twice, json_document, put_once, read_entry, regular_file, safe_name,
                    zip_members)
from ..limits import MAX_DOCUMENT_BYTES, MAX_NESTING
from ..names import split_endpoint
from ..notes import note
from ..scenario.definition import Scenario, apply_overrides, parse_scenario
from ..scenario.assembly import fmu_component
from ..scenario.parameter_set import number as _number, parameter_set as _parameter_set

__all__ = ["load_ssp", "ssd_schema_errors", "qualified", "SSD_NAME", "FMU_TYPE", "NS", "OSP_NAMESPACE", "OSP_ANNOTATION",
           "COSIM_NAMESPACE", "COSIM_ANNOTATION"]

FMU_TYPE = "application/x-fmu-sharedlibrary"
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
}
# libcosim (0.11, the one inside libcosimpy 0.0.6) reads the step size from
#   ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation[@type="com.opensimulationplatform"]
#     /osp:Algorithm/osp:FixedStepAlgorithm/@baseStepSize   (seconds)
# with Boost.PropertyTree, which matches the prefixes literally: they must be
# exactly ssd:, ssc: and osp: (the URI is the one OSP's own tools declare).
OSP_NAMESPACE = "http://opensimulationplatform.com/SSP/OSPAnnotations"
OSP_ANNOTATION = "com.opensimulationplatform"
# This engine's own annotation on the ssd:System: what an SSD has no place for
# (the seed, the ordering, the seed parameters, the recorded signals, the
# envelope). Other tools ignore it.
COSIM_NAMESPACE = "urn:fnn-cosim:ssp-scenario:1"
COSIM_ANNOTATION = "fnn-cosim.scenario.definition"
_KNOWN_ANNOTATIONS = (OSP_ANNOTATION, COSIM_ANNOTATION)


_SCHEMA = None


def ssd_schema_errors(ssd: str | Path | bytes) -> list[str]:
    """The SSP 1.0 schema's complaints about an SSD, or a ``.ssv`` or ``.ssm`` file (empty: valid), one line each.

    The XSDs are the normative SSP 1.0 schemas that ``pyssp-standard`` ships
    (``pyssp_standard/resources``); inline ``ssv:ParameterSet`` elements are
    and ``ssm:ParameterMapping`` elements are validated too (the SSD schema
    admits them as lax wildcard content, checked against the SSV and SSM
    schemas it is given here).
    """
    global _SCHEMA
    if _SCHEMA is None:
        from importlib.util import find_spec

        # the package's folder, found without importing it (its import is pint's and xmlschema's, over 1 s of CPU)
        folder = Path(find_spec("pyssp_standard").submodule_search_locations[0]) / "resources"
        imports = "".join(
            f'<xs:import namespace="{NS[p]}" schemaLocation="{(folder / f).as_uri()}"/>'
            for p, f in (("ssd", "SystemStructureDescription.xsd"), ("ssv", "SystemStructureParameterValues.xsd"),
                         ("ssm", "SystemStructureParameterMapping.xsd")))
        driver = f'<xs:schema xmlns:xs="http://www.w3.org/2001/XMLSchema">{imports}</xs:schema>'
        _SCHEMA = etree.XMLSchema(etree.fromstring(driver.encode(), base_url=folder.as_uri() + "/"))
    document = _xml(ssd)
    if _SCHEMA.validate(document):
        return []
    return [f"line {e.line}: {e.message}" for e in _SCHEMA.error_log]


# ---- reading ----------------------------------------------------------------------------------

@dataclass
class _System:
    """What the reader took from an SSD."""

    name: str
    description: str
    start: float | None
    stop: float | None
    step: float | None
    components: dict[str, dict[str, Any]]  # name -> {"path": Path, "parameters": {...}, "connectors": {name: kind}}
    connections: list[str | dict[str, Any]]  # strings, or tables with a conversion or the unchecked marker
    seed: int | None = None
    block_rows: int | None = None
    ordering: str | None = None
    coupling: str | None = None
    seed_parameters: dict[str, str] = field(default_factory=dict)  # component -> parameter
    seed_streams: dict[str, int] = field(default_factory=dict)  # component -> its stream, where not 0
    fmu_settings: dict[str, dict[str, Any]] = field(default_factory=dict)  # component -> interface, solver, start
    record: list[str] = field(default_factory=list)
    envelope: dict[str, list[float]] = field(default_factory=dict)
    sections: dict[str, Any] = field(default_factory=dict)  # an application's own tables, by name
    ssd_units: dict[str, Any] = field(default_factory=dict)  # the SSD's ssd:Units, by name


def qualified(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _integer(where: str, text: str | None, what: str) -> int:
    """A whole number written as one (``1.5`` and ``1e3`` are refused, not truncated)."""
    if text is None or not text.strip().lstrip("+-").isdigit():
        raise ScenarioError(f"{where}: {what} = {text!r} is not an integer")
    return int(text)


def _source_path(where: str, source: str, folder: Path) -> Path:
    """A component's or parameter set's ``source`` URI as a file inside the
    archive: a relative reference, resolved against the SSD's folder, that
    stays inside it (symbolic links followed). An archive is data
    (``docs/security.md``): a ``file:`` URI, an absolute path or a ``..``
    that leaves the folder would load an FMU, that is native code, from
    anywhere, and is refused like any other scheme."""
    parsed = urllib.parse.urlparse(source)
    if parsed.scheme or parsed.netloc or source.startswith(("/", "\\")):
        raise ScenarioError(f"{where}: source {source!r}: only files inside the archive (relative URIs) are "
                            f"supported")
    inside = folder.resolve()
    path = (inside / urllib.parse.unquote(parsed.path)).resolve()
    if not path.is_relative_to(inside):
        raise ScenarioError(f"{where}: source {source!r}: leaves the archive; only files inside it are supported")
    if not path.is_file():
        raise ScenarioError(f"{where}: source {source!r}: no such file in the archive ({path})")
    return path


def _path(parent: str, tag: str, name: str | None = None) -> str:
    """An XPath-like step below ``parent``: ``ssd:System[@name='SuT']``, for the one-line refusals."""
    if name is None:
        return f"{parent}/{tag}"
    return f"{parent}/{tag}[@name={repr(name) if chr(39) not in name else chr(34) + name + chr(34)}]"


def _note_annotations(parent: etree._Element, where: str) -> None:
    """Annotations this reader does not know are ignored, as SSP 1.0 asks of a tool that does not know
    their type (SystemStructureCommon, ``ssc:Annotation``), with a note at info level naming the type."""
    for i, annotation in enumerate(parent.findall("ssd:Annotations/ssc:Annotation", NS), 1):
        if annotation.get("type") not in _KNOWN_ANNOTATIONS:
            note(__name__, "%s/ssd:Annotations/ssc:Annotation[%d]: type %r is an annotation this reader does not know: "
                 "ignored", where, i, annotation.get("type"))


def _document(where: str, source: str, folder: Path, tag: tuple[str, str]) -> etree._Element:
    """The root element of a file the archive references (a ``.ssv`` or ``.ssm``): inside the archive,
    at most :data:`~cosim.limits.MAX_DOCUMENT_BYTES`, read as data, of the element ``tag`` expects."""
    from ..files import read_text

    path = _source_path(where, source, folder)
    try:
        node = _xml(read_text(path, f"{where}: source").encode()).getroot()
    except etree.XMLSyntaxError as exc:
        raise ScenarioError(f"{where}: {source}: not well-formed XML: {one_line(str(exc))}") from None
    if node.tag != qualified(*tag):
        raise ScenarioError(f"{where}: {source}: expected an {tag[0]}:{tag[1]}, found {etree.QName(node).localname}")
    return node


def _transformation(where: str, parent: etree._Element, allowed: tuple[str, ...]) -> tuple[float, float] | None:
    """The ``ssc:LinearTransformation`` among ``parent``'s children (``(factor, offset)``: target = factor *
    source + offset), or None; another transformation (``ssc:BooleanMappingTransformation``, ...) is refused
    by name, the children in ``allowed`` (geometry, annotations) pass."""
    transformation = None
    for child in parent:
        if not isinstance(child.tag, str):
            continue
        if child.tag == qualified("ssc", "LinearTransformation") and transformation is None:
            at = f"{where}/ssc:LinearTransformation"
            transformation = (_number(at, child.get("factor", "1"), "factor"),
                              _number(at, child.get("offset", "0"), "offset"))
        elif child.tag not in allowed:
            raise ScenarioError(f"{where}/{child.prefix or 'ssc'}:{etree.QName(child).localname}: not supported (of "
                                f"the transformations, one ssc:LinearTransformation is)")
    return transformation


def _suppressed(where: str, element: etree._Element) -> bool:
    """An element's ``suppressUnitConversion`` (an ``xs:boolean``, false by default: a connection's or a
    mapping entry's)."""
    suppress = element.get("suppressUnitConversion", "false")
    if suppress not in ("true", "false", "1", "0"):
        raise ScenarioError(f"{where}: suppressUnitConversion = {suppress!r}: expected true or false")
    return suppress in ("true", "1")


@dataclass(frozen=True)
class _Value:
    """A bound value on its way to its FMU: converted from the unit its set states into its variable's
    unit, unless its mapping entry suppresses that, then through the entry's transformation (SSP 1.0
    SystemStructureParameterMapping: "the linear transformation is performed in addition to any unit
    conversions"; :func:`_final_values`)."""

    value: float
    unit: str | None
    transformation: tuple[float, float] | None
    where: str


def _content(where: str, element: etree._Element, folder: Path, mime: str, wrapper: str | None,
             tag: tuple[str, str]) -> tuple[etree._Element, str]:
    """The document an ``ssd:ParameterBinding`` (a parameter set) or an ``ssd:ParameterMapping`` (a
    mapping) holds, and where it is: of the MIME ``type`` SSP 1.0 defines for it, either its ``source``,
    a file in the archive (``sourceBase = "SSD"``), or inline, the first element inside ``wrapper``
    (inside ``element`` itself without one)."""
    if element.get("type", mime) != mime:
        raise ScenarioError(f"{where}: type {element.get('type')!r} is not supported ({mime} only)")
    source = element.get("source")
    if source is not None:
        if element.get("sourceBase", "SSD") != "SSD":
            raise ScenarioError(f"{where}: sourceBase {element.get('sourceBase')!r} is not supported (SSD only)")
        return _document(where, source, folder, tag), f"{where} ({source})"
    inline = element.find(wrapper, NS) if wrapper else element
    node = next((n for n in inline if isinstance(n.tag, str)), None) if inline is not None else None
    if node is None or (wrapper is None and node.tag != qualified(*tag)):
        raise ScenarioError(f"{where}: neither a source nor an inline {wrapper or ':'.join(tag)}")
    return node, f"{where}/{wrapper or ':'.join(tag)}"


def _mapped(where: str, element: etree._Element, values: Mapping[str, _Value], folder: Path) -> dict[str, _Value]:
    """A parameter set's values renamed by an ``ssd:ParameterMapping`` (SSP 1.0
    SystemStructureParameterMapping: inline ``ssm:ParameterMapping``, or a ``.ssm`` source): each
    ``ssm:MappingEntry source target`` gives the set's ``source`` to the variable ``target``, through its
    ``ssc:LinearTransformation`` if it has one; names no entry maps keep their own (the standard's name
    resolution). An entry whose source the set does not hold maps nothing (a note at info level);
    ``suppressUnitConversion = "true"`` takes the value as it is, in the variable's unit."""
    mapping, at = _content(where, element, folder, "application/x-ssp-parameter-mapping", None,
                           ("ssm", "ParameterMapping"))
    out, renamed = dict(values), {}
    for k, entry in enumerate(mapping.findall("ssm:MappingEntry", NS), 1):
        entry_at = f"{at}/ssm:MappingEntry[{k}]"
        name, target = entry.get("source"), entry.get("target")
        if not name or not target:
            raise ScenarioError(f"{entry_at}: a source and a target are required")
        transformation = _transformation(entry_at, entry, (qualified("ssc", "Annotations"),
                                                           qualified("ssm", "Annotations")))
        if name not in values:
            note(__name__, "%s: source %r is no parameter of the set: maps nothing", entry_at, name)
            continue
        suppress = _suppressed(entry_at, entry)
        out.pop(name, None)
        value = values[name]
        put_once(renamed, target, _Value(value.value, None if suppress else value.unit,
                                         transformation, entry_at), f"{entry_at}: target")
    for target, value in renamed.items():
        put_once(out, target, value, f"{at}: parameter")
    return out


def _bindings(where: str, element: etree._Element, folder: Path) -> dict[str, _Value]:
    """The values an element's ``ssd:ParameterBindings`` give, by the names they bind (a component's
    variables; a system's hierarchical names, ``Element.variable``): each binding's parameter set
    (inline ``ssd:ParameterValues`` or a ``.ssv`` source), its ``prefix`` prepended to every name
    (SSP 1.0: "prior to processing the normal name resolution or name mapping rules"), then its
    ``ssd:ParameterMapping``. A name two bindings of one element give is refused (the standard lets
    the later one win; here that is a value lost without a word)."""
    values: dict[str, _Value] = {}
    bindings = element.find("ssd:ParameterBindings", NS)
    for j, binding in enumerate(bindings if bindings is not None else [], 1):
        if not isinstance(binding.tag, str):
            continue
        at = f"{where}/ssd:ParameterBindings/ssd:ParameterBinding[{j}]"
        node, node_at = _content(at, binding, folder, "application/x-ssp-parameter-set", "ssd:ParameterValues",
                                 ("ssv", "ParameterSet"))
        stated: dict[str, str] = {}
        prefix = binding.get("prefix", "")
        more = {prefix + name: _Value(value, stated.get(name), None, node_at)
                for name, value in _parameter_set(node_at, node, stated).items()}
        mapping = binding.find("ssd:ParameterMapping", NS)
        if mapping is not None:
            more = _mapped(f"{at}/ssd:ParameterMapping", mapping, more, folder)
        _note_annotations(binding, at)
        for name, value in more.items():
            put_once(values, name, value, f"{where}: parameter")
    return values


def _component(at: str, element: etree._Element, folder: Path) -> dict[str, Any]:
    """One ``ssd:Component`` (an FMU): its file, connectors and their units, the values its bindings
    give, and the interface its ``implementation`` asks for (SSP 1.0: ``ModelExchange``,
    ``CoSimulation``, or ``any``, the importer's choice: the master's default, None here)."""
    type_ = element.get("type", FMU_TYPE)
    if type_ != FMU_TYPE:
        raise ScenarioError(f"{at}: type {type_!r} is not supported ({FMU_TYPE} only)")
    implementation = element.get("implementation", "any")
    if implementation not in ("any", "CoSimulation", "ModelExchange"):
        raise ScenarioError(f"{at}: implementation {implementation!r}: expected any, CoSimulation or ModelExchange")
    source = element.get("source")
    if not source:
        raise ScenarioError(f"{at}: no source attribute")
    connectors, connector_units = _connectors(at, element)
    _note_annotations(element, at)
    return {"path": _source_path(at, source, folder), "parameters": _bindings(at, element, folder),
            "connectors": connectors, "units": connector_units, "where": at,
            "interface": None if implementation == "any" else implementation}


def _connectors(at: str, element: etree._Element) -> tuple[dict[str, str], dict[str, str]]:
    """An element's ``ssd:Connectors``: kind by name, and the unit of those that state one."""
    connectors: dict[str, str] = {}
    connector_units: dict[str, str] = {}
    for i, connector in enumerate(element.findall("ssd:Connectors/ssd:Connector", NS), 1):
        name = connector.get("name")
        if not name:
            raise ScenarioError(f"{at}/ssd:Connectors/ssd:Connector[{i}]: no name attribute")
        put_once(connectors, name, connector.get("kind", ""), f"{at}: ssd:Connector")
        real = connector.find("ssc:Real", NS)
        if real is not None and real.get("unit"):
            connector_units[name] = real.get("unit")
    return connectors, connector_units


def _ssd_units(root: etree._Element) -> dict[str, Any]:
    """The SSD's ``ssd:Units`` (SystemStructureCommon ``ssc:Unit``/``ssc:BaseUnit``,
    the FMI form) as :class:`cosim.fmi.units.Unit`, by name."""
    out = {}
    for unit in root.iterfind("ssd:Units/ssc:Unit", NS):
        base = unit.find("ssc:BaseUnit", NS)
        if unit.get("name") and base is not None:
            where = _path("/ssd:SystemStructureDescription/ssd:Units", "ssc:Unit", unit.get("name"))
            exponents = tuple(_integer(where, base.get(b, "0"), b) for b in units.BASE_UNITS)
            out[unit.get("name")] = units.Unit(unit.get("name"), exponents,
                                               _number(where, base.get("factor", "1"), "factor"),
                                               _number(where, base.get("offset", "0"), "offset"))
    return out


_DICTIONARY = object()  # marks a signal dictionary's entries among the systems' connectors (_Flattening.reference)
# A connection's end: (False, instance, connector) for a component's connector, (True, system path below
# the root, connector) for a system's own.
_End = tuple[bool, Any, str]


@dataclass(frozen=True)
class _Hop:
    """One ``ssd:Connection`` of a chain: where it is, the units of its two ends (as the SSD states
    them), its ``ssc:LinearTransformation`` and ``suppressUnitConversion``."""

    where: str
    units: tuple[str | None, str | None]
    transformation: tuple[float, float] | None
    suppress: bool


class _Flattening:
    """An ``ssd:System`` and the systems inside it, flattened: every component under its dotted path
    below the root system (``SuT.edrive_mass``), every chain of connections through systems'
    connectors one direct connection (``docs/ssp.md``, "Nested systems")."""

    def __init__(self, folder: Path, ssd_units: Mapping[str, Any]):
        self.folder, self.ssd_units = folder, ssd_units
        self.components: dict[str, dict[str, Any]] = {}
        self.systems: dict[tuple[str, ...], dict[str, str | None]] = {}  # path -> connector -> unit
        self.edges: dict[_End, list[tuple[_End, _Hop]]] = {}
        self.dictionaries: dict[tuple[str, ...], set[str]] = {}  # system path -> its signal dictionaries
        self.references: dict[tuple[str, ...], tuple[tuple, dict[str, str | None]]] = {}  # -> hub, connectors

    def system(self, element: etree._Element, at: str, path: tuple[str, ...]) -> None:
        if len(path) >= MAX_NESTING:
            raise ScenarioError(f"{at}: systems nested {len(path)} deep; at most {MAX_NESTING}")
        _note_annotations(element, at)
        self.dictionaries[path] = set()
        for k, dictionary in enumerate(element.findall("ssd:SignalDictionaries/ssd:SignalDictionary", NS), 1):
            if not dictionary.get("name"):
                raise ScenarioError(f"{at}/ssd:SignalDictionaries/ssd:SignalDictionary[{k}]: no name attribute")
            if dictionary.get("name") in self.dictionaries[path]:
                raise given_twice(f"{at}/ssd:SignalDictionaries: ssd:SignalDictionary", dictionary.get("name"))
            self.dictionaries[path].add(dictionary.get("name"))
        kinds, connector_units = _connectors(at, element)
        self.systems[path] = {name: connector_units.get(name) for name in kinds}
        children: dict[str, str] = {}
        elements = element.find("ssd:Elements", NS)
        for child in elements if elements is not None else []:
            if not isinstance(child.tag, str):
                continue  # comments, processing instructions
            name = child.get("name")
            child_at = _path(f"{at}/ssd:Elements", f"{child.prefix or 'ssd'}:{etree.QName(child).localname}", name)
            if not name:
                raise ScenarioError(f"{child_at}: no name attribute")
            instance = ".".join((*path, name))
            if name in children or instance in self.components:
                raise ScenarioError(f"{child_at}: an element of that name is already given")
            if child.tag == qualified("ssd", "Component"):
                children[name] = "component"
                self.components[instance] = _component(child_at, child, self.folder)
            elif child.tag == qualified("ssd", "System"):
                children[name] = "system"
                self.system(child, child_at, (*path, name))
            elif child.tag == qualified("ssd", "SignalDictionaryReference"):
                children[name] = "dictionary"
                self.reference(child, child_at, (*path, name))
            else:
                raise ScenarioError(f"{child_at}: not supported (ssd:Component and ssd:System are)")
        for i, connection in enumerate(element.findall("ssd:Connections/ssd:Connection", NS), 1):
            self.connection(f"{at}/ssd:Connections/ssd:Connection[{i}]", connection, path, children)
        self.bind(at, element, path)

    def connection(self, where: str, element: etree._Element, path: tuple[str, ...],
                   children: Mapping[str, str]) -> None:
        ends: list[_End] = []
        end_units: list[str | None] = []
        for side in ("start", "end"):
            name, connector = element.get(f"{side}Element"), element.get(f"{side}Connector")
            if connector is None:
                raise ScenarioError(f"{where}: no {side}Connector")
            if name is None:  # the system's own connector
                end, known, unit = (True, path, connector), self.systems[path], self.systems[path].get(connector)
            elif children.get(name) == "component":
                instance = ".".join((*path, name))
                entry = self.components[instance]
                end, known, unit = (False, instance, connector), entry["connectors"], entry["units"].get(connector)
            elif children.get(name) == "system":
                inner = self.systems[(*path, name)]
                end, known, unit = (True, (*path, name), connector), inner, inner.get(connector)
            elif children.get(name) == "dictionary":  # the entry of that name, shared by every reference
                hub, inner = self.references[(*path, name)]
                end, known, unit = (True, hub, connector), inner, inner.get(connector)
            else:
                raise ScenarioError(f"{where}: {side}Element {name!r} is no element of its system; its elements "
                                    f"are: {', '.join(children) or '(none)'}")
            if connector not in known:
                raise ScenarioError(f"{where}: {side}Connector {connector!r} is no connector of "
                                    f"{repr(name) if name is not None else 'the system'}")
            ends.append(end)
            end_units.append(unit)
        suppress = _suppressed(where, element)
        transformation = _transformation(where, element, (qualified("ssd", "ConnectionGeometry"),
                                                          qualified("ssd", "Annotations")))
        _note_annotations(element, where)
        hop = _Hop(where, (end_units[0], end_units[1]), transformation, suppress)
        self.edges.setdefault(ends[0], []).append((ends[1], hop))

    def reference(self, element: etree._Element, at: str, path: tuple[str, ...]) -> None:
        """An ``ssd:SignalDictionaryReference``: its connectors are entries of the signal dictionary it
        names, looked up in its system, then in each enclosing one (SSP 1.0, ``ssd:SignalDictionary``
        ``name``). Every reference to one dictionary shares its entries: what is connected into an
        entry reaches whatever is connected out of it, anywhere (the entries' types and units in the
        dictionary itself are not read: the references' connectors state theirs)."""
        dictionary = element.get("dictionary")
        owner = next((path[:i] for i in range(len(path) - 1, -1, -1)
                      if dictionary in self.dictionaries.get(path[:i], ())), None)
        if owner is None:
            raise ScenarioError(f"{at}: dictionary {dictionary!r}: no ssd:SignalDictionary of that name in its system "
                                f"or an enclosing one")
        kinds, connector_units = _connectors(at, element)
        _note_annotations(element, at)
        self.references[path] = ((_DICTIONARY, *owner, dictionary), {c: connector_units.get(c) for c in kinds})

    def bind(self, at: str, element: etree._Element, path: tuple[str, ...]) -> None:
        """A system's bindings, applied to the components below it: a name is ``Element.variable``
        (``Sub.Element.variable`` further down; SSP 1.0 ParameterBinding), resolved against the
        instance names below the system, longest first. A system's binding wins over those below it
        (the standard's precedence: the higher level)."""
        values = _bindings(at, element, self.folder)
        if not values:
            return
        below = {name[len(".".join(path)) + 1 if path else 0:]: name for name in self.components
                 if not path or name.startswith(".".join(path) + ".")}
        for name, value in values.items():
            relative, variable = split_endpoint(name, below) or (None, None)
            if relative not in below:
                raise ScenarioError(f"{at}: parameter {name!r}: names no element of the system (expected "
                                    f"Element.variable; elements below it: {', '.join(below)})")
            self.components[below[relative]]["parameters"][variable] = value

    def connections(self) -> list[str | dict[str, Any]]:
        """Every chain from a component's connector to a component's connector, one connection each."""
        memo: dict[_End, list[tuple[_End, tuple[_Hop, ...]]]] = {}
        out = []
        for start in self.edges:
            if not start[0]:
                out.extend(self._connection(start, end, hops) for end, hops in self._ends(start, memo, ()))
        for start in self.edges:
            if start[0] and start not in memo:
                note(__name__, "%s: starts at %s, which nothing connected drives: ignored",
                     self.edges[start][0][1].where, _shown(start))
        return out

    def _ends(self, node: _End, memo: dict, busy: tuple[_End, ...]) -> list[tuple[_End, tuple[_Hop, ...]]]:
        """The component connectors a connector reaches, each with its chain of connections."""
        ends: list[tuple[_End, tuple[_Hop, ...]]] = []
        for nxt, hop in self.edges.get(node, []):
            if not nxt[0]:
                ends.append((nxt, (hop,)))
                continue
            if nxt in busy:
                raise ScenarioError(f"{hop.where}: a loop of connections through the systems' connectors")
            if nxt not in memo:
                if nxt not in self.edges:
                    note(__name__, "%s: ends at %s, connected to nothing further: ignored", hop.where, _shown(nxt))
                memo[nxt] = self._ends(nxt, memo, (*busy, node))
            ends.extend((end, (hop, *hops)) for end, hops in memo[nxt])
        if len(ends) > len(self.components) * max(1, max((len(c["connectors"]) for c in self.components.values()),
                                                         default=1)):
            raise ScenarioError(f"{self.edges[node][0][1].where}: fans out to more connections than the components "
                                f"have connectors (an input fed twice)")
        return ends

    def _connection(self, start: _End, end: _End, hops: tuple[_Hop, ...]) -> str | dict[str, Any]:
        """A chain as one connection: a string when no connection of it transforms (the master converts by
        the FMUs' units), ``units = "unchecked"`` when each suppresses the conversion without a
        transformation, else the composed conversion. Each connection applies the conversion its
        ends' units give, then its transformation (SSP 1.0 SystemStructureCommon,
        ``LinearTransformation``; none with ``suppressUnitConversion``): target = f (u_f source + u_o) + o."""
        text = f"{start[1]}.{start[2]} -> {end[1]}.{end[2]}"
        if all(h.transformation is None and not h.suppress for h in hops):
            return text
        if all(h.transformation is None and h.suppress for h in hops):
            return {"connect": text, "units": "unchecked"}
        factor, offset = 1.0, 0.0
        for hop in hops:
            unit_factor, unit_offset = 1.0, 0.0
            source_unit, target_unit = hop.units
            if not hop.suppress and source_unit and target_unit and source_unit != target_unit:
                try:
                    unit_factor, unit_offset = units.conversion(
                        units.unit_of(source_unit, self.ssd_units) or source_unit,
                        units.unit_of(target_unit, self.ssd_units) or target_unit)
                except CosimError as exc:
                    raise ScenarioError(f"{hop.where}: {exc}") from None
            f, o = hop.transformation or (1.0, 0.0)
            f, o = f * unit_factor, f * unit_offset + o
            factor, offset = f * factor, f * offset + o
        return {"connect": text, "factor": factor, "offset": offset}


def _shown(end: _End) -> str:
    if not end[0]:
        return f"{end[1]}.{end[2]}"
    if end[1] and end[1][0] is _DICTIONARY:
        return f"entry {end[2]!r} of the signal dictionary {end[1][-1]!r}"
    return f"connector {end[2]!r} of the {'system ' + repr('.'.join(end[1])) if end[1] else 'root system'}"


def _annotations(parent: etree._Element, type_: str) -> list[etree._Element]:
    """The single child of each ``ssc:Annotation`` of ``type_`` under ``parent/ssd:Annotations``."""
    return [a[0] for a in parent.findall("ssd:Annotations/ssc:Annotation", NS) if a.get("type") == type_ and len(a)]


def _read_ssd(ssd_path: Path) -> _System:
    """Parse and check an SSD; every refusal names its element by its path in the document."""
    try:
        root = _xml(ssd_path).getroot()
    except etree.XMLSyntaxError as exc:
        raise ScenarioError(f"not well-formed XML: {exc}") from None
    if root.tag != qualified("ssd", "SystemStructureDescription"):
        raise ScenarioError(f"the root element is {root.tag}, not ssd:SystemStructureDescription")
    system = root.find("ssd:System", NS)
    if system is None:
        raise ScenarioError("no ssd:System")
    top = "/ssd:SystemStructureDescription"
    at = _path(top, "ssd:System", system.get("name", ""))
    _note_annotations(root, top)
    flat = _Flattening(ssd_path.parent, _ssd_units(root))
    flat.system(system, at, ())
    if not flat.components:
        raise ScenarioError(f"{at}: no ssd:Component (an FMU) in its ssd:Elements or below")
    connections = flat.connections()
    components = flat.components

    start = stop = step = None
    experiment = root.find("ssd:DefaultExperiment", NS)
    if experiment is not None:
        where = f"{top}/ssd:DefaultExperiment"
        if experiment.get("startTime") is not None:
            start = _number(where, experiment.get("startTime"), "startTime")
        if experiment.get("stopTime") is not None:
            stop = _number(where, experiment.get("stopTime"), "stopTime")
        _note_annotations(experiment, where)
        for algorithm in _annotations(experiment, OSP_ANNOTATION):
            for fixed in algorithm:
                if isinstance(fixed.tag, str) and etree.QName(fixed).localname == "FixedStepAlgorithm":
                    at_fixed = f"{where}: osp:FixedStepAlgorithm"
                    step = _number(at_fixed, fixed.get("baseStepSize"), "baseStepSize")
                    if step <= 0:
                        raise ScenarioError(f"{at_fixed}: baseStepSize = {fixed.get('baseStepSize')!r} is not "
                                            f"positive")
    out = _System(root.get("name") or system.get("name") or ssd_path.parent.name, root.get("description", ""),
                  start, stop, step, components, connections, ssd_units=flat.ssd_units)
    recorded: set[str] = set()
    for scenario in _annotations(system, COSIM_ANNOTATION):
        where = f"ssd:System: ssc:Annotation {COSIM_ANNOTATION}"
        if scenario.get("seed") is not None:
            out.seed = _integer(where, scenario.get("seed"), "seed")
        if scenario.get("blockRows") is not None:
            out.block_rows = _integer(where, scenario.get("blockRows"), "blockRows")
        out.ordering = scenario.get("ordering")
        out.coupling = scenario.get("coupling")
        for item in scenario:
            tag = etree.QName(item).localname if isinstance(item.tag, str) else None
            if tag == "Record":
                if item.get("signal", "") in recorded:
                    raise given_twice(f"{where}: Record", item.get("signal", ""))
                recorded.add(item.get("signal", ""))
                out.record.append(item.get("signal", ""))
            elif tag == "SeedParameter":
                component, name = item.get("component"), item.get("parameter")
                if component not in components or not name:
                    raise ScenarioError(f"{where}: SeedParameter: component {component!r} is no component, or "
                                        f"no parameter is named")
                put_once(out.seed_parameters, component, name, f"{where}: SeedParameter of component")
                if item.get("stream") is not None:
                    out.seed_streams[component] = _integer(f"{where}: SeedParameter {component!r}", item.get("stream"),
                                                           "stream")
            elif tag == "Fmu":  # validated with the rest of the scenario ([fmus.X] keys)
                component = item.get("component")
                if component not in components:
                    raise ScenarioError(f"{where}: Fmu: component {component!r} is no component")
                put_once(out.fmu_settings, component, {}, f"{where}: Fmu of component")
                settings = out.fmu_settings[component]
                if item.get("interface") is not None:
                    settings["interface"] = item.get("interface")
                for key in ("start", "solver"):
                    if item.get(key) is not None:
                        settings[key] = json_document(item.get(key), f"{where}: Fmu {component!r}: {key}", 3)
            elif tag == "Envelope":
                signal = item.get("signal", "")
                if signal in out.envelope:
                    raise given_twice(f"{where}: Envelope", signal)
                out.envelope[signal] = [_number(f"{where}: Envelope {signal!r}", item.get(k), k)
                                        for k in ("low", "high")]
            elif tag == "Section":
                # An archive is data: only an application's registered sections (tables of values
                # its own code checks), never a component table, a short component section or a
                # generic key, which could name Python code to run (a factory).
                name = item.get("name", "")
                if name not in registry.sections():
                    raise ScenarioError(f"{where}: Section {name!r}: not a section an archive may carry; known: "
                                        f"{', '.join(sorted(registry.sections())) or '(none registered)'}")
                if name in out.sections:  # two [wind] sections: the last one won
                    raise given_twice(f"{where}: Section", name)
                out.sections[name] = json_document(item.text or "", f"{where}: Section {name!r}", 1)
    return out


def _xml(source: str | Path | bytes) -> etree._ElementTree:
    """An XML document read as data: no entity expansion, no DTD, no network
    (an archive is data from anyone: ``docs/security.md``)."""
    parser = etree.XMLParser(resolve_entities=False, load_dtd=False, no_network=True, huge_tree=False)
    if isinstance(source, bytes):
        return etree.ElementTree(etree.fromstring(source, parser))
    return etree.parse(str(source), parser)


def _referenced(ssd: bytes) -> set[str]:
    """The archive entries an SSD names (its components' and parameter
    bindings' sources, resolved from the archive's root): all an archive
    has extracted (the rest of it may be anything)."""
    try:
        root = _xml(ssd).getroot()
    except etree.XMLSyntaxError:
        return set()  # the reader says why, naming the line
    names = set()
    for element in root.iter(qualified("ssd", "Component"), qualified("ssd", "ParameterBinding"),
                             qualified("ssd", "ParameterMapping")):
        source = element.get("source")
        if source and not urllib.parse.urlparse(source).scheme:
            name = posixpath.normpath(urllib.parse.unquote(source))
            if not name.startswith(("/", "../")) and name != "..":
                names.add(name)
    return names


def _open(path: Path, extract_to: str | Path | None) -> tuple[Path, Path | None]:
    """The SSD of an archive, folder or ``.ssd`` file, and the folder made
    for a temporary extraction (None when nothing was extracted, or when
    extracted to ``extract_to``). Of an archive only the SSD and the entries
    it references are extracted, within the limits of :mod:`cosim.files`;
    a broken archive is one line, and leaves no folder behind."""
    if path.is_dir():
        ssd = path / SSD_NAME
        if not ssd.is_file():
            raise ScenarioError(f"{path}: not an extracted SSP archive: the folder holds no {SSD_NAME}")
        return ssd, None
    if not path.exists():
        raise ScenarioError(f"{path}: no such file")
    regular_file(path, "SSP archive")
    if path.suffix.lower() == ".ssd":
        return path, None
    label = f"{path}: not an SSP archive"
    try:
        with zipfile.ZipFile(path) as archive:
            members = zip_members(archive, str(path))
            if SSD_NAME not in members:
                raise ScenarioError(f"{label}: it holds no {SSD_NAME}")
            if members[SSD_NAME].file_size > MAX_DOCUMENT_BYTES:
                raise ScenarioError(f"{path}: {SSD_NAME} is {members[SSD_NAME].file_size} bytes; at most "
                                    f"{MAX_DOCUMENT_BYTES} are read")
            referenced = {n for n in _referenced(read_entry(archive, members[SSD_NAME], str(path))) if n in members}
    except (zipfile.BadZipFile, OSError, NotImplementedError, RuntimeError, EOFError, ValueError) as exc:
        raise ScenarioError(f"{label}: not a zip archive ({one_line(str(exc))})") from None
    temporary = None
    if extract_to is None:
        folder = temporary = Path(tempfile.mkdtemp(prefix=f"ssp-{safe_name(path.stem)}-"))
    else:
        folder = Path(extract_to)
    try:
        extract_zip(path, folder, str(path), only={SSD_NAME} | referenced)
    except BaseException:
        if temporary is not None:
            shutil.rmtree(temporary, ignore_errors=True)
        raise
    return folder / SSD_NAME, temporary


def load_ssp(path: str | Path, *, step: float | None = None, duration: float | None = None,
             overrides: Mapping[str, Any] | None = None, extract_to: str | Path | None = None) -> Scenario:
    """Read an SSP archive (``.ssp``), its extracted folder, or its ``.ssd``
    file into a :class:`~cosim.scenario.definition.Scenario` of FMUs (by path).

    The communication step comes from the user's ``overrides``
    (``simulation.step``), else from the OSP annotation
    (``osp:FixedStepAlgorithm baseStepSize``), else from ``step``, else from
    the FMUs' ``DefaultExperiment stepSize`` (the smallest), else the span /
    1000 (:func:`_step`; a note at info level says which); the duration from
    the default experiment (stop - start), else from ``duration``, else from
    the overrides; the seed, ordering, seed parameters, recorded signals and
    envelope from this engine's annotation if the archive has it (else seed
    0, the default ordering, every output connector of every component
    recorded, no envelope). A seed parameter's bound value is dropped: the
    master sets it to the run's seed. ``overrides`` sets dotted keys
    (``{"simulation.duration": 5.0}``) as for a TOML scenario; the result is
    checked by :func:`~cosim.scenario.definition.parse_scenario`.

    An archive is extracted to ``extract_to``, else to a temporary folder that
    lives as long as the returned scenario (``scenario.source`` is the
    extracted ``SystemStructure.ssd``; libcosim takes its folder).

    Refusals are :class:`~cosim.errors.ScenarioError` in one line that names
    the file and the element by its path in the SSD, e.g. ``x.ssp:
    SystemStructure.ssd: /ssd:SystemStructureDescription/ssd:System[@name='Root']/ssd:Connections/ssd:Connection[3]:
    startElement 'Plant' is no element of its system; ...``. Nested systems
    are flattened (:class:`_Flattening`).
    """
    path = Path(path)
    ssd_path, temporary = _open(path, extract_to)
    label = f"{path}: {SSD_NAME}" if path.suffix.lower() != ".ssd" else str(path)
    # messages name the archive, not the folder it was extracted to
    forget = show_folder_as(temporary, str(path)) if temporary is not None else (lambda: None)
    try:
        try:
            system = _read_ssd(ssd_path)
        except ScenarioError as exc:
            raise ScenarioError(f"{label}: {exc}") from None
        try:
            _final_values(system)
        except ScenarioError as exc:
            raise ScenarioError(f"{label}: {exc}") from None
        start = system.start if system.start is not None else 0.0
        given = apply_overrides({}, overrides or {}).get("simulation", {})
        given = given if isinstance(given, Mapping) else {}
        if system.stop is None and duration is None and "duration" not in given:
            raise ScenarioError(f"{label}: no duration: the ssd:DefaultExperiment has no stopTime; give one "
                                f"(duration=... or --set simulation.duration=...)")
        length = system.stop - start if system.stop is not None else duration
        span = length if length is not None else given.get("duration")
        chosen, origin = _step(system, step, given, span if isinstance(span, (int, float)) else None)
        if chosen is not None and given.get("step") is None and system.step is None and step is None:
            note(__name__, "%s: communication step %s s, from %s", label, chosen, origin)  # a default: said
        record = system.record or [f"{c}.{n}" for c, entry in system.components.items()
                                   for n, kind in entry["connectors"].items() if kind == "output"]
        raw: dict[str, Any] = {
            "name": system.name,
            "description": system.description,
            "connections": system.connections,
            "simulation": {"duration": length, "step": chosen,
                           "seed": system.seed if system.seed is not None else 0, "start_time": start,
                           **({"ordering": system.ordering} if system.ordering else {}),
                           **({"coupling": system.coupling} if system.coupling else {})},
            "fmus": {c: {"path": str(entry["path"]),
                         **({"interface": entry["interface"]} if entry.get("interface") else {}),
                         # a seed parameter is set by the master to the run's seed: not a fixed value
                         "parameters": {k: v for k, v in entry["parameters"].items()
                                        if k != system.seed_parameters.get(c)},
                         **({"seed_parameter": system.seed_parameters[c]} if c in system.seed_parameters else {}),
                         **({"seed_stream": system.seed_streams[c]} if c in system.seed_streams else {}),
                         **system.fmu_settings.get(c, {})}
                     for c, entry in system.components.items()},
            "record": {"signals": record, **({"block_rows": system.block_rows} if system.block_rows is not None else {})},
            "envelope": dict(system.envelope),
            **system.sections,
        }
        try:
            scenario = parse_scenario(apply_overrides(raw, overrides or {}), source=ssd_path)
        except ScenarioError as exc:
            raise ScenarioError(f"{label}: {exc}") from None
        if scenario.components:  # an archive holds FMUs only: it never names Python code to run
            raise ScenarioError(f"{label}: Python component(s) {', '.join(sorted(scenario.components))}: an "
                                f"SSP archive holds FMUs only")
        try:
            _check_kinds(system)
        except ScenarioError as exc:
            raise ScenarioError(f"{label}: {exc}") from None
    except BaseException:
        if temporary is not None:
            _remove_extraction(str(temporary), forget)
        raise
    if temporary is not None:
        weakref.finalize(scenario, _remove_extraction, str(temporary), forget)
    return scenario


def _final_values(system: _System) -> None:
    """Every bound value as the number its FMU gets (:class:`_Value`): a unit the parameter set states
    converted into the unit the FMU's variable declares (by ``ssd:Units``, the FMU's
    ``UnitDefinitions``, else by name: :mod:`cosim.fmi.units`), then the mapping's transformation. A value
    without a unit, or for a variable without one, is taken as it is."""
    from ..fmi.description import fmu_ports
    from ..fmi.fmu import read_description

    for name, entry in system.components.items():
        ports = None
        final = {}
        for key, bound in entry["parameters"].items():
            value = bound.value
            if bound.unit is not None:
                if ports is None:
                    try:
                        groups = fmu_ports(read_description(name, entry["path"])[0])
                    except FmuError:
                        groups = {}  # a broken FMU is told where it is built, naming its [fmus] entry
                    ports = {p.name: p for kind in ("parameter", "input") for p in groups.get(kind, ())}
                port = ports.get(key)
                if port is not None and port.unit and port.unit != bound.unit:
                    try:
                        factor, offset = units.conversion(units.unit_of(bound.unit, system.ssd_units) or bound.unit,
                                                          port.unit_definition or port.unit)
                    except CosimError as exc:
                        raise ScenarioError(f"{bound.where}: parameter {key!r}: {exc}") from None
                    value = factor * value + offset
            if bound.transformation is not None:
                value = bound.transformation[0] * value + bound.transformation[1]
            final[key] = value
        entry["parameters"] = final


def _step(system: _System, step: float | None, given: Mapping[str, Any],
          length: float | None) -> tuple[float | None, str]:
    """The communication step and where it comes from (``docs/ssp.md``, "The step"): the user's
    (``--set simulation.step``, an override; set by :func:`~cosim.scenario.definition.apply_overrides`), the
    archive's OSP annotation, the ``step`` argument, the smallest ``DefaultExperiment stepSize`` among
    the FMUs (made smaller to divide the span into whole steps), the span / 1000. An archive of
    Model Exchange FMUs states no step: it is then only the grid the master exchanges values and
    records on (its solver takes its own steps between)."""
    from ..fmi.fmu import read_description

    if "step" in given:
        return given["step"], "the user's setting (simulation.step)"
    if system.step is not None:
        return system.step, "the archive's OSP annotation (osp:FixedStepAlgorithm baseStepSize)"
    if step is not None:
        return step, "the step argument"
    sizes = {}
    for name, entry in system.components.items():
        try:
            md, _ = read_description(name, entry["path"])
        except FmuError:
            continue  # a broken FMU is told where it is built, naming its [fmus] entry
        experiment = md.defaultExperiment
        if experiment is not None and experiment.stepSize is not None:
            try:
                size = float(experiment.stepSize)
            except ValueError:
                continue
            if size > 0 and size == size and size != float("inf"):
                sizes[name] = size
    if length is None or length <= 0:
        return None, "nowhere (no span to divide)"  # parse_scenario refuses the missing step, naming it
    if sizes:
        name = min(sizes, key=sizes.get)
        steps = max(1, math.ceil(length / sizes[name] - 1e-9))
        return length / steps, (f"the smallest FMU DefaultExperiment stepSize ({name}: {sizes[name]:.6g} s), "
                                f"{steps} steps over the span of {length:.6g} s")
    return length / 1000, f"the span / 1000 (no step in the archive nor in its FMUs; span {length:.6g} s)"


# An FMU's variable's causality -> the kind an SSD's connector to it states (SSP 1.0 ssd:Connector
# kind; an FMI 3.0 structural parameter is a parameter to an SSP tool).
_KIND_OF = {"input": "input", "output": "output", "parameter": "parameter", "structuralParameter": "parameter",
            "calculatedParameter": "calculatedParameter"}


def _check_kinds(system: _System) -> None:
    """Refuse a connector whose kind contradicts its FMU (an "input" that is
    the FMU's output, a connector to no variable of it): an SSP tool that
    trusts the SSD would connect or record the wrong thing, ours trusted the
    FMU and said nothing."""
    from ..fmi.fmu import read_description

    for name, entry in system.components.items():
        if not entry["connectors"]:
            continue
        try:
            md, _ = read_description(name, entry["path"])
        except FmuError:
            continue  # a broken FMU is told where it is built, naming its [fmus] entry
        variables = {v.name: v for v in md.modelVariables}
        for connector, kind in entry["connectors"].items():
            variable = variables.get(connector)
            if variable is None:
                raise ScenarioError(f"{entry['where']}: ssd:Connector {connector!r}: no variable of its FMU")
            expected = _KIND_OF.get(variable.causality)
            if kind != expected:
                raise ScenarioError(f"{entry['where']}: ssd:Connector {connector!r}: kind = {kind!r}, but its "
                                    f"FMU's variable is {'an' if variable.causality[0] in 'aeiou' else 'a'} "
                                    f"{variable.causality}" + (f" (kind {expected!r})" if expected else ""))


def _remove_extraction(folder: str, forget) -> None:
    shutil.rmtree(folder, ignore_errors=True)
    forget()
