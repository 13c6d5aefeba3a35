"""SSP 1.0 archives read back: an archive (or its extracted folder, or its
``.ssd`` file) into a :class:`~cosim.scenario.Scenario`, and the SSD checked
against the standard's schema; the names both directions share.

An SSP archive (System Structure and Parameterization, Modelica Association,
version 1.0) is a zip file holding ``SystemStructure.ssd`` (the system: its
components, their connectors, the connections, parameter values, the default
experiment) and the FMUs under ``resources/``. Any SSP tool can load it; the
Open Simulation Platform's libcosim runs it (``docs/ssp.md``).
:mod:`cosim.ssp_export` writes them.

* :func:`load_ssp` reads an archive back into a Scenario (FMUs by path),
  checked by :func:`~cosim.scenario.parse_scenario` like any TOML scenario;
  a bad archive is a one-line :class:`~cosim.errors.ScenarioError` naming the
  element. The reader uses lxml directly, so that every refusal can name the
  element it comes from.
* :func:`ssd_schema_errors` validates an SSD against the SSP 1.0 XML schemas
  shipped with ``pyssp-standard``.
"""
from __future__ import annotations

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

from . import registry, units
from .errors import CosimError, FmuError, ScenarioError, one_line, show_folder_as
from .files import (SSD_NAME, extract_zip, given_twice, json_document, put_once, read_entry, regular_file, safe_name,
                    zip_members)
from .limits import MAX_DOCUMENT_BYTES
from .scenario import Scenario, apply_overrides, parse_scenario
from .assembly import fmu_component
from .ssv import number as _number, parameter_set as _parameter_set

__all__ = ["load_ssp", "ssd_schema_errors", "qualified", "SSD_NAME", "FMU_TYPE", "NS", "OSP_NAMESPACE", "OSP_ANNOTATION",
           "COSIM_NAMESPACE", "COSIM_ANNOTATION"]

FMU_TYPE = "application/x-fmu-sharedlibrary"
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
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
COSIM_ANNOTATION = "fnn-cosim.scenario"


_SCHEMA = None


def ssd_schema_errors(ssd: str | Path | bytes) -> list[str]:
    """The SSP 1.0 schema's complaints about an SSD (empty: valid), one line each.

    The XSDs are the normative SSP 1.0 schemas that ``pyssp-standard`` ships
    (``pyssp_standard/resources``); inline ``ssv:ParameterSet`` elements are
    validated too (the SSD schema admits them as lax wildcard content, checked
    against the SSV schema it is given here).
    """
    global _SCHEMA
    if _SCHEMA is None:
        from importlib.util import find_spec

        # the package's folder, found without importing it (its import is pint's and xmlschema's, over 1 s of CPU)
        folder = Path(find_spec("pyssp_standard").submodule_search_locations[0]) / "resources"
        imports = "".join(
            f'<xs:import namespace="{NS[p]}" schemaLocation="{(folder / f).as_uri()}"/>'
            for p, f in (("ssd", "SystemStructureDescription.xsd"), ("ssv", "SystemStructureParameterValues.xsd")))
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


def _bindings(where: str, component: etree._Element, folder: Path) -> dict[str, float]:
    values: dict[str, float] = {}
    bindings = component.find("ssd:ParameterBindings", NS)
    for j, binding in enumerate(bindings if bindings is not None else [], 1):
        at = f"{where}: ssd:ParameterBinding {j}"
        if binding.get("type", "application/x-ssp-parameter-set") != "application/x-ssp-parameter-set":
            raise ScenarioError(f"{at}: type {binding.get('type')!r} is not supported "
                                f"(application/x-ssp-parameter-set only)")
        if binding.get("prefix"):
            raise ScenarioError(f"{at}: prefix {binding.get('prefix')!r} is not supported")
        if binding.find("ssd:ParameterMapping", NS) is not None:
            raise ScenarioError(f"{at}: ssd:ParameterMapping is not supported")
        source = binding.get("source")
        if source is not None:
            if binding.get("sourceBase", "SSD") != "SSD":
                raise ScenarioError(f"{at}: sourceBase {binding.get('sourceBase')!r} is not supported")
            path = _source_path(at, source, folder)
            try:
                node = _xml(path).getroot()
            except etree.XMLSyntaxError as exc:
                raise ScenarioError(f"{at}: {source}: not well-formed XML: {exc}") from None
            _bind(values, _parameter_set(f"{at} ({source})", node), where)
            continue
        inline = binding.find("ssd:ParameterValues", NS)
        node = next(iter(inline), None) if inline is not None else None
        if node is None:
            raise ScenarioError(f"{at}: neither a source nor inline ssd:ParameterValues")
        _bind(values, _parameter_set(at, node), where)
    return values


def _bind(values: dict[str, float], more: Mapping[str, float], where: str) -> None:
    """A parameter set's values added to a component's: a parameter bound by two sets is refused (the
    last one won: a z_0 of -50 in one set over the -15 of another, and nothing said)."""
    for name, value in more.items():
        put_once(values, name, value, f"{where}: parameter")


def _component(where: str, element: etree._Element, folder: Path) -> tuple[str, dict[str, Any]]:
    kind = etree.QName(element).localname
    name = element.get("name")
    if kind != "Component":
        raise ScenarioError(f"{where}: ssd:{kind} {name!r}: only ssd:Component elements (FMUs) are supported, "
                            f"no nested systems or signal dictionaries")
    if not name:
        raise ScenarioError(f"{where}: no name attribute")
    at = f"ssd:Component {name!r}"
    type_ = element.get("type", FMU_TYPE)
    if type_ != FMU_TYPE:
        raise ScenarioError(f"{at}: type {type_!r} is not supported ({FMU_TYPE} only)")
    if element.get("implementation", "CoSimulation") not in ("CoSimulation", "any"):
        raise ScenarioError(f"{at}: implementation {element.get('implementation')!r} is not supported "
                            f"(CoSimulation only)")
    source = element.get("source")
    if not source:
        raise ScenarioError(f"{at}: no source attribute")
    connectors: dict[str, str] = {}
    units: dict[str, str] = {}
    for i, connector in enumerate(element.findall("ssd:Connectors/ssd:Connector", NS), 1):
        if not connector.get("name"):
            raise ScenarioError(f"{at}: ssd:Connector {i}: no name attribute")
        put_once(connectors, connector.get("name"), connector.get("kind", ""), f"{at}: ssd:Connector")
        real = connector.find("ssc:Real", NS)
        if real is not None and real.get("unit"):
            units[connector.get("name")] = real.get("unit")
    return name, {"path": _source_path(at, source, folder), "parameters": _bindings(at, element, folder),
                  "connectors": connectors, "units": units}


def _ssd_units(root: etree._Element) -> dict[str, Any]:
    """The SSD's ``ssd:Units`` (SystemStructureCommon ``ssc:Unit``/``ssc:BaseUnit``,
    the FMI form) as :class:`cosim.units.Unit`, by name."""
    out = {}
    for unit in root.iterfind("ssd:Units/ssc:Unit", NS):
        base = unit.find("ssc:BaseUnit", NS)
        if unit.get("name") and base is not None:
            where = f"ssd:Units: ssc:Unit {unit.get('name')!r}"
            exponents = tuple(_integer(where, base.get(b, "0"), b) for b in units.BASE_UNITS)
            out[unit.get("name")] = units.Unit(unit.get("name"), exponents,
                                               _number(where, base.get("factor", "1"), "factor"),
                                               _number(where, base.get("offset", "0"), "offset"))
    return out


def _connection(where: str, element: etree._Element, components: Mapping[str, dict[str, Any]],
                ssd_units: Mapping[str, Any] | None = None) -> str | dict[str, Any]:
    """One ``ssd:Connection`` as the scenario's connection: a string, or a
    table with the conversion it states (``ssc:LinearTransformation``) or
    ``units = "unchecked"`` (``suppressUnitConversion = "true"`` without
    one). A transformation without ``suppressUnitConversion`` applies after
    the conversion the connectors' units give (SSP 1.0,
    SystemStructureCommon): the two are composed into one."""
    ends = []
    for side in ("start", "end"):
        comp, conn = element.get(f"{side}Element"), element.get(f"{side}Connector")
        if comp is None:
            raise ScenarioError(f"{where}: no {side}Element: connections to the system's own connectors are "
                                f"not supported")
        if comp not in components:
            raise ScenarioError(f"{where}: {side}Element {comp!r} is no component; components are: "
                                f"{', '.join(components)}")
        if conn is None:
            raise ScenarioError(f"{where}: no {side}Connector")
        if conn not in components[comp]["connectors"]:
            raise ScenarioError(f"{where}: {side}Connector {conn!r} is no connector of {comp!r}")
        ends.append((comp, conn))
    text = " -> ".join(f"{comp}.{conn}" for comp, conn in ends)
    suppress = element.get("suppressUnitConversion", "false")
    if suppress not in ("true", "false", "1", "0"):
        raise ScenarioError(f"{where}: suppressUnitConversion = {suppress!r}: expected true or false")
    transformation = None
    for child in element:
        if not isinstance(child.tag, str):
            continue
        if child.tag == qualified("ssc", "LinearTransformation") and transformation is None:
            transformation = (_number(f"{where}: ssc:LinearTransformation", child.get("factor", "1"), "factor"),
                              _number(f"{where}: ssc:LinearTransformation", child.get("offset", "0"), "offset"))
        elif child.tag not in (qualified("ssd", "ConnectionGeometry"), qualified("ssd", "Annotations")):
            raise ScenarioError(f"{where}: {etree.QName(child).localname}: not supported (of the "
                                f"transformations, a connection may carry one ssc:LinearTransformation)")
    if suppress in ("true", "1"):
        if transformation is None:
            return {"connect": text, "units": "unchecked"}
        return {"connect": text, "factor": transformation[0], "offset": transformation[1]}
    if transformation is None:
        return text
    # the connectors' units convert first, then the transformation: target = f (u_f source + u_o) + o
    (start, start_connector), (end, end_connector) = ends  # as given: names may hold dots
    source_unit = components[start].get("units", {}).get(start_connector)
    target_unit = components[end].get("units", {}).get(end_connector)
    unit_factor, unit_offset = 1.0, 0.0
    if source_unit and target_unit and source_unit != target_unit:
        try:
            unit_factor, unit_offset = units.conversion(units.unit_of(source_unit, ssd_units) or source_unit,
                                                        units.unit_of(target_unit, ssd_units) or target_unit)
        except CosimError as exc:
            raise ScenarioError(f"{where}: {exc}") from None
    factor, offset = transformation
    return {"connect": text, "factor": factor * unit_factor, "offset": factor * unit_offset + offset}


def _annotations(parent: etree._Element, type_: str) -> list[etree._Element]:
    """The single child of each ``ssc:Annotation`` of ``type_`` under ``parent/ssd:Annotations``."""
    return [a[0] for a in parent.findall("ssd:Annotations/ssc:Annotation", NS) if a.get("type") == type_ and len(a)]


def _read_ssd(ssd_path: Path) -> _System:
    """Parse and check an SSD; every refusal names its element."""
    try:
        root = _xml(ssd_path).getroot()
    except etree.XMLSyntaxError as exc:
        raise ScenarioError(f"not well-formed XML: {exc}") from None
    if root.tag != qualified("ssd", "SystemStructureDescription"):
        raise ScenarioError(f"the root element is {root.tag}, not ssd:SystemStructureDescription")
    system = root.find("ssd:System", NS)
    if system is None:
        raise ScenarioError("no ssd:System")
    folder = ssd_path.parent
    components: dict[str, dict[str, Any]] = {}
    elements = system.find("ssd:Elements", NS)
    for i, element in enumerate(elements if elements is not None else [], 1):
        if not isinstance(element.tag, str):
            continue  # comments, processing instructions
        name, entry = _component(f"ssd:Elements child {i}", element, folder)
        if name in components:
            raise ScenarioError(f"ssd:Component {name!r}: a component of that name is already given")
        components[name] = entry
    if not components:
        raise ScenarioError(f"ssd:System {system.get('name')!r}: no ssd:Component (an FMU) in its ssd:Elements")
    ssd_units = _ssd_units(root)
    connections = [_connection(f"ssd:Connection {i}", c, components, ssd_units)
                   for i, c in enumerate(system.findall("ssd:Connections/ssd:Connection", NS), 1)]

    start = stop = step = None
    experiment = root.find("ssd:DefaultExperiment", NS)
    if experiment is not None:
        if experiment.get("startTime") is not None:
            start = _number("ssd:DefaultExperiment", experiment.get("startTime"), "startTime")
        if experiment.get("stopTime") is not None:
            stop = _number("ssd:DefaultExperiment", experiment.get("stopTime"), "stopTime")
        for algorithm in _annotations(experiment, OSP_ANNOTATION):
            for fixed in algorithm:
                if isinstance(fixed.tag, str) and etree.QName(fixed).localname == "FixedStepAlgorithm":
                    where = "ssd:DefaultExperiment: osp:FixedStepAlgorithm"
                    step = _number(where, fixed.get("baseStepSize"), "baseStepSize")
                    if step <= 0:
                        raise ScenarioError(f"{where}: baseStepSize = {fixed.get('baseStepSize')!r} is not positive")
    out = _System(root.get("name") or system.get("name") or ssd_path.parent.name, root.get("description", ""),
                  start, stop, step, components, connections)
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
    for element in root.iter(qualified("ssd", "Component"), qualified("ssd", "ParameterBinding")):
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
    file into a :class:`~cosim.scenario.Scenario` of FMUs (by path).

    The communication step comes from the OSP annotation
    (``osp:FixedStepAlgorithm baseStepSize``), else from ``step``; the
    duration from the default experiment (stop - start), else from
    ``duration``; the seed, ordering, seed parameters, recorded signals and
    envelope from this engine's annotation if the archive has it (else seed
    0, the default ordering, every output connector of every component
    recorded, no envelope). A seed parameter's bound value is dropped: the
    master sets it to the run's seed. ``overrides`` sets dotted keys
    (``{"simulation.duration": 5.0}``) as for a TOML scenario; the result is
    checked by :func:`~cosim.scenario.parse_scenario`.

    An archive is extracted to ``extract_to``, else to a temporary folder that
    lives as long as the returned scenario (``scenario.source`` is the
    extracted ``SystemStructure.ssd``; libcosim takes its folder).

    Refusals are :class:`~cosim.errors.ScenarioError` in one line that names
    the file and the element, e.g. ``x.ssp: SystemStructure.ssd:
    ssd:Connection 3: startElement 'Plant' is no component; ...``.
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
        start = system.start if system.start is not None else 0.0
        if system.step is None and step is None:
            raise ScenarioError(f"{label}: no step size: the ssd:DefaultExperiment has no OSP annotation "
                                f"(osp:FixedStepAlgorithm baseStepSize); give one (step=...)")
        if (system.stop is None) and duration is None:
            raise ScenarioError(f"{label}: no duration: the ssd:DefaultExperiment has no stopTime; give one "
                                f"(duration=...)")
        length = system.stop - start if system.stop is not None else duration
        record = system.record or [f"{c}.{n}" for c, entry in system.components.items()
                                   for n, kind in entry["connectors"].items() if kind == "output"]
        raw: dict[str, Any] = {
            "name": system.name,
            "description": system.description,
            "connections": system.connections,
            "simulation": {"duration": length, "step": system.step if system.step is not None else step,
                           "seed": system.seed if system.seed is not None else 0, "start_time": start,
                           **({"ordering": system.ordering} if system.ordering else {}),
                           **({"coupling": system.coupling} if system.coupling else {})},
            "fmus": {c: {"path": str(entry["path"]),
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


# An FMU's variable's causality -> the kind an SSD's connector to it states (SSP 1.0 ssd:Connector
# kind; an FMI 3.0 structural parameter is a parameter to an SSP tool).
_KIND_OF = {"input": "input", "output": "output", "parameter": "parameter", "structuralParameter": "parameter",
            "calculatedParameter": "calculatedParameter"}


def _check_kinds(system: _System) -> None:
    """Refuse a connector whose kind contradicts its FMU (an "input" that is
    the FMU's output, a connector to no variable of it): an SSP tool that
    trusts the SSD would connect or record the wrong thing, ours trusted the
    FMU and said nothing."""
    from .fmu_component import read_description

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
                raise ScenarioError(f"ssd:Component {name!r}: ssd:Connector {connector!r}: no variable of its FMU")
            expected = _KIND_OF.get(variable.causality)
            if kind != expected:
                raise ScenarioError(f"ssd:Component {name!r}: ssd:Connector {connector!r}: kind = {kind!r}, but its "
                                    f"FMU's variable is {'an' if variable.causality[0] in 'aeiou' else 'a'} "
                                    f"{variable.causality}" + (f" (kind {expected!r})" if expected else ""))


def _remove_extraction(folder: str, forget) -> None:
    shutil.rmtree(folder, ignore_errors=True)
    forget()
