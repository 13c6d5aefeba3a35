"""SSP 1.0 archives written: an all-FMU scenario out to a ``.ssp`` file
(:func:`export_ssp`; :mod:`cosim.ssp.archive` reads them back).

:func:`export_ssp` writes a scenario of FMUs as an archive: one
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
cannot go into an archive: such a scenario is refused, naming them. The SSD
is written with ``pyssp-standard`` (imported only here).
"""
from __future__ import annotations

import json
import os
import tempfile
import zipfile
from dataclasses import dataclass, field
from datetime import datetime, timezone
from io import BytesIO
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Mapping

from lxml import etree

from ..scenario import registry
from ..fmi import units
from ..loop.connection import check_connections, parse_connections
from ..errors import FmuError, ScenarioError, one_line
from ..names import split_endpoint
from ..scenario.definition import Scenario
from ..scenario.assembly import check_fmu_file, fmu_component, fmu_error_in_scenario, fmu_file
from .archive import COSIM_ANNOTATION, COSIM_NAMESPACE, FMU_TYPE, NS, OSP_ANNOTATION, OSP_NAMESPACE, SSD_NAME, qualified

__all__ = ["export_ssp"]

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
    :func:`~cosim.scenario.assembly.build_master` would (without instantiating)."""
    from ..fmi.fmu import FmuComponent
    from ..fmi.lifecycle import stream_seed

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
    check_connections(parse_connections(scenario.connections, components), components)
    for where, signals in (("record.signals", scenario.record or ()), ("envelope", list(scenario.envelope))):
        for signal in signals:
            comp, var = split_endpoint(signal, components) or (signal, "")
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
    if getattr(scenario, "coupling", "tight") != "tight":  # the default left out: archives as before
        root.set("coupling", scenario.coupling)
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
    for signal in scenario.record or ():  # none: every output (as an SSP archive without them is read)
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
            transformation = etree.Element(qualified("ssc", "LinearTransformation"), nsmap={"ssc": NS["ssc"]})
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
    for c in parse_connections(scenario.connections, list(scenario.fmus) + list(scenario.components)):
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
        ssd.top_level_metadata.generationTool = "fnn-cosim (cosim.ssp.archive, pyssp-standard)"
        ssd.top_level_metadata.generationDateAndTime = datetime.now(timezone.utc).replace(microsecond=0).isoformat()
        ssd.system = system
        ssd.default_experiment = experiment
        ssd.conversions = conversions
        for part in parts:
            for unit, base in part.units.items():
                if unit in ssd.units:
                    continue
                if base is None:  # a unit the modelDescription does not define: as pint reads its name, so
                    base = units.parse(unit)  # that an importer converts as our master does (cosim.fmi.units)
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
