"""SSP archives as other SSP editors write them (issue 41): nested systems,
Model Exchange components, no step in the default experiment, a ``.ssv``
parameter set renamed by a ``.ssm`` mapping, a binding on a sub-system with a
prefix, a transformation on one connection, an annotation this reader does
not know. The archive is written here as an editor writes it (SSP 1.0
schema-valid text), with the Reference FMUs, and must fly exactly as the
equivalent flat TOML scenario.
"""
from __future__ import annotations

import logging
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cosim.scenario.assembly import build_master
from cosim.loop.connection import parse_connections
from cosim.errors import ScenarioError
from cosim.scenario.definition import load_scenario
from cosim.ssp.archive import load_ssp, ssd_schema_errors

REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"
pytestmark = pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {REFERENCE}")

def _binding(name: str, parameter: str, value: float, attributes: str = "") -> str:
    """An ``ssd:ParameterBindings`` of one inline parameter set holding one Real."""
    return (f'<ssd:ParameterBindings><ssd:ParameterBinding{attributes}><ssd:ParameterValues>'
            f'<ssv:ParameterSet version="1.0" name="{name}"><ssv:Parameters><ssv:Parameter name="{parameter}">'
            f'<ssv:Real value="{value}"/></ssv:Parameter></ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues>'
            f'</ssd:ParameterBinding></ssd:ParameterBindings>')


SSD = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
    version="1.0" name="bench" generationTool="SomeEditor 4.2">
  <ssd:System name="Root">
    <ssd:Connectors>
      <ssd:Connector name="monitor" kind="output"><ssc:Real/></ssd:Connector>
    </ssd:Connectors>
    <ssd:Elements>
      <ssd:Component name="Source" type="application/x-fmu-sharedlibrary" source="resources/Dahlquist.fmu"
          implementation="ModelExchange">
        <ssd:Connectors>
          <ssd:Connector name="x" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="resources/source.ssv">
            <ssd:ParameterMapping source="resources/source.ssm"/>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
        <ssd:Annotations>
          <ssc:Annotation type="com.someeditor.layout"><Layout xmlns="urn:someeditor" x="10" y="20"/></ssc:Annotation>
        </ssd:Annotations>
      </ssd:Component>
      <ssd:System name="SuT">
        <ssd:Connectors>
          <ssd:Connector name="x_in" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="y_out" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        {_binding("oscillator", "mu", 0.5, ' prefix="osc."')}
        <ssd:Elements>
          <ssd:Component name="edrive_mass" type="application/x-fmu-sharedlibrary"
              source="resources/Feedthrough.fmu" implementation="CoSimulation">
            <ssd:Connectors>
              <ssd:Connector name="Float64_continuous_input" kind="input"><ssc:Real/></ssd:Connector>
              <ssd:Connector name="Float64_continuous_output" kind="output"><ssc:Real/></ssd:Connector>
            </ssd:Connectors>
          </ssd:Component>
          <ssd:Component name="osc" source="resources/VanDerPol.fmu" implementation="any">
            <ssd:Connectors>
              <ssd:Connector name="x0" kind="output"><ssc:Real/></ssd:Connector>
            </ssd:Connectors>
            {_binding("stiff", "mu", 3.0)}
          </ssd:Component>
        </ssd:Elements>
        <ssd:Connections>
          <ssd:Connection startConnector="x_in" endElement="edrive_mass" endConnector="Float64_continuous_input"/>
          <ssd:Connection startElement="edrive_mass" startConnector="Float64_continuous_output"
              endConnector="y_out"/>
        </ssd:Connections>
      </ssd:System>
      <ssd:Component name="Sink" source="resources/Feedthrough.fmu">
        <ssd:Connectors>
          <ssd:Connector name="Float64_continuous_input" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="Float64_continuous_output" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="Source" startConnector="x" endElement="SuT" endConnector="x_in">
        <ssc:LinearTransformation factor="2.0" offset="0.5"/>
      </ssd:Connection>
      <ssd:Connection startElement="SuT" startConnector="y_out" endElement="Sink"
          endConnector="Float64_continuous_input"/>
      <ssd:Connection startElement="SuT" startConnector="y_out" endConnector="monitor"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.0" stopTime="1.0"/>
</ssd:SystemStructureDescription>
"""

SSV = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0"
    name="source">
  <ssv:Parameters>
    <ssv:Parameter name="decay"><ssv:Real value="4.0"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>
"""

SSM = """<?xml version="1.0" encoding="UTF-8"?>
<ssm:ParameterMapping xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0">
  <ssm:MappingEntry source="decay" target="k">
    <ssc:LinearTransformation factor="0.5"/>
  </ssm:MappingEntry>
</ssm:ParameterMapping>
"""

# The same system written flat, by hand: what the archive must fly as (k = 0.5 * 4.0 through the mapping,
# the transformation 2 x + 0.5 through SuT's connector, SuT's binding "osc." + "mu").
FLAT = """
name = "bench"
connections = [
  {{ connect = "Source.x -> SuT.edrive_mass.Float64_continuous_input", factor = 2.0, offset = 0.5 }},
  "SuT.edrive_mass.Float64_continuous_output -> Sink.Float64_continuous_input",
]
[simulation]
duration = 1.0
step = 0.01
[fmus.Source]
path = "{ref}/Dahlquist.fmu"
interface = "ModelExchange"
parameters = {{ k = 2.0 }}
[fmus."SuT.edrive_mass"]
path = "{ref}/Feedthrough.fmu"
interface = "CoSimulation"
[fmus."SuT.osc"]
path = "{ref}/VanDerPol.fmu"
parameters = {{ mu = 0.5 }}
[fmus.Sink]
path = "{ref}/Feedthrough.fmu"
[record]
signals = ["Source.x", "SuT.edrive_mass.Float64_continuous_output", "SuT.osc.x0", "Sink.Float64_continuous_output"]
"""


def _archive(path: Path, ssd: str = SSD, extra: dict[str, str] | None = None) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, text in {"SystemStructure.ssd": ssd, "resources/source.ssv": SSV, "resources/source.ssm": SSM,
                           **(extra or {})}.items():
            z.writestr(name, text)
        for name in ("Dahlquist", "Feedthrough", "VanDerPol"):
            z.write(REFERENCE / "fmi2" / f"{name}.fmu", f"resources/{name}.fmu")
    return path


@pytest.fixture(scope="module")
def foreign(tmp_path_factory) -> Path:
    return _archive(tmp_path_factory.mktemp("foreign") / "bench.ssp")


def test_the_editors_archive_is_valid_ssp_1_0():
    for text in (SSD, SSV, SSM):
        assert ssd_schema_errors(text.encode()) == []


def test_the_nested_archive_is_flattened(foreign, caplog):
    with caplog.at_level(logging.INFO, logger="cosim.ssp.archive"):
        scenario = load_ssp(foreign)
    fmus = scenario.fmus
    assert list(fmus) == ["Source", "SuT.edrive_mass", "SuT.osc", "Sink"]
    assert fmus["Source"]["interface"] == "ModelExchange" and fmus["SuT.edrive_mass"]["interface"] == "CoSimulation"
    assert "interface" not in fmus["SuT.osc"] and "interface" not in fmus["Sink"]  # "any", absent: the master's
    assert fmus["Source"]["parameters"] == {"k": 2.0}  # decay = 4.0 through the .ssm, factor 0.5
    # the sub-system's binding (prefix "osc.") wins over the component's own mu = 3.0: the higher level
    assert fmus["SuT.osc"]["parameters"] == {"mu": 0.5}
    connections = {str(c): c for c in parse_connections(scenario.connections)}
    assert sorted(connections) == ["Source.x -> SuT.edrive_mass.Float64_continuous_input",
                                   "SuT.edrive_mass.Float64_continuous_output -> Sink.Float64_continuous_input"]
    assert connections["Source.x -> SuT.edrive_mass.Float64_continuous_input"].conversion == (2.0, 0.5)
    # no step in the archive: the smallest DefaultExperiment stepSize of its FMUs (VanDerPol's 1e-2)
    assert scenario.step == 0.01 and scenario.duration == 1.0
    notes = [r.getMessage() for r in caplog.records if r.levelno == logging.INFO]
    assert any("communication step 0.01 s, from the smallest FMU DefaultExperiment stepSize (SuT.osc: 0.01 s)"
               in n for n in notes), notes
    assert any("ssc:Annotation[1]: type 'com.someeditor.layout' is an annotation this reader does not know" in n
               and "ssd:Component[@name='Source']" in n for n in notes), notes
    assert any("connector 'monitor' of the root system, connected to nothing further: ignored" in n
               for n in notes), notes


def test_the_nested_archive_flies_as_the_flat_scenario(foreign, tmp_path):
    flat_file = tmp_path / "flat.toml"
    flat_file.write_text(FLAT.format(ref=REFERENCE / "fmi2"))
    flat = load_scenario(flat_file)
    nested = load_ssp(foreign, overrides={"record.signals": list(flat.record)})
    results = []
    for scenario in (nested, flat):
        with build_master(scenario) as master:
            results.append(master.run(scenario.duration, seed=0, t0=scenario.start_time))
    archive, by_hand = results
    assert len(archive.time) == 101
    for signal in flat.record:
        np.testing.assert_array_equal(archive[signal], by_hand[signal], err_msg=signal)
    # what went through: the Dahlquist state x = exp(-k t) with k = 2 (the mapping's), and through SuT
    # (direct feedthrough, evaluated within the step in the default ordering) 2 x + 0.5 at Sink
    x = archive["Source.x"]
    assert x[0] == 1.0 and abs(x[-1] - np.exp(-2.0)) < 1e-5
    np.testing.assert_array_equal(archive["Sink.Float64_continuous_output"], 2.0 * x + 0.5)


SUT = "/ssd:SystemStructureDescription/ssd:System[@name='Root']/ssd:Elements/ssd:System[@name='SuT']"
SOURCE_BINDING = ("/ssd:SystemStructureDescription/ssd:System[@name='Root']/ssd:Elements/ssd:Component[@name='Source']"
                  "/ssd:ParameterBindings/ssd:ParameterBinding[1]")
REFUSED = [
    # what is still refused: each one line naming the element by its path
    (lambda s: s.replace("        <ssd:Elements>\n          <ssd:Component name=\"edrive_mass\"",
                         "        <ssd:Elements>\n          <ssd:SignalDictionaryReference name=\"bus\" "
                         "dictionary=\"d\"/>"
                         "\n          <ssd:Component name=\"edrive_mass\"", 1), {},
     f"{SUT}/ssd:Elements/ssd:SignalDictionaryReference[@name='bus']: dictionary 'd': no ssd:SignalDictionary of that "
     f"name in its system or an enclosing one"),
    (lambda s: s, {"resources/source.ssm": SSM.replace('<ssc:LinearTransformation factor="0.5"/>',
                                                      '<ssc:BooleanMappingTransformation/>')},
     f"{SOURCE_BINDING}/ssd:ParameterMapping (resources/source.ssm)/ssm:MappingEntry[1]/"
     f"ssc:BooleanMappingTransformation: not supported"),
    (lambda s: s.replace('prefix="osc."', 'prefix="oscillator."'), {},
     f"{SUT}: parameter 'oscillator.mu': names no element of the system (expected Element.variable; elements below "
     f"it: edrive_mass, osc)"),
    (lambda s: s.replace('implementation="ModelExchange"', 'implementation="ScheduledExecution"'), {},
     "ssd:Component[@name='Source']: implementation 'ScheduledExecution': expected any, CoSimulation or "
     "ModelExchange"),
    (lambda s: s.replace('<ssd:ParameterMapping source="resources/source.ssm"/>',
                         '<ssd:ParameterMapping source="../../source.ssm"/>'), {},
     f"{SOURCE_BINDING}/ssd:ParameterMapping: source '../../source.ssm': leaves the archive"),
    (lambda s: s.replace('endConnector="Float64_continuous_input"/>\n          <ssd:Connection',
                         'endConnector="Float64_continuous_input"/>\n          <ssd:Connection startConnector="y_out" '
                         'endConnector="x_in"/>\n          <ssd:Connection startConnector="x_in" '
                         'endConnector="y_out"/>\n          <ssd:Connection', 1), {},
     "a loop of connections through the systems' connectors"),
]


@pytest.mark.parametrize("edit, extra, message", REFUSED, ids=[m.split(": ")[-1][:30] for *_, m in REFUSED])
def test_what_is_refused_is_one_line_naming_the_element(tmp_path, edit, extra, message):
    path = _archive(tmp_path / "bad.ssp", edit(SSD), extra)
    with pytest.raises(ScenarioError) as info:
        load_ssp(path)
    text = str(info.value)
    assert text.startswith(f"{path}: SystemStructure.ssd: /ssd:SystemStructureDescription/") and "\n" not in text
    assert message in text, text


def test_the_command_line_refuses_a_reference_to_no_dictionary_with_exit_2(tmp_path, capsys):
    from quadrotor_paper.cli import EXIT_BAD_INPUT, main

    ssd = SSD.replace('    <ssd:Elements>\n', '    <ssd:Elements>\n      <ssd:SignalDictionaryReference name="bus" '
                      'dictionary="nobus"/>\n', 1)
    assert ssd_schema_errors(ssd.encode()) == []  # the schema does not know which dictionaries there are
    path = _archive(tmp_path / "dictionary.ssp", ssd)
    code = main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet", "--no-plots",
                 "--set", "simulation.step=0.001"])
    err = capsys.readouterr().err.strip()
    assert code == EXIT_BAD_INPUT and len(err.splitlines()) == 1, err
    assert err.endswith("/ssd:SystemStructureDescription/ssd:System[@name='Root']/ssd:Elements/"
                        "ssd:SignalDictionaryReference[@name='bus']: dictionary 'nobus': no ssd:SignalDictionary of "
                        "that name in its system or an enclosing one"), err
    assert not (tmp_path / "out").exists()


def _reference(name: str, kind: str) -> str:
    return (f'<ssd:SignalDictionaryReference name="{name}" dictionary="bus"><ssd:Connectors><ssd:Connector name="x" '
            f'kind="{kind}"><ssc:Real/></ssd:Connector></ssd:Connectors></ssd:SignalDictionaryReference>')


def test_a_signal_dictionary_carries_a_signal_between_systems(foreign, tmp_path):
    """Source.x into the root's dictionary entry ``x`` (through the transformation), read from it inside SuT:
    the same direct connection as through SuT's connector."""
    ssd = (SSD.replace('      <ssd:Component name="Sink"', f'      {_reference("busref", "input")}\n'
                       f'      <ssd:Component name="Sink"', 1)
           .replace('        <ssd:Elements>\n', f'        <ssd:Elements>\n          {_reference("busin", "output")}\n', 1)
           .replace('endElement="SuT" endConnector="x_in"', 'endElement="busref" endConnector="x"', 1)
           .replace('<ssd:Connection startConnector="x_in" endElement="edrive_mass"',
                    '<ssd:Connection startElement="busin" startConnector="x" endElement="edrive_mass"', 1)
           .replace('  </ssd:System>\n  <ssd:DefaultExperiment',
                    '    <ssd:SignalDictionaries><ssd:SignalDictionary name="bus"><ssb:SignalDictionary '
                    'xmlns:ssb="http://ssp-standard.org/SSP1/SystemStructureSignalDictionary" version="1.0">'
                    '<ssb:DictionaryEntry name="x"><ssc:Real/></ssb:DictionaryEntry></ssb:SignalDictionary>'
                    '</ssd:SignalDictionary></ssd:SignalDictionaries>\n  </ssd:System>\n  <ssd:DefaultExperiment', 1))
    assert ssd.count('dictionary="bus"') == 2 and 'startElement="busin"' in ssd and 'endElement="busref"' in ssd
    assert ssd_schema_errors(ssd.encode()) == []
    bused = load_ssp(_archive(tmp_path / "bus.ssp", ssd))
    assert ({str(c): c.conversion for c in parse_connections(bused.connections)}
            == {str(c): c.conversion for c in parse_connections(load_ssp(foreign).connections)})


def test_the_command_line_flies_it_at_the_users_step(foreign, tmp_path, capsys):
    """``fnn-cosim run bench.ssp --set simulation.step=...``: the user's step is taken before any other."""
    from quadrotor_paper.cli import main

    code = main(["run", str(foreign), "--out", str(tmp_path / "out"), "--quiet", "--no-plots",
                 "--set", "simulation.step=0.02"])
    assert code == 0, capsys.readouterr().err
    rows = np.loadtxt(tmp_path / "out" / "results.csv", delimiter=",", skiprows=1, ndmin=2)
    assert len(rows) == 51 and rows[1, 0] == 0.02


def test_exported_again_it_reads_back_the_same(foreign, tmp_path):
    """Our writer puts the flattened system in one ssd:System (instances keep their dotted names): it reads
    back to the same scenario, schema-valid."""
    from cosim.ssp.export import export_ssp

    nested = load_ssp(foreign)
    again = load_ssp(export_ssp(nested, tmp_path / "again.ssp"))
    assert ssd_schema_errors(again.source) == []
    assert {k: {**v, "path": None} for k, v in again.fmus.items()} == {k: {**v, "path": None}
                                                                       for k, v in nested.fmus.items()}
    assert ({str(c): c.conversion for c in parse_connections(again.connections)}
            == {str(c): c.conversion for c in parse_connections(nested.connections)})
    assert (again.step, again.duration, again.record) == (nested.step, nested.duration, nested.record)


ONE = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0"
    name="one">
  <ssd:System name="Root">
    <ssd:Elements><ssd:Component name="{fmu}" source="resources/{fmu}.fmu"/></ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment stopTime="{stop}"/>
</ssd:SystemStructureDescription>
"""


@pytest.mark.parametrize("fmu, stop, step, origin", [
    ("Feedthrough", "2.0", 0.002, "from the span / 1000 (no step in the archive nor in its FMUs; span 2 s)"),
    # Dahlquist asks 0.1 s: 0.25 s is no whole number of them, so the grid is 0.25 / 3
    ("Dahlquist", "0.25", 0.25 / 3, "from the smallest FMU DefaultExperiment stepSize (Dahlquist: 0.1 s), 3 steps "
                                    "over the span of 0.25 s"),
])
def test_without_a_step_the_default_is_said(tmp_path, caplog, fmu, stop, step, origin):
    path = _archive(tmp_path / "one.ssp", ONE.format(fmu=fmu, stop=stop))
    with caplog.at_level(logging.INFO, logger="cosim.ssp.archive"):
        scenario = load_ssp(path)
    assert scenario.step == step
    assert any(origin in r.getMessage() for r in caplog.records), [r.getMessage() for r in caplog.records]
