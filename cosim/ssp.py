"""SSP 1.0 archives: an all-FMU scenario out to a ``.ssp`` file, and back in.

An SSP archive (System Structure and Parameterization, Modelica Association,
version 1.0) is a zip file holding ``SystemStructure.ssd`` (the system: its
components, their connectors, the connections, parameter values, the default
experiment) and the FMUs under ``resources/``. Any SSP tool can load it; the
Open Simulation Platform's libcosim runs it (``docs/ssp.md``).

* :func:`export_ssp` writes a scenario of FMUs as an archive: one
  ``ssd:System`` with one ``ssd:Component`` per FMU instance
  (``resources/<Instance>.fmu``), its inputs, outputs and the parameters the
  scenario sets as connectors (types and units from the modelDescription, the
  units defined in ``ssd:Units``), every connection (brace groups expanded),
  every parameter value (an inline ``ssv:ParameterSet`` per component), the
  default experiment (start, stop = start + duration) with the OSP annotation
  libcosim takes its step size from, and this engine's own annotation (seed,
  ordering, seed parameters, recorded signals, envelope; an FMU's seed
  parameter also gets the scenario's seed in its parameter set, for other
  tools). The FMU of a registered model is packed with the scenario's values
  as its own start values (``RegisteredModel.build_with``), so that a tool
  that ignores parameter bindings (fmpy's ``simulate_ssp``) still flies the
  scenario (``docs/ssp.md``, "Self-contained archives"). Python components
  cannot go into an archive: such a scenario is refused, naming them.
* :func:`load_ssp` reads an archive (or its extracted folder, or the ``.ssd``
  file) back into a :class:`~cosim.scenario.Scenario` (FMUs by path), checked
  by :func:`~cosim.scenario.parse_scenario` like any TOML scenario; a bad
  archive is a one-line :class:`~cosim.errors.ScenarioError` naming the element.
* :func:`run_libcosim` runs an archive in libcosim (optional ``libcosimpy``)
  and returns a :class:`~cosim.master.RunResult` like the master's.
* :func:`ssd_schema_errors` validates an SSD against the SSP 1.0 XML schemas
  shipped with ``pyssp-standard``.

The SSD is written with ``pyssp-standard`` (imported only by
:func:`export_ssp`); the reader uses lxml directly, so that every refusal can
name the element it comes from.
"""
from __future__ import annotations

import json
import os
import posixpath
import shutil
import tempfile
import time as _time
import urllib.parse
import weakref
import zipfile
from dataclasses import dataclass, field
from datetime import datetime, timezone
from io import BytesIO
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Mapping, Sequence

from lxml import etree

from . import registry, units
from .connection import check_connections, parse_connections
from .ssv import number as _number, parameter_set as _parameter_set, read_parameter_set
from .errors import CosimError, FmuError, ScenarioError, one_line, show_folder_as
from .files import (SSD_NAME, extract_zip, given_twice, is_ssp, json_document, put_once, read_entry, regular_file,
                    safe_name, zip_members)
from .limits import MAX_DOCUMENT_BYTES
from .scenario import Scenario, apply_overrides, fmu_component, fmu_error_in_scenario, fmu_file, parse_scenario
from .scenario import check_fmu_file

__all__ = ["export_ssp", "load_ssp", "read_parameter_set", "is_ssp", "run_libcosim", "ssd_schema_errors", "SSD_NAME", "FMU_TYPE",
           "OSP_NAMESPACE", "OSP_ANNOTATION", "COSIM_NAMESPACE", "COSIM_ANNOTATION"]

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

_TYPES = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Integer": "Integer", "Boolean": "Boolean",
          "String": "String", **{f"{s}Int{n}": "Integer" for s in ("", "U") for n in (8, 16, 32, 64)}}
_KINDS = ("input", "output", "parameter")


def _num(value: float) -> str:
    """A float as XML text that reads back to the same float."""
    return repr(float(value))


# ---- export -----------------------------------------------------------------------------------

@dataclass
class _Part:
    """One FMU instance on its way into the archive."""

    name: str
    data: bytes  # the .fmu file
    connectors: list[tuple[str, str, str, str | None]] = field(default_factory=list)  # name, kind, type, unit
    parameters: list[tuple[str, str, Any]] = field(default_factory=list)  # name, type, value
    units: dict[str, Any] = field(default_factory=dict)  # unit name -> fmpy BaseUnit or None


def _fmu_bytes(path: Path) -> bytes:
    """The bytes of an FMU file; an extracted FMU folder is zipped."""
    if not path.is_dir():
        return path.read_bytes()
    buffer = BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in sorted(path.rglob("*")):
            if file.is_file():
                archive.write(file, file.relative_to(path).as_posix())
    return buffer.getvalue()


def _collect(scenario: Scenario, fmu_files: Mapping[str, Path]) -> list[_Part]:
    """Every FMU's file, connectors, parameter values and units, checked as
    :func:`~cosim.scenario.build_master` would (without instantiating)."""
    from .fmu_component import FmuComponent, stream_seed

    components: dict[str, FmuComponent] = {}  # as build_master makes them (fmu_component), not instantiated
    values: dict[str, dict[str, Any]] = {}
    try:
        for name, spec in scenario.fmus.items():
            values[name] = params = dict(spec["parameters"])
            if spec.get("seed_parameter") is not None:
                # the scenario's seed (of the FMU's stream), so that another SSP tool runs with it; our
                # master sets the run's
                params[spec["seed_parameter"]] = stream_seed(scenario.seed, spec.get("seed_stream", 0))
            components[name] = fmu_component(name, spec, fmu_files.get(name) or _self_contained(name, spec, params))
    except FmuError as exc:
        raise fmu_error_in_scenario(scenario, exc) from None
    parts = []
    for name, fmu in components.items():
        # the FMI version, the parameters' names and declared ranges: build_master's own check
        check_fmu_file(scenario, fmu)
        part = _Part(name, _fmu_bytes(fmu.path))
        defined = {u.name: u.baseUnit for u in fmu.model_description.unitDefinitions}
        params = values[name]
        for var in fmu.model_description.modelVariables:
            kind = var.causality
            if kind not in _KINDS or (kind == "parameter" and var.name not in params):
                continue
            type_ = _TYPES.get(var.type)
            if type_ is None or getattr(var, "dimensions", None):
                if var.name in params:
                    raise ScenarioError(f"fmus.{name}.parameters.{var.name}: a {var.type} variable cannot be "
                                        f"given in an SSP parameter set")
                continue  # enumerations, binaries, clocks and arrays have no connector here
            unit = (var.unit or None) if type_ == "Real" else None
            part.connectors.append((var.name, kind, type_, unit))
            if unit is not None:
                part.units.setdefault(unit, defined.get(unit))
        for key, value in params.items():
            part.parameters.append((key, _TYPES[fmu.variables[key].type], value))
        parts.append(part)
    check_connections(parse_connections(scenario.connections), components)
    for where, signals in (("record.signals", scenario.record), ("envelope", list(scenario.envelope))):
        for signal in signals:
            comp, _, var = signal.partition(".")
            fmu = components.get(comp)
            if fmu is None or var not in {p.name for p in fmu.inputs + fmu.outputs}:
                raise ScenarioError(f"{where}: {signal!r} is no input or output of an FMU of the scenario "
                                    f"({', '.join(components)})")
    return parts


def _self_contained(name: str, spec: Mapping[str, Any], values: Mapping[str, Any]) -> Path:
    """The FMU file of the ``[fmus]`` entry ``name``: for a registered model
    that can build one, an FMU whose own start values are ``values`` (the
    scenario's parameters and seed), so that a tool that ignores the SSD's
    parameter bindings still runs the scenario; else the entry's file. A
    value the model refuses is one line naming it."""
    model = registry.fmu_models().get(spec.get("model")) if "path" not in spec else None
    if model is None or model.build_with is None:
        return fmu_file(spec)
    try:
        return model.build_with({k: float(v) for k, v in values.items()}, spec["fmi_version"])
    except (KeyError, ValueError) as exc:
        raise ScenarioError(f"fmus.{name}.parameters: {one_line(str(exc).strip(chr(39)))}") from None


def _osp_algorithm(step: float) -> etree._Element:
    algorithm = etree.Element(f"{{{OSP_NAMESPACE}}}Algorithm", nsmap={"osp": OSP_NAMESPACE})
    etree.SubElement(algorithm, f"{{{OSP_NAMESPACE}}}FixedStepAlgorithm", baseStepSize=_num(step))
    return algorithm


def _cosim_annotation(scenario: Scenario) -> etree._Element:
    q = lambda tag: f"{{{COSIM_NAMESPACE}}}{tag}"  # noqa: E731
    root = etree.Element(q("Scenario"), nsmap={"cosim": COSIM_NAMESPACE}, seed=str(scenario.seed),
                         blockRows=str(scenario.block_rows))
    if getattr(scenario, "ordering", None) is not None:
        root.set("ordering", scenario.ordering)
    for name, spec in scenario.fmus.items():
        if spec.get("seed_parameter") is not None:
            element = etree.SubElement(root, q("SeedParameter"), component=name, parameter=spec["seed_parameter"])
            if spec.get("seed_stream"):
                element.set("stream", str(spec["seed_stream"]))
    for name, spec in scenario.fmus.items():  # what SSP 1.0 has no place for: how our master runs the FMU
        settings = {k: json.dumps(dict(spec[k])) for k in ("start", "solver") if spec.get(k)}
        if spec.get("interface") is not None:
            settings["interface"] = spec["interface"]
        if settings:
            etree.SubElement(root, q("Fmu"), component=name, **settings)
    for signal in scenario.record:
        etree.SubElement(root, q("Record"), signal=signal)
    for signal, (low, high) in scenario.envelope.items():
        etree.SubElement(root, q("Envelope"), signal=signal, low=_num(low), high=_num(high))
    for name in registry.sections():  # an application's own tables (e.g. which signals a metric compares)
        if name in scenario.raw:
            etree.SubElement(root, q("Section"), name=name).text = json.dumps(scenario.raw[name])
    return root


def _ssd_class():
    from pyssp_standard.ssd import SSD

    class OrderedSSD(SSD):
        """pyssp-standard's SSD with two fixes made after it builds the tree:

        * pyssp-standard 0.9.1 appends ssd:Units after ssd:DefaultExperiment;
          the SSP 1.0 schema wants them before it (System, Enumerations,
          Units, DefaultExperiment, Annotations);
        * every namespace is declared once, on the root. libcosim reads the SSD
          with Boost.PropertyTree, which sees an ``xmlns:osp`` declaration on
          osp:Algorithm as one more child and fails ("Unknown algorithm:
          <xmlattr>"); declared on the root it is out of the way.
        """

        def __write__(self):
            super().__write__()
            defined = self.root.find("ssd:Units", NS)
            experiment = self.root.find("ssd:DefaultExperiment", NS)
            if defined is not None and experiment is not None:
                experiment.addprevious(defined)
            _write_conversions(self.root, getattr(self, "conversions", {}))
            etree.cleanup_namespaces(self.root, top_nsmap={"ssv": NS["ssv"], "osp": OSP_NAMESPACE,
                                                           "cosim": COSIM_NAMESPACE})

    return OrderedSSD


def _connection_key(start_element, start_connector, end_element, end_connector) -> tuple[str, str, str, str]:
    return start_element, start_connector, end_element, end_connector


def _write_conversions(root: etree._Element, conversions: Mapping[tuple[str, str, str, str], Any]) -> None:
    """A connection the scenario states a conversion for, or marks unchecked,
    the SSP 1.0 way (SystemStructureDescription, ssd:Connection;
    SystemStructureCommon, ssc:LinearTransformation): ``suppressUnitConversion
    = "true"`` (the stated conversion replaces the one the connectors' units
    would give; unchecked: none at all) and, for a conversion,
    ``<ssc:LinearTransformation factor offset>`` (target = factor * source +
    offset) as its first child. A conversion the units give is written as
    the connectors' units (and ``ssd:Units``): the importing tool converts."""
    for element in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS):
        key = _connection_key(*(element.get(a) for a in ("startElement", "startConnector", "endElement",
                                                          "endConnector")))
        if key not in conversions:
            continue
        element.set("suppressUnitConversion", "true")
        conversion = conversions[key]
        if conversion is not None:
            transformation = etree.Element(_q("ssc", "LinearTransformation"), nsmap={"ssc": NS["ssc"]})
            transformation.set("factor", _num(conversion[0]))
            transformation.set("offset", _num(conversion[1]))
            element.insert(0, transformation)


def _write_ssd(scenario: Scenario, parts: list[_Part], path: Path) -> None:
    """``SystemStructure.ssd`` with pyssp-standard's classes; what they have no
    class for (the annotations' contents) is built with lxml and added to
    pyssp-standard's ``Annotation``."""
    from pyssp_standard.common_content_ssc import Annotation, TypeBoolean, TypeInteger, TypeReal, TypeString
    from pyssp_standard.parameter_types import ParameterType
    from pyssp_standard.ssd import Component, Connection, Connector, DefaultExperiment, ParameterBinding, System
    from pyssp_standard.ssv import Parameter, SSVElem
    from pyssp_standard.unit import BaseUnit, Unit

    type_of = {"Real": TypeReal, "Integer": TypeInteger, "Boolean": TypeBoolean, "String": TypeString}
    system = System(name=scenario.name)
    for part in parts:
        component = Component()
        component.name, component.component_type, component.source = part.name, FMU_TYPE, f"resources/{part.name}.fmu"
        component.connectors = [Connector(name=n, kind=k, type_=TypeReal(u) if t == "Real" else type_of[t]())
                                for n, k, t, u in part.connectors]
        if part.parameters:
            values = []
            for name, type_, value in part.parameters:
                text = {"Real": _num, "Integer": lambda v: str(int(v)),
                        "Boolean": lambda v: "true" if v else "false", "String": str}[type_](value)
                parameter_type = ParameterType(type_, {"value": text})
                # pyssp-standard 0.9.1 writes unit=None as an attribute (lxml refuses it): a value
                # without its own unit (the connector declares it) must drop the key.
                parameter_type.parameter = {k: v for k, v in parameter_type.parameter.items() if v is not None}
                values.append(Parameter(name=name, type_name=type_, type_value=parameter_type))
            component.parameter_bindings = [ParameterBinding(ssv=SSVElem(name=part.name, parameters=values))]
        system.elements.append(component)
    conversions = {}  # stated conversions (factor, offset) and unchecked connections (None)
    for c in parse_connections(scenario.connections):
        system.connections.append(Connection(start_element=c.source.component, start_connector=c.source.variable,
                                             end_element=c.destination.component,
                                             end_connector=c.destination.variable))
        if c.conversion is not None or c.unchecked:
            key = _connection_key(c.source.component, c.source.variable, c.destination.component,
                                  c.destination.variable)
            conversions[key] = c.conversion
    annotation = Annotation(COSIM_ANNOTATION)
    annotation.add_element(_cosim_annotation(scenario))
    system.annotations.add_annotation(annotation)

    experiment = DefaultExperiment()
    experiment.start_time = scenario.start_time
    experiment.stop_time = scenario.start_time + scenario.duration
    osp = Annotation(OSP_ANNOTATION)
    osp.add_element(_osp_algorithm(scenario.step))  # pyssp-standard has no OSP classes: plain lxml
    experiment.annotations.add_annotation(osp)

    with _ssd_class()(path, mode="w") as ssd:
        ssd.name, ssd.version = scenario.name, "1.0"
        ssd.base_element.description = scenario.description
        ssd.top_level_metadata.generationTool = "fnn-cosim (cosim.ssp, pyssp-standard)"
        ssd.top_level_metadata.generationDateAndTime = datetime.now(timezone.utc).replace(microsecond=0).isoformat()
        ssd.system = system
        ssd.default_experiment = experiment
        ssd.conversions = conversions
        for part in parts:
            for unit, base in part.units.items():
                if unit in ssd.units:
                    continue
                if base is None:  # a unit the modelDescription does not define: as pint reads its name, so
                    base = units.parse(unit)  # that an importer converts as our master does (cosim.units)
                    if base is None:
                        continue  # a name nothing knows stays a bare name
                    base = SimpleNamespace(**dict(zip(units.BASE_UNITS, base.exponents)), factor=base.factor,
                                           offset=base.offset)
                exponents = {k: getattr(base, k) for k in units.BASE_UNITS if getattr(base, k)}
                if base.factor != 1.0:
                    exponents["factor"] = base.factor
                if base.offset != 0.0:
                    exponents["offset"] = base.offset
                ssd.units.add_unit(Unit(unit, BaseUnit(exponents)))


def export_ssp(scenario: Scenario, out_path: str | Path, fmu_files: Mapping[str, str | Path] | None = None) -> Path:
    """Write ``scenario`` as an SSP 1.0 archive at ``out_path``; return its path.

    Every FMU instance becomes a component whose FMU is copied to
    ``resources/<Instance>.fmu``: a registered model that can be is built with
    the values the archive binds (the instance's parameters and its seed) as
    its own start values, else as the registry builds it; ``fmu_files`` may
    give, per instance, an FMU file or extracted folder to use instead (its
    values are then in the bindings only). Refused with a
    :class:`~cosim.errors.ScenarioError`: Python components (an archive holds
    FMUs only; the message names them), an FMU
    file that cannot be used, a parameter the FMU does not have, a recorded
    or bounded signal that is no FMU input or output; a wrong connection is a
    :class:`~cosim.errors.ConnectionCheckError`. Nothing is written then.
    """
    if scenario.components:
        names = ", ".join(sorted(scenario.components))
        raise ScenarioError(f"scenario {scenario.name!r}: an SSP archive holds FMUs only; remove the Python "
                            f"component(s) {names} (or make them FMUs) to export it")
    parts = _collect(scenario, {k: Path(v) for k, v in (fmu_files or {}).items()})
    from pyssp_standard.ssp import SSP

    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.partial")
    try:
        with tempfile.TemporaryDirectory(prefix="ssp-export-") as staging:
            ssd_path = Path(staging) / SSD_NAME
            _write_ssd(scenario, parts, ssd_path)
            with SSP(tmp, mode="w") as archive:
                archive.add_file(ssd_path)
                for part in parts:
                    archive.add_file_contents(part.data, Path("resources") / f"{part.name}.fmu")
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    return out


# ---- schema -----------------------------------------------------------------------------------

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
        import pyssp_standard

        folder = Path(pyssp_standard.__file__).parent / "resources"
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
    seed_parameters: dict[str, str] = field(default_factory=dict)  # component -> parameter
    seed_streams: dict[str, int] = field(default_factory=dict)  # component -> its stream, where not 0
    fmu_settings: dict[str, dict[str, Any]] = field(default_factory=dict)  # component -> interface, solver, start
    record: list[str] = field(default_factory=list)
    envelope: dict[str, list[float]] = field(default_factory=dict)
    sections: dict[str, Any] = field(default_factory=dict)  # an application's own tables, by name


def _q(prefix: str, tag: str) -> str:
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
        ends.append(f"{comp}.{conn}")
    text = f"{ends[0]} -> {ends[1]}"
    suppress = element.get("suppressUnitConversion", "false")
    if suppress not in ("true", "false", "1", "0"):
        raise ScenarioError(f"{where}: suppressUnitConversion = {suppress!r}: expected true or false")
    transformation = None
    for child in element:
        if not isinstance(child.tag, str):
            continue
        if child.tag == _q("ssc", "LinearTransformation") and transformation is None:
            transformation = (_number(f"{where}: ssc:LinearTransformation", child.get("factor", "1"), "factor"),
                              _number(f"{where}: ssc:LinearTransformation", child.get("offset", "0"), "offset"))
        elif child.tag not in (_q("ssd", "ConnectionGeometry"), _q("ssd", "Annotations")):
            raise ScenarioError(f"{where}: {etree.QName(child).localname}: not supported (of the "
                                f"transformations, a connection may carry one ssc:LinearTransformation)")
    if suppress in ("true", "1"):
        if transformation is None:
            return {"connect": text, "units": "unchecked"}
        return {"connect": text, "factor": transformation[0], "offset": transformation[1]}
    if transformation is None:
        return text
    # the connectors' units convert first, then the transformation: target = f (u_f source + u_o) + o
    (start, start_connector), (end, end_connector) = (e.split(".", 1) for e in ends)
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
    if root.tag != _q("ssd", "SystemStructureDescription"):
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
    for element in root.iter(_q("ssd", "Component"), _q("ssd", "ParameterBinding")):
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
                           **({"ordering": system.ordering} if system.ordering else {})},
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


# ---- libcosim ---------------------------------------------------------------------------------

def run_libcosim(path: str | Path, signals: Sequence[str], *, step: float | None = None,
                 duration: float | None = None):
    """Run an SSP archive (or its extracted folder) in libcosim and record
    ``signals`` (``Component.variable``) at every communication point, t0
    (after libcosim's initialization) included; return a
    :class:`~cosim.master.RunResult` like the master's (``data[:, 0]`` is time).

    Needs ``libcosimpy``. The step is the archive's (its OSP annotation)
    unless ``step`` is given; the duration the default experiment's unless
    ``duration`` is given. libcosim runs FMI 1.0 and 2.0 co-simulation FMUs
    only (an FMI 3.0 FMU crashes the process), so an archive holding an FMI
    3.0 FMU is refused before libcosim sees it; so is a parameter value that
    names no parameter or input of its FMU (libcosim would log a warning and
    run without it). Sets libcosim's log level (process-wide) to errors only.
    """
    from ctypes import POINTER, c_double, c_int, c_int64, c_size_t, c_uint32

    import numpy as np
    try:
        from libcosimpy import CosimLogging
        from libcosimpy._internal import get_last_error_message, libcosimc, wrap_function
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimObserver import CosimObserver
    except ImportError as exc:
        raise ImportError(f"running an SSP archive in libcosim needs libcosimpy ({exc})") from None
    from fmpy import read_model_description

    from .master import RunResult

    overrides = {k: v for k, v in (("simulation.step", step), ("simulation.duration", duration)) if v is not None}
    with tempfile.TemporaryDirectory(prefix="ssp-libcosim-") as tmp:
        scenario = load_ssp(path, step=step, duration=duration, overrides=overrides, extract_to=tmp)
        units: dict[str, str | None] = {}
        for name, spec in scenario.fmus.items():
            md = read_model_description(str(spec["path"]), validate=False)
            units.update({f"{name}.{v.name}": v.unit or None for v in md.modelVariables})
            if not md.fmiVersion.startswith(("1.", "2.")):
                raise ScenarioError(f"{path}: ssd:Component {name!r} is an FMI {md.fmiVersion} FMU; libcosim runs "
                                    f"FMI 1.0 and 2.0 co-simulation FMUs only")
            variables = {v.name: v for v in md.modelVariables}
            for key in spec["parameters"]:
                if key not in variables or variables[key].causality not in ("parameter", "input"):
                    raise ScenarioError(f"{path}: ssd:Component {name!r}: ssv:Parameter {key!r} is no parameter "
                                        f"or input of its FMU")
        h, n = scenario.step, scenario.n_steps
        CosimLogging.log_output_level(CosimLogging.CosimLogLevel.ERROR)
        try:  # libcosimpy asserts; libcosim says why in its last error message
            execution = CosimExecution.from_ssp_file(str(scenario.source.parent),
                                                     step_size=round(h * 1e9) if step is not None else None)
        except AssertionError:
            raise CosimError(f"{path}: libcosim cannot load the archive: {get_last_error_message()}") from None
        slaves = {info.name.decode(): info.index for info in execution.slave_infos()}  # not the SSD's order
        targets = []
        for signal in signals:
            comp, _, var = signal.partition(".")
            if comp not in slaves:
                raise ScenarioError(f"signal {signal!r}: no component {comp!r}; components are: {', '.join(slaves)}")
            refs = {v.name.decode(): v.reference for v in execution.slave_variables(slaves[comp])}
            if var not in refs:
                raise ScenarioError(f"signal {signal!r}: {comp} has no variable {var!r}")
            targets.append((slaves[comp], refs[var]))
        observer = CosimObserver.create_time_series(n + 1)
        execution.add_observer(observer)
        for slave, ref in targets:
            observer.start_time_series(slave, ref, CosimVariableType.REAL)
        wall0 = _time.perf_counter()
        if not execution.step(n):
            raise CosimError(f"{path}: libcosim failed: {get_last_error_message()}")
        wall = _time.perf_counter() - wall0
        # libcosimpy 0.0.6 drops the last sample when step 0 is among those read (it
        # counts zero step numbers as missing ones): read them through libcosimc itself.
        read = wrap_function(lib=libcosimc(), funcname="cosim_observer_slave_get_real_samples", restype=c_int64,
                             argtypes=[POINTER(CosimObserver), c_int, c_uint32, c_int64, c_size_t,
                                       POINTER(c_double), POINTER(c_int64), POINTER(c_int64)])
        columns = ("time",) + tuple(signals)
        data = np.empty((n + 1, len(columns)))
        data[:, 0] = scenario.start_time + np.arange(n + 1) * h  # from the step counter, as the master's
        values, numbers, times = np.empty(n + 1), np.empty(n + 1, np.int64), np.empty(n + 1, np.int64)
        for j, (slave, ref) in enumerate(targets, 1):
            got = read(observer.ptr(), slave, ref, 0, n + 1, values.ctypes.data_as(POINTER(c_double)),
                       numbers.ctypes.data_as(POINTER(c_int64)), times.ctypes.data_as(POINTER(c_int64)))
            if got != n + 1 or not np.array_equal(numbers, np.arange(n + 1)):
                raise CosimError(f"libcosim returned {got} samples of {columns[j]} for steps 0..{n}")
            data[:, j] = values
        del observer, execution
    return RunResult(columns, ("s",) + tuple(units.get(s) for s in signals), data, "ok", None, wall, n, h,
                     seed=scenario.seed)
