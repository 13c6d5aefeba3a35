"""Units by meaning (cosim.fmi.units): parsing, equivalence, conversion; the
modelDescription's UnitDefinitions (also through a declaredType) winning over
the name; connections that convert, in the compiled and the Python loop
alike; the explicit conversion and the unchecked marker of a scenario."""
from __future__ import annotations

import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from cosim.loop import kernel
from cosim.component import Port, ports
from cosim.loop.connection import check_connections, parse_connections
from cosim.errors import ConnectionCheckError, ScenarioError
from cosim.fmi.fmu import FmuComponent
from cosim.fmi.description import fmu_ports
from cosim.loop.master import Master
from cosim.scenario.definition import parse_scenario
from cosim.scenario.assembly import build_master
from cosim.fmi.units import BASE_UNITS, Unit, conversion, definitions, parse, unit_of
from toy_models import LAG_K, LAG_TAU, Constant, Probe, lag_fmu_path, lag_step

H = 0.01


# ---- units on their own ------------------------------------------------------------------------------

def test_rad_per_s_and_radian_per_second_are_one_unit():
    assert parse("rad/s") == Unit("rad/s", parse("radian / second").exponents)
    assert parse("rad/s").exponents == (0, 0, -1, 0, 0, 0, 0, 1)  # kg m s A K mol cd rad
    assert conversion("rad/s", "radian / second") == (1.0, 0.0)


def test_km_per_h_converts_to_m_per_s_by_1000_over_3600():
    factor, offset = conversion("km/h", "m/s")
    assert factor == pytest.approx(1000.0 / 3600.0, rel=1e-15) and offset == 0.0
    back, _ = conversion("m/s", "km/h")
    assert back == pytest.approx(3.6, rel=1e-15)


def test_degC_to_K_is_affine():
    assert conversion("degC", "K") == (1.0, 273.15)
    factor, offset = conversion("K", "degC")
    assert (factor, offset) == (1.0, -273.15)
    # 212 degF is 100 degC
    f, o = conversion("degF", "degC")
    assert f * 212.0 + o == pytest.approx(100.0, abs=1e-12)


def test_modelica_unit_syntax_is_read():
    assert conversion("m/s2", "m/s^2") == (1.0, 0.0)
    assert parse("kg.m2/s2").exponents == parse("J").exponents


def test_a_unit_that_leaves_out_the_radian_is_the_unit_with_it_but_cycles_are_not_radians():
    """FMI keeps rad as a base unit, and many FMUs' definitions (and units
    libraries) leave it out: rad/s and 1/s, rad and 1 connect by their own
    factors; Hz counts cycles (2 pi rad each): refused saying so, and an
    rpm defined without its radian is read by its name (2 pi / 60 rad/s)."""
    assert conversion("rad/s", "1/s") == conversion("rad", "1") == (1.0, 0.0)
    assert conversion("deg", "1") == conversion("deg", "rad")
    dropped = Unit("radian / second", parse("1/s").exponents)  # <BaseUnit s="-1"/>, the issue's FMU input
    assert conversion("rad/s", dropped) == (1.0, 0.0)
    assert conversion(Unit("rpm", parse("1/s").exponents, 1 / 60), "rad/s") == conversion("rpm", "rad/s")
    for a, b in (("Hz", "rad/s"), ("rad/s", "kHz")):
        with pytest.raises(ConnectionCheckError, match=r"not one quantity: k?Hz counts cycles, rad/s radians \(2\*pi"):
            conversion(a, b)
    with pytest.raises(ConnectionCheckError, match="not one quantity"):
        conversion("m", "rad")
    assert conversion("1", "dimensionless") == conversion("", "1") == (1.0, 0.0)
    assert conversion("deg", "rad")[0] == pytest.approx(np.pi / 180, rel=1e-15)
    assert conversion("rpm", "rad/s")[0] == pytest.approx(2 * np.pi / 60, rel=1e-15)


@pytest.mark.parametrize("name", ["m", "s", "kg", "rad", "A", "K", "mol", "cd", "m/s", "rad/s", "m/s2", "m/s^2",
                                  "kg.m2", "kg*m^2/s2", "N", "1/s", "s-1", "m.s-2", "rad/s2", "kg.m2.s-2"])
def test_a_name_of_base_units_is_read_without_pint_as_pint_reads_it(name):
    """Names written with the FMI base units alone are read from the name
    (no pint registry to build): the same Unit, factor and offset included,
    as pint's reading; other names (N here) go to pint."""
    from cosim.fmi import units

    assert units.parse(name) == Unit(name, *_by_pint(name))
    plain = units._base_units_only(name)
    assert plain is None if name == "N" else plain == units.parse(name)


def _by_pint(name):
    from cosim.fmi import units

    units.parse.cache_clear()
    real = units._base_units_only
    try:
        units._base_units_only = lambda _: None
        u = units.parse(name)
    finally:
        units._base_units_only = real
        units.parse.cache_clear()
    return u.exponents, u.factor, u.offset


def test_names_that_only_look_like_base_units_go_to_pint():
    from cosim.fmi.units import _base_units_only

    for name in ("ms", "Hz", "km/h", "m/s/s", "kg/(m.s)", "degC", "mm", "furlongs_per_blob", "m s"):
        assert _base_units_only(name) is None, name
    assert parse("ms").exponents == parse("s").exponents and parse("ms").factor == pytest.approx(1e-3)


def test_incompatible_units_name_both():
    with pytest.raises(ConnectionCheckError, match=re.escape("units m and s are not one quantity")):
        conversion("m", "s")
    with pytest.raises(ConnectionCheckError, match=re.escape("units furlongs_per_blob (unknown to the "
                                                             "modelDescription and to pint) and m")):
        conversion("furlongs_per_blob", "m")
    assert parse("furlongs_per_blob") is None


def test_a_definition_wins_over_the_name():
    mm_named_m = Unit("m", (0, 1, 0, 0, 0, 0, 0, 0), factor=0.001)
    assert unit_of("m", {"m": mm_named_m}) is mm_named_m
    assert unit_of("m", {}) == parse("m")
    assert conversion(mm_named_m, "m") == (0.001, 0.0)


MODEL_DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Units" guid="{0}" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="Units"/>
  <UnitDefinitions>
    <Unit name="km/h"><BaseUnit m="1" s="-1" factor="0.2777777777777778"/>
      <DisplayUnit name="mph" factor="0.621371"/></Unit>
    <Unit name="degF"><BaseUnit K="1" factor="0.5555555555555556" offset="255.3722222222222"/></Unit>
    <Unit name="tick"/>
  </UnitDefinitions>
  <TypeDefinitions>
    <SimpleType name="Speed"><Real unit="km/h" displayUnit="mph"/></SimpleType>
  </TypeDefinitions>
  <ModelVariables>
    <ScalarVariable name="wind" valueReference="0" causality="output" variability="continuous"
                    initial="exact"><Real declaredType="Speed" start="0"/></ScalarVariable>
    <ScalarVariable name="temperature" valueReference="1" causality="output" variability="continuous"
                    initial="exact"><Real unit="degF" start="0"/></ScalarVariable>
    <ScalarVariable name="count" valueReference="2" causality="output" variability="continuous"
                    initial="exact"><Real unit="tick" start="0"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1"/><Unknown index="2"/><Unknown index="3"/></Outputs></ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture
def model_description(tmp_path):
    path = tmp_path / "modelDescription.xml"
    path.write_text(MODEL_DESCRIPTION)
    return read_model_description(str(path))


def test_unit_definitions_are_read_from_the_model_description(model_description):
    units = definitions(model_description)
    assert units["km/h"] == Unit("km/h", (0, 1, -1, 0, 0, 0, 0, 0), 0.2777777777777778, 0.0)
    assert units["degF"].offset == 255.3722222222222
    assert "tick" not in units  # a <Unit> without <BaseUnit> says nothing about SI: its name is all there is
    assert len(BASE_UNITS) == 8


def test_a_port_takes_its_unit_through_its_declared_type(model_description):
    outputs = {p.name: p for p in fmu_ports(model_description)["output"]}
    wind = outputs["wind"]
    assert wind.unit == "km/h"  # from the SimpleType; its displayUnit mph takes no part
    assert wind.unit_definition.factor == 0.2777777777777778
    sink = {"sink": _stand_in(inputs=ports(("v", "m/s"), ("T", "degC"), ("n", "tick")))}
    src = {"src": _stand_in(outputs=tuple(outputs.values()))}
    checked = check_connections(parse_connections(["src.wind -> sink.v", "src.temperature -> sink.T",
                                                   "src.count -> sink.n"]), {**src, **sink})
    assert checked[0].conversion == (0.2777777777777778, 0.0)
    f, o = checked[1].conversion
    assert f * 212.0 + o == pytest.approx(100.0, abs=1e-9)  # the FMU's degF into the sink's pint degC
    assert checked[2].conversion is None  # one name, known to neither: one unit


def _stand_in(inputs=(), outputs=()):
    from types import SimpleNamespace

    return SimpleNamespace(inputs=tuple(inputs), outputs=tuple(outputs))


# ---- connections -----------------------------------------------------------------------------------

def _components():
    return {"src": _stand_in(outputs=ports(("v", "km/h"), ("x", "m"), ("w", "rad/s"))),
            "sink": _stand_in(inputs=ports(("v", "m/s"), ("t", "s"), ("w", "radian / second"), ("d", "1")))}


def test_a_connection_that_drops_the_radian_is_told_at_info_level_and_hz_is_refused(caplog):
    import logging

    comps = {"src": _stand_in(outputs=ports(("w", "rad/s"), ("f", "Hz"))),
             "sink": _stand_in(inputs=(Port("w", "radian / second", unit_definition=Unit("radian / second",
                                                                                           parse("1/s").exponents)),))}
    with caplog.at_level(logging.INFO, logger="cosim.loop.connection"):
        (w,) = check_connections(parse_connections(["src.w -> sink.w"]), comps)
    assert w.conversion is None and "connection src.w -> sink.w:" in caplog.text and "radian" in caplog.text
    with pytest.raises(ConnectionCheckError, match="connection src.f -> sink.w: unit mismatch.*Hz counts cycles"):
        check_connections(parse_connections(["src.f -> sink.w"]), comps)


def test_a_connection_between_units_of_one_quantity_converts():
    v, w = check_connections(parse_connections(["src.v -> sink.v", "src.w -> sink.w"]), _components())
    assert v.conversion == conversion("km/h", "m/s")
    assert w.conversion is None  # rad/s into radian / second: the same unit, nothing to convert


@pytest.mark.parametrize("text, units", [("src.x -> sink.t", "src.x is in m but sink.t is in s"),
                                         ("src.v -> sink.d", "src.v is in km/h (SI m.s-1) but sink.d is in 1")])
def test_incompatible_units_name_both_and_the_two_ways_out(text, units):
    with pytest.raises(ConnectionCheckError) as info:
        check_connections(parse_connections([text]), _components())
    message = str(info.value)
    assert message == (f"connection {text}: unit mismatch, {units}, not one quantity; state the conversion, "
                       f"{{ connect = \"{text}\", factor = ..., offset = ... }} ({text.split(' -> ')[1]} = factor * "
                       f"{text.split(' -> ')[0]} + offset), or mark it {{ connect = \"{text}\", "
                       f"units = \"unchecked\" }}")
    assert "\n" not in message


def test_an_explicit_conversion_or_the_unchecked_marker_lets_them_connect():
    converted, unchecked = check_connections(parse_connections([
        {"connect": "src.x -> sink.t", "factor": 2.0, "offset": 0.5},
        {"connect": "src.v -> sink.d", "units": "unchecked"}]), _components())
    assert converted.conversion == (2.0, 0.5) and not converted.unchecked
    assert unchecked.conversion is None and unchecked.unchecked
    # an explicit conversion replaces the one the units would give
    (v,) = check_connections(parse_connections([{"connect": "src.v -> sink.v", "factor": 1.0}]), _components())
    assert v.conversion == (1.0, 0.0)


# ---- runs --------------------------------------------------------------------------------------------

def _with_unit_definition(tmp_path: Path, version: int, old: str, new: str) -> Path:
    """The toy lag FMU with one unit definition rewritten (``old`` -> ``new`` in its modelDescription)."""
    source, target = lag_fmu_path(version), tmp_path / f"lag{version}_redefined.fmu"
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                assert old in text
                data = text.replace(old, new).encode()
            zout.writestr(item, data)
    return target


MM_NAMED_M = ('<Unit name="m"><BaseUnit m="1"/></Unit>', '<Unit name="m"><BaseUnit m="1" factor="0.001"/></Unit>')


def test_an_fmu_whose_unit_definitions_give_a_factor_is_converted(tmp_path):
    """Its 'm' is defined as 0.001 m: the definition wins over the name, so A.y -> B.u converts by 0.001."""
    a = FmuComponent("A", _with_unit_definition(tmp_path, 2, *MM_NAMED_M))
    b = FmuComponent("B", lag_fmu_path(2))
    try:
        assert {p.name: p for p in a.outputs}["y"].unit_definition.factor == 0.001
        master = Master([a, b], [], ["A.y -> B.u"], H, ["A.y", "B.u"])
        assert master.connections[0].conversion == (0.001, 0.0)
    finally:
        a.close()
        b.close()


def _converting_master(tmp_path, version: int, ordering: str) -> Master:
    a = FmuComponent("A", _with_unit_definition(tmp_path, version, *MM_NAMED_M))
    b, c = FmuComponent("B", lag_fmu_path(version)), FmuComponent("C", lag_fmu_path(version))
    connections = ["A.y -> B.u",  # by the units: 0.001
                   {"connect": "B.y -> C.u", "factor": -2.0, "offset": 0.25},  # stated
                   "C.y -> A.u"]
    return Master([a, b, c], [], connections, H, ["A.y", "B.u", "B.y", "C.u", "C.y", "B.rate"],
                  {"C.u": (-1e3, 1e3)}, {"A": {"y_0": 500.0}, "B": {"y_0": 0.1}}, ordering=ordering)


def _run(monkeypatch, tmp_path, compiled: bool, version: int, ordering: str):
    monkeypatch.setenv("COSIM_PYTHON_LOOP", "" if compiled else "1")
    kernel.load.cache_clear()
    try:
        with _converting_master(tmp_path, version, ordering) as master:
            assert master.plan.compiled
            return master.run(1.0, block_rows=16)
    finally:
        kernel.load.cache_clear()


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("ordering", ["feedthrough", "exchange"])
def test_a_conversion_is_applied_alike_in_the_compiled_and_the_python_loop(monkeypatch, tmp_path, version, ordering):
    kernel.load.cache_clear()
    if kernel.load() is None:
        pytest.skip("no C compiler: the compiled loop is not available")
    fast = _run(monkeypatch, tmp_path, True, version, ordering)
    slow = _run(monkeypatch, tmp_path, False, version, ordering)
    assert fast.status == slow.status == "ok"
    assert np.array_equal(fast.data, slow.data)  # bit for bit
    # the recorded inputs are the converted values (in their own unit)
    np.testing.assert_array_equal(fast["B.u"], 0.001 * fast["A.y"])
    np.testing.assert_array_equal(fast["C.u"], -2.0 * fast["B.y"] + 0.25)
    assert fast["A.y"][0] == 500.0 and fast["B.u"][0] == 0.5
    # and B flew on them: its lag from the converted input held over each step (exchange: B sees t_n's values)
    y_next = [lag_step(y, u, H) for y, u in zip(fast["B.y"][:-1], fast["B.u"][:-1])]
    np.testing.assert_allclose(fast["B.y"][1:], y_next, rtol=1e-9, atol=1e-12)
    assert fast["B.rate"][0] == pytest.approx((LAG_K * 0.5 - 0.1) / LAG_TAU, rel=1e-12)


def test_the_unchecked_marker_passes_the_value_as_it_is():
    src, probe = Constant("src", value=3.6), Probe("probe")
    src.outputs = ports(("out", "km/h"))
    probe.inputs = ports(("y", "s"))
    with pytest.raises(ConnectionCheckError, match="unit mismatch, src.out is in km/h"):
        Master([], [src, probe], ["src.out -> probe.y"], H)
    master = Master([], [src, probe], [{"connect": "src.out -> probe.y", "units": "unchecked"}], H, ["probe.y"])
    result = master.run(0.02)
    assert [call[2][0] for call in probe.calls] == [3.6, 3.6, 3.6]
    assert list(result["probe.y"]) == [3.6, 3.6, 3.6]


def test_a_python_component_input_is_converted(tmp_path):
    src, probe = Constant("src", value=36.0), Probe("probe")
    src.outputs = ports(("out", "km/h"))
    probe.inputs = ports(("y", "m/s"))
    master = Master([], [src, probe], ["src.out -> probe.y"], H, ["src.out", "probe.y"])
    result = master.run(0.02)
    assert [call[2][0] for call in probe.calls] == [36.0 * conversion("km/h", "m/s")[0]] * 3
    assert result["probe.y"][0] == pytest.approx(10.0, rel=1e-15)


def test_a_scenario_states_a_conversion_and_refuses_a_wrong_table(tmp_path):
    raw = {"fmus": {"A": {"path": str(lag_fmu_path(2))}, "B": {"path": str(lag_fmu_path(2))}},
           "connections": [{"connect": "A.y -> B.u", "factor": 3.0, "offset": -1.0}],
           "simulation": {"duration": 0.05, "step": H}, "record": {"signals": ["A.y", "B.u"]}}
    raw["fmus"]["A"]["parameters"] = {"y_0": 2.0}
    with build_master(parse_scenario(raw)) as master:
        result = master.run(0.05)
    np.testing.assert_array_equal(result["B.u"], 3.0 * result["A.y"] - 1.0)
    raw["connections"] = [{"connect": "A.y -> B.u"}]
    with pytest.raises(ScenarioError, match=re.escape("connections[0]: give a conversion (factor, offset) or "
                                                      "units = 'unchecked', not both and not neither")):
        parse_scenario(raw)
    raw["connections"] = [{"connect": "A.y -> B.u", "units": "ignored"}]
    with pytest.raises(ScenarioError, match=re.escape("connections[0].units = 'ignored': expected one of unchecked")):
        parse_scenario(raw)


def test_the_scenario_schema_declares_connection_tables():
    from cosim.scenario.definition import scenario_json_schema

    schema = scenario_json_schema()
    items = schema["properties"]["connections"]["items"]["oneOf"]
    assert {"type": "string"} in items
    table = schema["$defs"]["ConnectionTable"]
    assert set(table["properties"]) == {"connect", "factor", "offset", "units"}
    assert table["properties"]["units"]["enum"] == ["unchecked"]
    jsonschema = pytest.importorskip("jsonschema", reason="jsonschema (a test extra) is not installed")
    validator = jsonschema.Draft202012Validator(schema)
    good = {"fmus": {"A": {"path": "a.fmu"}}, "connections": [
        "A.y -> B.u", {"connect": "A.y -> C.u", "factor": 0.5}, {"connect": "A.y -> D.u", "units": "unchecked"}]}
    assert [e.message for e in validator.iter_errors(good)] == []
    for bad in ({"connect": "A.y -> B.u", "units": "off"}, {"factor": 2.0}, {"connect": "A.y -> B.u", "gain": 2.0}):
        assert list(validator.iter_errors({**good, "connections": [bad]})), bad


# ---- SSP ---------------------------------------------------------------------------------------------

SSP_SCENARIO = """
name = "converted_chain"
connections = [{ connect = "A.y -> B.u", factor = 1000.0, offset = 0.5 },
               { connect = "B.y -> C.u", units = "unchecked" }]

[simulation]
duration = 1.0
step = 0.1
ordering = "exchange"

[fmus.A]
model = "toy_FirstOrderLag"
parameters = { y_0 = 1.5, u = 2.0 }

[fmus.B]
model = "toy_FirstOrderLag"

[fmus.C]
model = "toy_FirstOrderLag"

[record]
signals = ["A.y", "B.y", "C.y", "B.u", "C.u"]
"""


@pytest.fixture
def converted_archive(toys, tmp_path):
    import tomllib

    from cosim.ssp.export import export_ssp

    scenario = parse_scenario(tomllib.loads(SSP_SCENARIO))
    return scenario, export_ssp(scenario, tmp_path / "converted.ssp")


def _ssd(path: Path):
    from lxml import etree

    from cosim.ssp.archive import SSD_NAME

    with zipfile.ZipFile(path) as z:
        return etree.fromstring(z.read(SSD_NAME))


def test_an_archive_carries_the_conversions_the_ssp_way_and_reads_them_back(converted_archive):
    from cosim.ssp.archive import NS, load_ssp, ssd_schema_errors

    scenario, archive = converted_archive
    root = _ssd(archive)
    converted, unchecked = root.findall("ssd:System/ssd:Connections/ssd:Connection", NS)
    assert converted.get("suppressUnitConversion") == unchecked.get("suppressUnitConversion") == "true"
    (transformation,) = converted
    assert transformation.tag == f"{{{NS['ssc']}}}LinearTransformation"
    assert (float(transformation.get("factor")), float(transformation.get("offset"))) == (1000.0, 0.5)
    assert len(unchecked) == 0
    with zipfile.ZipFile(archive) as z:
        assert ssd_schema_errors(z.read("SystemStructure.ssd")) == []
    loaded = load_ssp(archive)
    assert [dict(c) for c in loaded.connections] == [dict(c) for c in scenario.connections]
    with build_master(scenario) as master:
        ours = master.run(scenario.duration)
    with build_master(loaded) as master:
        again = master.run(loaded.duration)
    assert np.array_equal(ours.data, again.data)
    np.testing.assert_array_equal(ours["B.u"], 1000.0 * ours["A.y"] + 0.5)


def test_a_transformation_applies_after_the_connectors_unit_conversion(converted_archive, tmp_path):
    """SSP 1.0: without suppressUnitConversion, the connectors' units convert first, then the transformation."""
    from lxml import etree

    from cosim.ssp.archive import NS, SSD_NAME, load_ssp

    _, archive = converted_archive
    folder = tmp_path / "edited"
    with zipfile.ZipFile(archive) as z:
        z.extractall(folder)
    tree = etree.parse(str(folder / SSD_NAME))
    connection = tree.find("ssd:System/ssd:Connections/ssd:Connection", NS)
    del connection.attrib["suppressUnitConversion"]
    a_y = tree.find("ssd:System/ssd:Elements/ssd:Component[@name='A']/ssd:Connectors/ssd:Connector[@name='y']/"
                    "ssc:Real", NS)
    a_y.set("unit", "km")  # no ssd:Units entry: read by pint
    tree.write(str(folder / SSD_NAME))
    loaded = load_ssp(folder)
    assert dict(loaded.connections[0]) == {"connect": "A.y -> B.u", "factor": 1000.0 * 1000.0, "offset": 0.5}
    a_y.set("unit", "s")
    tree.write(str(folder / SSD_NAME))
    with pytest.raises(ScenarioError, match=re.escape("ssd:Connections/ssd:Connection[1]: units s and m are not one quantity")):
        load_ssp(folder)


def test_libcosim_applies_the_archives_conversions(converted_archive):
    """libcosim (libcosimpy) loads the archive and applies ssc:LinearTransformation: it flies the
    'exchange' ordering's run (docs/ssp.md)."""
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed: libcosim cannot be run")
    from libcosim_runner import run_libcosim

    scenario, archive = converted_archive
    lc = run_libcosim(archive, ["A.y", "B.y", "C.y", "B.u"])
    with build_master(scenario) as master:
        ours = master.run(scenario.duration)
    assert lc["B.u"][0] == 1000.0 * 1.5 + 0.5  # the transformation, at initialization
    for name in ("A.y", "B.y", "C.y"):
        np.testing.assert_allclose(lc[name], ours[name], rtol=1e-12, atol=1e-9, err_msg=name)


class _TwoInputs(Probe):
    """Remembers its two inputs as given (a, b in m)."""

    inputs = ports(("a", "m"), ("b", "m"))


def test_only_the_converted_inputs_are_touched():
    """b converts (km -> m); a does not, and keeps the sign of its -0.0 (x * 1 + 0 would not)."""
    zero, two_km, probe = Constant("zero", value=-0.0), Constant("two_km", value=2.0), _TwoInputs("probe")
    two_km.outputs = ports(("out", "km"))
    master = Master([], [zero, two_km, probe], ["zero.out -> probe.a", "two_km.out -> probe.b"], H)
    assert [c.conversion for c in master.connections] == [None, (1000.0, 0.0)]
    master.run(0.01)
    for _, _, u in probe.calls:
        assert np.signbit(u[0]) and u[0] == 0.0 and u[1] == 2000.0


def test_a_snapshot_holds_the_converted_inputs(tmp_path):
    a = FmuComponent("A", _with_unit_definition(tmp_path, 2, *MM_NAMED_M))
    b = FmuComponent("B", lag_fmu_path(2))
    with Master([a, b], [], ["A.y -> B.u"], H, ["A.y"], fmu_parameters={"A": {"y_0": 300.0}}) as master:
        (snapshot,) = master.run(0.1, snapshots=[0.05]).snapshots
    assert snapshot.inputs["B.u"] == 0.001 * snapshot.outputs["A.y"] != 0.0
    assert "B.u" not in snapshot.outputs


def test_an_archive_defines_a_unit_the_fmu_only_names(toys, tmp_path):
    """A unit the modelDescription names but does not define goes into ssd:Units as pint reads it,
    so that an importer converts as our master does."""
    import tomllib

    from cosim.ssp.archive import NS
    from cosim.ssp.export import export_ssp

    no_m = _with_unit_definition(tmp_path, 2, '<Unit name="m"><BaseUnit m="1"/></Unit>', "")
    text = SSP_SCENARIO.replace('model = "toy_FirstOrderLag"', f'path = "{no_m}"')
    assert text.count(str(no_m)) == 3
    archive = export_ssp(parse_scenario(tomllib.loads(text)), tmp_path / "no_m.ssp")
    (m,) = [u for u in _ssd(archive).iterfind("ssd:Units/ssc:Unit", NS) if u.get("name") == "m"]
    assert dict(m.find("ssc:BaseUnit", NS).attrib) == {"m": "1"}


@pytest.mark.parametrize("table", [{"connect": "src.x -> sink.t"}, {"connect": "src.x -> sink.t", "units": "no"},
                                   {"connect": "src.x -> sink.t", "factor": 2.0, "units": "unchecked"},
                                   {"factor": 2.0}, {"connect": "src.x -> sink.t", "gain": 2.0}])
def test_a_wrong_connection_table_given_to_the_master_is_refused(table):
    with pytest.raises(ConnectionCheckError, match=re.escape("expected 'connect' and either a conversion (factor, "
                                                             "offset) or units = 'unchecked'")):
        parse_connections([table])


def test_the_dc_motors_speed_without_its_radian_connects_checked(tmp_path, caplog):
    """The issue's angle case on FMUs a modelling tool writes (tests/industrial_fmus.py, their
    modelDescriptions only): the mechanical part's rad/s leaves the radian out, the electrical
    part's keeps it; the checked connection passes the value as it is, noted at info level."""
    import logging

    from tests.industrial_fmus import dc_motor_specs, model_description

    comps = {}
    for name in ("DCMotor_Mechanical", "DCMotor_Electrical"):
        xml = tmp_path / f"{name}.xml"
        xml.write_text(model_description(dc_motor_specs()[name], "{0}"))
        ports_ = fmu_ports(read_model_description(str(xml)))
        comps[name] = _stand_in(inputs=ports_["input"], outputs=ports_["output"])
    with caplog.at_level(logging.INFO, logger="cosim.loop.connection"):
        (c,) = check_connections(parse_connections(["DCMotor_Mechanical.w -> DCMotor_Electrical.w"]), comps)
    assert c.conversion is None and not c.unchecked
    assert "connection DCMotor_Mechanical.w -> DCMotor_Electrical.w: rad/s (SI s-1) and rad/s (SI s-1.rad)" \
        in caplog.text
