"""SSP archives of toy FMUs: export -> load round trip, the SSP 1.0 schema,
the master on a loaded archive, every refusal; and (with libcosimpy) how
libcosim's fixed-step algorithm orders a step, shown with a probe FMU whose
answers are derived by hand. ``docs/ssp.md`` quotes what these tests find."""
from __future__ import annotations

import gc
import json
import importlib.util
import re
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

import cosim
import toy_models
from cosim.loop.connection import parse_connections
from cosim.errors import ConnectionCheckError, ScenarioError
from cosim.fmi.fmu import FmuComponent
from cosim.loop.master import Master
from cosim.scenario.definition import apply_overrides, parse_scenario
from cosim.scenario.assembly import build_master
from cosim.ssp.archive import (COSIM_ANNOTATION, COSIM_NAMESPACE, NS, OSP_ANNOTATION, OSP_NAMESPACE, SSD_NAME, load_ssp,
                       ssd_schema_errors)
from cosim.ssp.export import export_ssp
from fmu_models.export.build import cached_fmu
from fmu_models.export.model import FmuModel
from fmu_models.export.variables import input_, output, parameter, state

SCENARIO = """
name = "toy_chain"
description = "three first-order lags in a chain"
connections = ["{A,B}.y -> {B,C}.u"]

[simulation]
duration = 2.0
step = 0.1
seed = 7
start_time = 0.5
ordering = "exchange"

[fmus.A]
model = "toy_FirstOrderLag"
parameters = { y_0 = 1.5, u = 2.0 }

[fmus.B]
model = "toy_FirstOrderLag"
parameters = { tau = 0.25 }

[fmus.C]
model = "toy_FirstOrderLag"
parameters = { k = 0.5, y_0 = -1.0 }

[record]
signals = ["A.y", "B.y", "C.y", "B.rate", "C.rate", "C.u"]
block_rows = 4

[envelope]
"C.y" = [-10.0, 10.0]
"""


pytestmark = pytest.mark.usefixtures("toys")  # tests/engine/conftest.py


@pytest.fixture
def scenario():
    return parse_scenario(tomllib.loads(SCENARIO))


@pytest.fixture
def archive(scenario, tmp_path):
    return export_ssp(scenario, tmp_path / "toy_chain.ssp")


def ssd_of(path: Path) -> etree._Element:
    with zipfile.ZipFile(path) as z:
        return etree.fromstring(z.read(SSD_NAME))


def expanded(connections):
    return [(str(c.source), str(c.destination)) for c in parse_connections(connections)]


# ---- round trip -------------------------------------------------------------------------------

def test_round_trip_gives_the_same_scenario(scenario, archive):
    loaded = load_ssp(archive)
    assert list(loaded.fmus) == ["A", "B", "C"]
    for name in scenario.fmus:
        assert loaded.fmus[name]["parameters"] == scenario.fmus[name]["parameters"]
        assert loaded.fmus[name]["path"].read_bytes() == toy_models.lag_fmu_path(2).read_bytes()
    assert expanded(loaded.connections) == expanded(scenario.connections) == [("A.y", "B.u"), ("B.y", "C.u")]
    assert loaded.components == {}
    for key in ("name", "description", "duration", "step", "seed", "start_time", "ordering", "record",
                "block_rows", "envelope"):
        assert getattr(loaded, key) == getattr(scenario, key), key
    assert loaded.source.name == SSD_NAME and loaded.source.parent.is_dir()


def test_archive_holds_the_ssd_and_one_fmu_per_instance(archive):
    with zipfile.ZipFile(archive) as z:
        files = {n for n in z.namelist() if not n.endswith("/")}
        assert files == {SSD_NAME, "resources/A.fmu", "resources/B.fmu", "resources/C.fmu"}
        assert z.read("resources/B.fmu") == toy_models.lag_fmu_path(2).read_bytes()
    root = ssd_of(archive)
    assert root.get("version") == "1.0" and root.get("name") == "toy_chain"
    components = root.findall("ssd:System/ssd:Elements/ssd:Component", NS)
    assert [(c.get("name"), c.get("type"), c.get("source")) for c in components] == [
        (n, "application/x-fmu-sharedlibrary", f"resources/{n}.fmu") for n in "ABC"]
    # inputs, outputs, and the parameters the scenario sets, with the modelDescription's types and units
    a = {c.get("name"): (c.get("kind"), c[0].tag.split("}")[1], c[0].get("unit"))
         for c in components[0].findall("ssd:Connectors/ssd:Connector", NS)}
    assert a == {"y": ("output", "Real", "m"), "rate": ("output", "Real", "m/s"), "u": ("input", "Real", "m"),
                 "y_0": ("parameter", "Real", "m")}
    values = {p.get("name"): p[0].get("value") for p in components[0].iterfind(".//ssv:Parameter", NS)}
    assert values == {"y_0": "1.5", "u": "2.0"}
    units = {u.get("name"): dict(u.find("ssc:BaseUnit", NS).attrib) for u in root.findall("ssd:Units/ssc:Unit", NS)}
    assert units == {"m": {"m": "1"}, "m/s": {"m": "1", "s": "-1"}, "s": {"s": "1"}, "1": {}}
    connections = [(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                   for c in root.findall("ssd:System/ssd:Connections/ssd:Connection", NS)]
    assert connections == [("A", "y", "B", "u"), ("B", "y", "C", "u")]
    experiment = root.find("ssd:DefaultExperiment", NS)
    assert (experiment.get("startTime"), experiment.get("stopTime")) == ("0.5", "2.5")
    osp = experiment.find("ssd:Annotations/ssc:Annotation", NS)
    assert osp.get("type") == OSP_ANNOTATION
    fixed = osp.find(f"{{{OSP_NAMESPACE}}}Algorithm/{{{OSP_NAMESPACE}}}FixedStepAlgorithm")
    assert fixed.get("baseStepSize") == "0.1"
    assert root.find("ssd:System/ssd:Annotations/ssc:Annotation", NS).get("type") == COSIM_ANNOTATION


def test_namespaces_are_declared_on_the_root_only(archive):
    """libcosim's Boost.PropertyTree reader takes an xmlns attribute on
    osp:Algorithm for an algorithm ("Unknown algorithm: <xmlattr>")."""
    with zipfile.ZipFile(archive) as z:
        text = z.read(SSD_NAME).decode()
    assert text.count("xmlns:") == 5
    assert re.search(r"<ssd:SystemStructureDescription [^>]*xmlns:osp=", text)
    assert "<osp:Algorithm>" in text and "<ssv:ParameterSet version" in text


def test_fmi3_round_trip(scenario, tmp_path):
    """An FMI 3.0 FMU goes into an archive as well (libcosim cannot run it; our master can)."""
    scenario = parse_scenario(apply_overrides(scenario.raw, {f"fmus.{n}.fmi_version": 3 for n in scenario.fmus}))
    loaded = load_ssp(export_ssp(scenario, tmp_path / "fmi3.ssp"))
    assert loaded.fmus["A"]["path"].read_bytes() == toy_models.lag_fmu_path(3).read_bytes()
    with build_master(scenario) as m1, build_master(loaded) as m2:
        assert np.array_equal(m1.run(scenario.duration, t0=0.5).data, m2.run(loaded.duration, t0=0.5).data)


# ---- the SSP 1.0 schema ------------------------------------------------------------------------

def test_the_ssd_is_valid_against_the_ssp_1_0_schema(archive):
    with zipfile.ZipFile(archive) as z:
        ssd = z.read(SSD_NAME)
    assert ssd_schema_errors(ssd) == []
    # the check is a real one, inline parameter sets included
    assert "'bogus' is not an element of the set" in ssd_schema_errors(ssd.replace(b'"input"', b'"bogus"', 1))[0]
    assert "'abc' is not a valid value of the atomic type 'xs:double'" in \
        ssd_schema_errors(ssd.replace(b'value="1.5"', b'value="abc"'))[0]


def test_units_stay_before_the_default_experiment(archive):
    """pyssp-standard 0.9.1 writes ssd:Units after ssd:DefaultExperiment,
    which the schema refuses; the export puts them back."""
    root = ssd_of(archive)
    tags = [etree.QName(child).localname for child in root]
    assert tags == ["System", "Units", "DefaultExperiment"]
    units = root.find("ssd:Units", NS)
    root.remove(units)
    root.append(units)
    assert "Units': This element is not expected" in ssd_schema_errors(etree.tostring(root))[0]


# ---- the master on a loaded archive --------------------------------------------------------------

def test_master_runs_the_loaded_archive_as_the_original(scenario, archive):
    loaded = load_ssp(archive)
    with build_master(scenario) as m1, build_master(loaded) as m2:
        r1 = m1.run(scenario.duration, seed=scenario.seed, t0=scenario.start_time)
        r2 = m2.run(loaded.duration, seed=loaded.seed, t0=loaded.start_time)
    assert r1.columns == r2.columns
    assert np.array_equal(r1.data, r2.data)
    # and the values are the lags': A from y_0 = 1.5 with u = 2 (k = 2, tau = 0.5)
    y = 1.5
    for n in range(3):
        assert r2["A.y"][n] == pytest.approx(y, abs=1e-12)
        y = toy_models.lag_step(y, 2.0, 0.1)


def test_load_from_the_folder_the_ssd_and_extract_to(archive, tmp_path):
    folder = tmp_path / "unpacked"
    by_archive = load_ssp(archive, extract_to=folder)
    assert by_archive.source == folder / SSD_NAME and (folder / "resources" / "A.fmu").is_file()
    for other in (load_ssp(folder), load_ssp(folder / SSD_NAME)):
        assert other.fmus == by_archive.fmus and other.connections == by_archive.connections


def test_the_temporary_extraction_lives_as_long_as_the_scenario(archive):
    loaded = load_ssp(archive)
    folder = loaded.source.parent
    assert folder.is_dir()
    del loaded
    gc.collect()
    assert not folder.exists()


def test_an_error_about_a_packed_fmu_names_the_archive_not_the_temporary_folder(archive, tmp_path):
    """A broken FMU inside an archive: the one-line error names it as
    ``archive/resources/B.fmu``, never the folder it was extracted to."""
    broken = tmp_path / "broken.ssp"
    with zipfile.ZipFile(archive) as source, zipfile.ZipFile(broken, "w") as target:
        for entry in source.infolist():
            target.writestr(entry, b"no zip" if entry.filename == "resources/B.fmu" else source.read(entry))
    loaded = load_ssp(broken)
    with pytest.raises(ScenarioError) as info:
        build_master(loaded)
    message = str(info.value)
    assert f"{broken}/resources/B.fmu" in message and "not an FMU" in message
    assert str(loaded.source.parent) not in message and "ssp-broken-" not in message


def test_overrides_and_fallbacks(archive, tmp_path):
    loaded = load_ssp(archive, overrides={"simulation.duration": 0.5, "fmus.B.parameters.tau": 0.75})
    assert loaded.duration == 0.5 and loaded.fmus["B"]["parameters"]["tau"] == 0.75
    # without the OSP annotation and the stop time, the arguments give them
    folder = _edited(archive, tmp_path, lambda root: [
        _drop(root, "ssd:DefaultExperiment/ssd:Annotations"),
        root.find("ssd:DefaultExperiment", NS).attrib.pop("stopTime")])
    with pytest.raises(ScenarioError, match=r"SystemStructure.ssd: no duration: the ssd:DefaultExperiment has no "
                                            r"stopTime; give one \(duration=\.\.\. or --set simulation.duration"):
        load_ssp(folder, step=0.05)
    # no step anywhere in the archive: the FMUs' DefaultExperiment stepSize, else the span / 1000
    # (tests/engine/test_engine_ssp_foreign.py); the user's setting first
    assert load_ssp(folder, duration=1.0, overrides={"simulation.step": 0.25}).step == 0.25
    loaded = load_ssp(folder, step=0.05, duration=1.0)
    assert (loaded.step, loaded.duration, loaded.start_time) == (0.05, 1.0, 0.5)
    # the archive's values win over the fallbacks
    assert load_ssp(archive, step=0.05, duration=1.0).step == 0.1


def test_an_archive_without_the_engines_annotation_records_every_output(archive, tmp_path):
    folder = _edited(archive, tmp_path, lambda root: _drop(root, "ssd:System/ssd:Annotations"))
    loaded = load_ssp(folder)
    assert loaded.record == tuple(f"{c}.{v}" for c in "ABC" for v in ("y", "rate"))
    assert (loaded.seed, loaded.envelope, loaded.block_rows) == (0, {}, 100)


# ---- refusals: export ---------------------------------------------------------------------------

def test_export_refuses_python_components_naming_them(tmp_path):
    raw = tomllib.loads(SCENARIO)
    raw["connections"] = ["source.out -> ctrl.r", "A.y -> ctrl.y", "ctrl.u -> B.u"]
    raw["toy_source"] = {"kind": "toy_constant", "value": 1.0}
    raw["toy_controller"] = {"kp": 1.0}
    raw["record"] = {}
    raw["envelope"] = {}
    out = tmp_path / "x.ssp"
    with pytest.raises(ScenarioError, match=r"^scenario 'toy_chain': an SSP archive holds FMUs only; remove the "
                                            r"Python component\(s\) ctrl, source "):
        export_ssp(parse_scenario(raw), out)
    assert not out.exists()


@pytest.mark.parametrize("edit, error, message", [
    (lambda raw, bad: raw["fmus"]["A"].update(path=str(bad)) or raw["fmus"]["A"].pop("model")
     and raw["fmus"]["A"].pop("fmi_version", None),
     ScenarioError, r"^fmus\.A\.path = '.*not_an_fmu\.fmu': not an FMU: not a zip archive"),
    (lambda raw, bad: raw["fmus"]["A"].update(path=str(toy_models.lag_fmu_path(3)), fmi_version=2)
     or raw["fmus"]["A"].pop("model"),
     ScenarioError, r"^fmus\.A\.fmi_version = 2: the FMU file .*ToyFirstOrderLag\.fmu is FMI 3\.0$"),
    (lambda raw, bad: raw["fmus"]["A"].update(path=str(toy_models.lag_fmu_path(2)), parameters={"nope": 1.0})
     or raw["fmus"]["A"].pop("model"),
     ScenarioError, r"^fmus\.A\.parameters\.nope: the FMU file .* has no parameter 'nope'$"),
    (lambda raw, bad: raw["fmus"]["A"].update(path=str(toy_models.lag_fmu_path(2)), parameters={"tau": 0.0})
     or raw["fmus"]["A"].pop("model"),
     ScenarioError, r"^fmus\.A\.parameters\.tau = 0\.0: outside the range \[0\.001, inf\] the FMU file .* declares$"),
    (lambda raw, bad: raw.update(connections=["A.y -> B.rate"]),
     ConnectionCheckError, r"^connection A\.y -> B\.rate: destination B\.rate is an output, not an input$"),
    (lambda raw, bad: raw.update(record={"signals": ["A.nope"]}),
     ScenarioError, r"^record\.signals: 'A\.nope' is no input or output of an FMU of the scenario \(A, B, C\)$"),
])
def test_export_refuses_what_the_master_would(tmp_path, edit, error, message):
    raw = tomllib.loads(SCENARIO)
    bad = tmp_path / "not_an_fmu.fmu"
    bad.write_text("hello")
    edit(raw, bad)
    out = tmp_path / "x.ssp"
    with pytest.raises(error, match=message):
        export_ssp(parse_scenario(raw), out)
    assert not out.exists() and not list(tmp_path.glob(".x.ssp*"))


# ---- refusals: bad archives ----------------------------------------------------------------------

def _drop(root, path):
    node = root.find(path, NS)
    node.getparent().remove(node)


def _edited(archive: Path, tmp_path: Path, edit) -> Path:
    """The archive extracted to a folder, its SSD changed by ``edit(root)``."""
    folder = tmp_path / f"edited{len(list(tmp_path.glob('edited*')))}"
    with zipfile.ZipFile(archive) as z:
        z.extractall(folder)
    tree = etree.parse(str(folder / SSD_NAME))
    edit(tree.getroot())
    tree.write(str(folder / SSD_NAME), xml_declaration=True, encoding="utf-8")
    return folder


def _component(root, name):
    return root.find(f"ssd:System/ssd:Elements/ssd:Component[@name='{name}']", NS)


def _connection(root, i):
    return root.findall("ssd:System/ssd:Connections/ssd:Connection", NS)[i - 1]


def _add(parent, prefix, tag, **attrib):
    return etree.SubElement(parent, f"{{{NS[prefix]}}}{tag}", **attrib)


def _value(root, component, parameter):
    return _component(root, component).find(f".//ssv:Parameter[@name='{parameter}']", NS)[0]


BAD_SSDS = [
    (lambda r: _connection(r, 2).set("startElement", "Plant"),
     "ssd:Connections/ssd:Connection[2]: startElement 'Plant' is no element of its system; its elements are: A, B, C"),
    (lambda r: _connection(r, 1).set("endConnector", "w"),
     "ssd:Connection[1]: endConnector 'w' is no connector of 'B'"),
    (lambda r: _connection(r, 1).attrib.pop("startElement"),
     "ssd:Connection[1]: startConnector 'y' is no connector of the system"),
    (lambda r: _add(_connection(r, 2), "ssc", "BooleanMappingTransformation"),
     "ssd:Connection[2]/ssc:BooleanMappingTransformation: not supported (of the transformations, one "
     "ssc:LinearTransformation is)"),
    (lambda r: _add(_connection(r, 2), "ssc", "LinearTransformation", factor="x"),
     "ssd:Connection[2]/ssc:LinearTransformation: factor = 'x' is not a number"),
    (lambda r: _component(r, "B").set("source", "resources/Missing.fmu"),
     "ssd:Component[@name='B']: source 'resources/Missing.fmu': no such file in the archive"),
    (lambda r: _component(r, "B").set("source", "https://example.org/B.fmu"),
     "ssd:Component[@name='B']: source 'https://example.org/B.fmu': only files inside the archive"),
    (lambda r: _component(r, "B").set("source", "../../B.fmu"),
     "ssd:Component[@name='B']: source '../../B.fmu': leaves the archive; only files inside it are supported"),
    (lambda r: _component(r, "B").set("source", "resources/../../x/B.fmu"),
     "ssd:Component[@name='B']: source 'resources/../../x/B.fmu': leaves the archive"),
    (lambda r: _component(r, "B").set("source", "file:///tmp/B.fmu"),
     "ssd:Component[@name='B']: source 'file:///tmp/B.fmu': only files inside the archive (relative URIs) are "
     "supported"),
    (lambda r: _component(r, "B").set("source", "/tmp/B.fmu"),
     "ssd:Component[@name='B']: source '/tmp/B.fmu': only files inside the archive (relative URIs) are supported"),
    (lambda r: _component(r, "C").find(".//ssd:ParameterBinding", NS).set("source", "../C.ssv"),
     "ssd:Component[@name='C']/ssd:ParameterBindings/ssd:ParameterBinding[1]: source '../C.ssv': leaves the archive"),
    (lambda r: _component(r, "B").set("type", "application/x-ssp-definition"),
     "ssd:Component[@name='B']: type 'application/x-ssp-definition' is not supported (application/x-fmu-sharedlibrary "
     "only)"),
    (lambda r: _component(r, "B").set("name", "A"),
     "ssd:Component[@name='A']: an element of that name is already given"),
    (lambda r: _add(r.find("ssd:System/ssd:Elements", NS), "ssd", "SignalDictionaryReference", name="Bus"),
     "ssd:System[@name='toy_chain']/ssd:Elements/ssd:SignalDictionaryReference[@name='Bus']: dictionary None: no "
     "ssd:SignalDictionary of that name in its system or an enclosing one"),
    (lambda r: [_component(r, n).getparent().remove(_component(r, n)) for n in "ABC"] and
     _drop(r, "ssd:System/ssd:Connections"),
     "ssd:System[@name='toy_chain']: no ssd:Component (an FMU) in its ssd:Elements or below"),
    (lambda r: _value(r, "A", "y_0").set("value", "abc"),
     "ssd:Component[@name='A']/ssd:ParameterBindings/ssd:ParameterBinding[1]/ssd:ParameterValues: "
     "ssv:Parameter 'y_0': value = 'abc' is not a number"),
    (lambda r: _value(r, "A", "y_0").set("value", "inf"),
     "ssv:Parameter 'y_0': value = 'inf' is not a finite number"),
    (lambda r: setattr(_value(r, "A", "u"), "tag", f"{{{NS['ssv']}}}String"),
     "ssd:ParameterBinding[1]/ssd:ParameterValues: ssv:Parameter 'u': String: only Real, Integer and Boolean "
     "values are supported"),
    (lambda r: _component(r, "C").find(".//ssd:ParameterBinding", NS).set("source", "resources/C.ssv"),
     "ssd:Component[@name='C']/ssd:ParameterBindings/ssd:ParameterBinding[1]: source 'resources/C.ssv': no such "
     "file in the archive"),
    (lambda r: _add(_component(r, "C").find(".//ssd:ParameterBinding", NS), "ssd", "ParameterMapping"),
     "ssd:Component[@name='C']/ssd:ParameterBindings/ssd:ParameterBinding[1]/ssd:ParameterMapping: neither a "
     "source nor an inline ssm:ParameterMapping"),
    (lambda r: r.find("ssd:DefaultExperiment", NS).set("stopTime", "soon"),
     "/ssd:SystemStructureDescription/ssd:DefaultExperiment: stopTime = 'soon' is not a number"),
    (lambda r: r.find(f".//{{{OSP_NAMESPACE}}}FixedStepAlgorithm").set("baseStepSize", "0"),
     "/ssd:SystemStructureDescription/ssd:DefaultExperiment: osp:FixedStepAlgorithm: baseStepSize = '0' is not "
     "positive"),
    (lambda r: r.find("ssd:DefaultExperiment", NS).set("stopTime", "2.55"),
     "simulation.duration = 2.05: not a whole number of steps of 0.1 s"),
    (lambda r: _drop(r, "ssd:System"), "no ssd:System"),
]


def test_a_value_in_another_unit_is_converted_into_its_variables(archive, tmp_path):
    """A parameter set's ``ssv:Real unit`` is converted into the unit the FMU's variable declares (SSP 1.0
    SystemStructureParameterValues), unless a mapping entry suppresses it; not one quantity: one line."""
    def edit(root):
        for component, name, value, unit in (("A", "y_0", "1500.0", "mm"), ("B", "tau", "250", "ms"),
                                             ("C", "y_0", "-1000.0", "mm")):
            _value(root, component, name).attrib.update({"value": value, "unit": unit})
        mapping = _add(_component(root, "C").find(".//ssd:ParameterBinding", NS), "ssd", "ParameterMapping")
        entry = etree.SubElement(etree.SubElement(mapping, f"{{{NS['ssm']}}}ParameterMapping", version="1.0"),
                                 f"{{{NS['ssm']}}}MappingEntry", source="y_0", target="y_0",
                                 suppressUnitConversion="true")
        _add(entry, "ssc", "LinearTransformation", factor="0.001")
    folder = _edited(archive, tmp_path, edit)
    assert ssd_schema_errors(folder / SSD_NAME) == []
    loaded = load_ssp(folder)
    assert loaded.fmus["A"]["parameters"]["y_0"] == pytest.approx(1.5, rel=1e-15)
    assert loaded.fmus["B"]["parameters"]["tau"] == pytest.approx(0.25, rel=1e-15)
    assert loaded.fmus["C"]["parameters"]["y_0"] == -1000.0 * 0.001  # suppressed: the transformation alone
    folder = _edited(archive, tmp_path, lambda root: _value(root, "A", "y_0").set("unit", "s"))
    with pytest.raises(ScenarioError, match=re.escape(
            "ssd:Component[@name='A']/ssd:ParameterBindings/ssd:ParameterBinding[1]/ssd:ParameterValues: parameter "
            "'y_0': units s and m are not one quantity")):
        load_ssp(folder)


@pytest.mark.parametrize("edit, message", BAD_SSDS, ids=[m.split(":")[0][:40] for _, m in BAD_SSDS])
def test_a_bad_ssd_is_refused_naming_the_element(archive, tmp_path, edit, message):
    folder = _edited(archive, tmp_path, edit)
    with pytest.raises(ScenarioError) as info:
        load_ssp(folder)
    text = str(info.value)
    assert text.startswith(f"{folder}: {SSD_NAME}: ")
    assert message in text
    assert "\n" not in text


def _section(name: str, value) -> callable:
    """An edit adding ``<cosim:Section name=...>`` (JSON) to the engine's annotation."""
    def edit(root):
        scenario = root.find(f"ssd:System/ssd:Annotations/ssc:Annotation[@type='{COSIM_ANNOTATION}']", NS)[0]
        etree.SubElement(scenario, f"{{{COSIM_NAMESPACE}}}Section", name=name).text = json.dumps(value)
    return edit


@pytest.mark.parametrize("name, value", [
    ("components", {"evil": {"factory": "os:makedirs"}}),  # would call os.makedirs(name="evil")
    ("toy_source", {"kind": "toy_constant", "value": 1.0}),  # a registered kind's short section
    ("connections", ["A.y -> B.u"]),  # a generic key
    ("fmus", {"D": {"path": "/etc/passwd"}}),
])
def test_an_archive_runs_no_code_of_its_own_choosing(archive, tmp_path, monkeypatch, name, value):
    """An archive is data (docs/security.md): its annotation may carry an
    application's registered sections only, never a component (a factory
    would run any callable) nor a generic key; refused before anything runs."""
    folder = _edited(archive, tmp_path, _section(name, value))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ScenarioError) as info:
        build_master(load_ssp(folder))
    assert re.search(rf"Section {name!r}: not a section an archive may carry; known: .*toy_lag", str(info.value))
    assert not (tmp_path / "evil").exists()


def test_an_archive_carries_a_registered_section(archive, tmp_path):
    folder = _edited(archive, tmp_path, _section("toy_lag", {"fmu": "B", "time_constant": 0.5}))
    assert load_ssp(folder).fmus["B"]["parameters"]["tau"] == 0.5


def test_bad_files_are_refused(archive, tmp_path):
    not_zip = tmp_path / "x.ssp"
    not_zip.write_text("hello")
    with pytest.raises(ScenarioError, match=r"x\.ssp: not an SSP archive: not a zip archive \(File is not a zip"):
        load_ssp(not_zip)
    no_ssd = tmp_path / "y.ssp"
    with zipfile.ZipFile(no_ssd, "w") as z:
        z.writestr("resources/A.fmu", b"")
    with pytest.raises(ScenarioError, match=r"y\.ssp: not an SSP archive: it holds no SystemStructure\.ssd$"):
        load_ssp(no_ssd)
    with pytest.raises(ScenarioError, match=r"holds no SystemStructure\.ssd$"):
        load_ssp(tmp_path)
    with pytest.raises(ScenarioError, match=r"nothing\.ssp: no such file$"):
        load_ssp(tmp_path / "nothing.ssp")
    folder = _edited(archive, tmp_path, lambda root: None)
    (folder / SSD_NAME).write_text("<ssd:SystemStructureDescription")
    with pytest.raises(ScenarioError, match=r"SystemStructure\.ssd: not well-formed XML: .*line 1"):
        load_ssp(folder)
    (folder / SSD_NAME).write_text("<SystemStructureDescription/>")
    with pytest.raises(ScenarioError, match="the root element is SystemStructureDescription, not "
                                            "ssd:SystemStructureDescription"):
        load_ssp(folder)


def test_an_external_parameter_set_is_read(archive, tmp_path):
    """``ssd:ParameterBinding source="...ssv"`` (relative to the SSD) works like the inline one."""
    folder = _edited(archive, tmp_path, lambda root: None)
    tree = etree.parse(str(folder / SSD_NAME))
    binding = _component(tree.getroot(), "C").find(".//ssd:ParameterBinding", NS)
    values = binding.find("ssd:ParameterValues", NS)
    etree.ElementTree(values[0]).write(str(folder / "resources" / "C.ssv"))
    binding.remove(values)
    binding.set("source", "resources/C.ssv")
    tree.write(str(folder / SSD_NAME))
    assert load_ssp(folder).fmus["C"]["parameters"] == {"k": 0.5, "y_0": -1.0}


# ---- the engine stays generic ---------------------------------------------------------------------

def test_cosim_ssp_imports_nothing_of_the_application_nor_pyssp():
    """pyssp-standard (and its pint, xmlschema) is imported by the export only."""
    code = ("import cosim.ssp.archive, cosim.ssp.export, sys; print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'quadrotor_paper', 'fnn_controller', 'fmu_models', 'pyssp_standard', 'libcosimpy', 'pint'}))")
    root = Path(cosim.__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


# ---- libcosim: how its fixed-step algorithm orders a step ------------------------------------------

PROBE = FmuModel(
    identifier="ToySspProbe",
    description="Probe for co-simulation ordering: clock c (dc/dt = 1), integral s of the input (ds/dt = u), "
                "echo = u (direct feedthrough)",
    variables=(
        state("c", "1", "clock: c(t) = c_0 + t - t0"),
        state("s", "1", "integral of the input"),
        input_("u", "1", "input", start=-7.0),
        output("echo", "1", "the input as it is when read (direct feedthrough)"),
        parameter("c_0", "1", "clock at t0", 0.0),
        parameter("s_0", "1", "integral at t0", 0.0),
    ),
    equations=lambda t, v: ({"c": 1.0 + 0.0 * v["c"], "s": v["u"]}, {"echo": v["u"]}),
    initial_state=lambda v: {"c": v["c_0"], "s": v["s_0"]},
)
H = 0.1


@pytest.fixture(scope="module")
def probe_fmu():
    return cached_fmu(PROBE, 2)


def probe_archive(probe_fmu, tmp_path, fmus, connections, signals, duration=1.0, seed=0):
    raw = {"name": "probes", "connections": connections,
           "simulation": {"duration": duration, "step": H, "seed": seed},
           "fmus": {name: {"path": str(probe_fmu), **spec} for name, spec in fmus.items()},
           "record": {"signals": signals}}
    return export_ssp(parse_scenario(raw), tmp_path / "probes.ssp")


def both(path, signals, ordering="exchange"):
    """The archive run by libcosim and by our master in ``ordering``."""
    from libcosim_runner import run_libcosim

    loaded = load_ssp(path, overrides={"simulation.ordering": ordering})
    with build_master(loaded) as master:
        ours = master.run(loaded.duration, seed=loaded.seed)
    return run_libcosim(path, signals), ours


def needs_libcosim():
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed: libcosim cannot be run")


CHAIN = ["A.c -> B.u", "B.echo -> C.u"]
CHAIN_SIGNALS = ["A.c", "A.echo", "B.u", "B.s", "B.echo", "C.u", "C.s", "C.echo"]
CHAIN_FMUS = {"A": {"parameters": {"c_0": 100.0}}, "B": {}, "C": {}}


@pytest.fixture
def chain_archive(probe_fmu, tmp_path):
    needs_libcosim()
    return probe_archive(probe_fmu, tmp_path, CHAIN_FMUS, CHAIN, CHAIN_SIGNALS)


@pytest.fixture
def chain(chain_archive):
    return both(chain_archive, CHAIN_SIGNALS)


def test_libcosim_transfers_connected_values_at_initialization(chain):
    """Before the first step libcosim runs (number of simulators) rounds of
    set inputs / get outputs in initialization mode, transferring between
    them: B.u gets A.c(t0) = 100, and B's direct-feedthrough echo reaches C
    (two hops) before the first doStep."""
    lc, _ = chain
    assert lc["B.u"][0] == lc["B.echo"][0] == 100.0
    assert lc["C.u"][0] == lc["C.echo"][0] == 100.0
    assert lc["C.s"][1] == pytest.approx(H * 100.0, abs=1e-12)  # C integrated 100 over the first step
    # an input nothing feeds keeps its start value (no binding in the archive: the FMU's own, -7)
    assert np.all(lc["A.echo"] == -7.0)


def test_libcosim_is_jacobi_and_reads_outputs_right_after_do_step(chain):
    """Each step: every FMU gets the values transferred after the previous
    step (the outputs at t_n), steps to t_{n+1}, and its outputs are read at
    once, before anything new is set: a direct-feedthrough output read at
    t_{n+1} still shows the input of the step just taken."""
    lc, _ = chain
    a_c = lc["A.c"]
    assert np.allclose(np.diff(lc["B.s"]), H * a_c[:-1], atol=1e-12)  # u over [t_n, t_n+1] = A.c(t_n)
    assert np.array_equal(lc["B.echo"][1:], a_c[:-1])  # echo at t_n+1 = A.c(t_n)
    # one more step of delay per direct-feedthrough hop: C integrates B.echo(t_n) = A.c(t_n-1)
    assert np.allclose(np.diff(lc["C.s"])[1:], H * a_c[:-2], atol=1e-12)


def test_the_exchange_ordering_is_libcosims(chain):
    """Our master's 'exchange' ordering is libcosim's fixed-step algorithm:
    connected values transferred before the first step (once per FMU, so two
    direct-feedthrough hops are consistent at t0), then Jacobi among FMUs with
    outputs read right after doStep (docs/ssp.md)."""
    lc, ours = chain
    assert ours["B.echo"][0] == lc["B.echo"][0] == 100.0  # transferred at initialization
    assert ours["C.s"][1] == pytest.approx(H * 100.0) and lc["C.s"][1] == pytest.approx(H * 100.0)
    for name in ("A.c", "B.s", "B.echo", "C.s", "C.echo"):
        assert np.allclose(ours[name], lc[name], rtol=0, atol=1e-12), name


def test_the_feedthrough_ordering_has_no_delay_per_hop(chain_archive):
    """Our master's default 'feedthrough' ordering evaluates an FMU whose used
    output depends directly on a connected input at t_n (inputs set, outputs
    read, no step): B.echo(t_n) = A.c(t_n), and C integrates A.c(t_n), where
    libcosim's C integrates A.c(t_n-1). At t0 it agrees with libcosim's
    initialization."""
    lc, ours = both(chain_archive, CHAIN_SIGNALS, ordering="feedthrough")
    a_c = ours["A.c"]
    assert np.array_equal(ours["B.echo"], a_c) and np.array_equal(ours["C.echo"], a_c)
    assert np.allclose(np.diff(ours["C.s"]), H * a_c[:-1], atol=1e-12)
    assert ours["B.echo"][0] == lc["B.echo"][0] and ours["C.s"][1] == pytest.approx(lc["C.s"][1])
    assert np.allclose(ours["B.s"], lc["B.s"], rtol=0, atol=1e-12)  # one hop from a state: no difference
    assert not np.allclose(ours["C.s"], lc["C.s"], rtol=0, atol=1e-3)


def test_a_loop_through_a_direct_feedthrough_fmu(probe_fmu, tmp_path):
    """Plant P (s integrates u) and an FMU 'controller' K (echo = u) in a loop,
    P.s -> K.u, K.echo -> P.u, s(0) = 1, h = 0.1. In libcosim and in our
    'exchange' ordering, P receives K's output read after K's previous step,
    i.e. K's answer to P.s(t_{n-1}): s_{n+1} = s_n + h s_{n-1}, K having
    answered P.s(t0) at initialization. Our 'feedthrough' ordering evaluates K
    at t_n, as a Python K would be: s_{n+1} = (1 + h) s_n. A Python K in the
    exchange ordering is sampled at t_n and held from t_{n+1}: the FMU's delay."""
    needs_libcosim()
    signals = ["P.s", "P.u", "K.echo"]
    path = probe_archive(probe_fmu, tmp_path, {"P": {"parameters": {"s_0": 1.0}}, "K": {}},
                         ["P.s -> K.u", "K.echo -> P.u"], signals, duration=0.5)
    lc, exchange = both(path, signals, ordering="exchange")
    _, feedthrough = both(path, signals, ordering="feedthrough")
    for s in (lc["P.s"], exchange["P.s"]):
        assert s[1] == pytest.approx(1.0 + H * 1.0, abs=1e-12)
        assert np.allclose(s[2:], s[1:-1] + H * s[:-2], atol=1e-12)
    assert lc["P.s"][:4] == pytest.approx([1.0, 1.1, 1.2, 1.31])
    assert np.allclose(exchange["P.s"], lc["P.s"], rtol=0, atol=1e-12)
    assert feedthrough["P.s"] == pytest.approx(1.1 ** np.arange(6), abs=1e-12)
    # the same 'controller' as a Python component of our master, in either ordering
    for ordering, expected in (("feedthrough", feedthrough), ("exchange", exchange)):
        master = Master([FmuComponent("P", probe_fmu)], [toy_models.Gain("K")], ["P.s -> K.u", "K.y -> P.u"], H,
                        ["P.s"], fmu_parameters={"P": {"s_0": 1.0}}, ordering=ordering)
        with master:
            python = master.run(0.5)
        assert np.allclose(python["P.s"], expected["P.s"], rtol=0, atol=1e-12), ordering


def test_a_seed_parameter_travels_in_the_parameter_set(probe_fmu, tmp_path):
    """An FMU's seed parameter: the archive binds it to the scenario's seed
    (so libcosim starts the same way), the loaded scenario names it again and
    drops the fixed value (our master sets the run's seed)."""
    path = probe_archive(probe_fmu, tmp_path, {"A": {"seed_parameter": "c_0"}}, [], ["A.c"], seed=42)
    values = {p.get("name"): p[0].get("value") for p in ssd_of(path).iterfind(".//ssv:Parameter", NS)}
    assert values == {"c_0": "42.0"}
    loaded = load_ssp(path)
    assert loaded.fmus["A"]["seed_parameter"] == "c_0" and loaded.fmus["A"]["parameters"] == {}
    assert loaded.seed == 42
    with build_master(loaded) as master:
        assert master.run(loaded.duration, seed=loaded.seed)["A.c"][0] == 42.0
        assert master.run(loaded.duration, seed=5)["A.c"][0] == 5.0
    if importlib.util.find_spec("libcosimpy") is not None:
        from libcosim_runner import run_libcosim

        assert run_libcosim(path, ["A.c"])["A.c"][0] == 42.0
    with pytest.raises(ScenarioError, match=r"^fmus\.A\.seed_parameter = 'u': no parameter of the FMU file "):
        probe_archive(probe_fmu, tmp_path, {"A": {"seed_parameter": "u"}}, [], ["A.c"])


def test_libcosim_runs_the_exported_toy_chain_as_our_master(archive):
    """The lag chain in the 'exchange' ordering: every state and every
    direct-feedthrough output (rate) agrees, t0 included (both transfer A.y to
    B.u at initialization). A recorded input differs by one row: our
    master records the value its source gives it at t_n (what the FMU gets
    for [t_n, t_n+1]); libcosim reads the FMU's input after the step, i.e.
    what it held over [t_n-1, t_n]."""
    needs_libcosim()
    from libcosim_runner import run_libcosim

    loaded = load_ssp(archive)
    assert loaded.ordering == "exchange"
    with build_master(loaded) as master:
        ours = master.run(loaded.duration, t0=loaded.start_time)
    lc = run_libcosim(archive, loaded.record)
    assert lc.columns == ours.columns and np.array_equal(lc.time, ours.time)
    for name in ("A.y", "B.y", "C.y"):
        assert np.allclose(lc[name], ours[name], rtol=0, atol=1e-12), name
    assert np.array_equal(ours["C.u"], ours["B.y"])
    assert lc["C.u"][0] == ours["C.u"][0] and np.allclose(lc["C.u"][1:], ours["C.u"][:-1], rtol=0, atol=1e-12)
    for name in ("B.rate", "C.rate"):
        assert np.allclose(lc[name], ours[name], rtol=0, atol=1e-12), name
    assert ours["B.rate"][0] == pytest.approx((2.0 * 1.5 - 0.0) / 0.25)  # B.u = A.y(t0) = 1.5: transferred at t0
