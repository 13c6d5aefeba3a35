"""Issue 41 end to end: a system as modelling and SSP tools export it flies as exported.

Three FMI 2.0 Model Exchange-only FMUs written the way Modelica tools write
them (``tests/industrial_fmus.py``: the DC motor's source, electrical and
mechanical parts; names ``pin_p.v``, ``flange.tau``, ``x[1]``,
``der(x[1])``; ``rad/s`` defined without the radian in one FMU and with it in
the other), packed in an SSP archive as an SSP editor writes it: the motor a
nested system ``SuT`` with its own connectors, every component
``implementation="ModelExchange"``, a ``.ssv`` parameter set, a default
experiment without a step. Nothing is added for our tool: no step, no
annotation. The run must land within 1e-6 of the monolithic solution, scipy's
``solve_ivp`` over the three FMUs' stacked states, written here.
"""
from __future__ import annotations

import dataclasses
import zipfile

import numpy as np
import pytest

from cosim.scenario.assembly import build_master
from cosim.ssp.archive import load_ssp, ssd_schema_errors
from tests.industrial_fmus import DC_MOTOR, dc_motor_rhs, dc_motor_specs

R = 1.5  # Ohm: the archive's parameter set, not the FMU's start value (1 Ohm)
TOLERANCE = 1e-10  # the FMUs' DefaultExperiment tolerance, as an exporting tool writes it

SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    version="1.0" name="motor_bench" generationTool="SomeEditor 4.2">
  <ssd:System name="Bench">
    <ssd:Elements>
      <ssd:Component name="supply" source="resources/DCMotor_Source.fmu" implementation="ModelExchange">
        <ssd:Connectors><ssd:Connector name="v" kind="output"><ssc:Real unit="V"/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
      <ssd:System name="SuT">
        <ssd:Connectors>
          <ssd:Connector name="v_in" kind="input"><ssc:Real unit="V"/></ssd:Connector>
          <ssd:Connector name="speed" kind="output"><ssc:Real unit="rad/s"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:Elements>
          <ssd:Component name="edrive_el" source="resources/DCMotor_Electrical.fmu" implementation="ModelExchange">
            <ssd:Connectors>
              <ssd:Connector name="pin_p.v" kind="input"><ssc:Real unit="V"/></ssd:Connector>
              <ssd:Connector name="w" kind="input"><ssc:Real unit="rad/s"/></ssd:Connector>
              <ssd:Connector name="flange.tau" kind="output"><ssc:Real unit="N.m"/></ssd:Connector>
              <ssd:Connector name="i" kind="output"><ssc:Real unit="A"/></ssd:Connector>
              <ssd:Connector name="R" kind="parameter"><ssc:Real unit="Ohm"/></ssd:Connector>
            </ssd:Connectors>
            <ssd:ParameterBindings><ssd:ParameterBinding source="resources/armature.ssv"/></ssd:ParameterBindings>
          </ssd:Component>
          <ssd:Component name="edrive_mass" source="resources/DCMotor_Mechanical.fmu" implementation="ModelExchange">
            <ssd:Connectors>
              <ssd:Connector name="flange.tau" kind="input"><ssc:Real unit="N.m"/></ssd:Connector>
              <ssd:Connector name="w" kind="output"><ssc:Real unit="rad/s"/></ssd:Connector>
              <ssd:Connector name="phi" kind="output"><ssc:Real unit="rad"/></ssd:Connector>
            </ssd:Connectors>
          </ssd:Component>
        </ssd:Elements>
        <ssd:Connections>
          <ssd:Connection startConnector="v_in" endElement="edrive_el" endConnector="pin_p.v"/>
          <ssd:Connection startElement="edrive_el" startConnector="flange.tau" endElement="edrive_mass"
              endConnector="flange.tau"/>
          <ssd:Connection startElement="edrive_mass" startConnector="w" endElement="edrive_el" endConnector="w"/>
          <ssd:Connection startElement="edrive_mass" startConnector="w" endConnector="speed"/>
        </ssd:Connections>
      </ssd:System>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="supply" startConnector="v" endElement="SuT" endConnector="v_in"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:Units>
    <ssc:Unit name="V"><ssc:BaseUnit kg="1" m="2" s="-3" A="-1"/></ssc:Unit>
    <ssc:Unit name="rad/s"><ssc:BaseUnit rad="1" s="-1"/></ssc:Unit>
  </ssd:Units>
  <ssd:DefaultExperiment startTime="0" stopTime="0.06"/>
</ssd:SystemStructureDescription>
"""

SSV = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0"
    name="armature">
  <ssv:Parameters><ssv:Parameter name="R"><ssv:Real value="{R}" unit="Ohm"/></ssv:Parameter></ssv:Parameters>
  <ssv:Units><ssc:Unit xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" name="Ohm">
    <ssc:BaseUnit kg="1" m="2" s="-3" A="-2"/></ssc:Unit></ssv:Units>
</ssv:ParameterSet>
"""


@pytest.fixture(scope="module")
def archive(tmp_path_factory, industrial_fmus):
    """The archive, its FMUs Model Exchange only (each FMU's default
    experiment carries the tolerance, as its tool exports it)."""
    path = tmp_path_factory.mktemp("industrial_system") / "motor_bench.ssp"
    with zipfile.ZipFile(path, "w") as ssp:
        ssp.writestr("SystemStructure.ssd", SSD)
        ssp.writestr("resources/armature.ssv", SSV)
        for name, spec in dc_motor_specs().items():
            spec = dataclasses.replace(spec, default_experiment={"startTime": 0.0, "stopTime": 0.06,
                                                                 "tolerance": TOLERANCE})
            ssp.write(industrial_fmus(spec), f"resources/{name}.fmu")
    return path


def _monolithic(times: np.ndarray) -> np.ndarray:
    """scipy's ``solve_ivp`` over the stacked states [i, phi, w] of the three
    FMUs (``dc_motor_rhs``: their equations, the connections substituted by
    hand): the source's step at t_step splits the integration (the
    right-hand side jumps there)."""
    from scipy.integrate import solve_ivp

    p = {**DC_MOTOR, "R": R}
    f = dc_motor_rhs(R=R)  # f(t, x, v): the three FMUs' equations, the source's value v held over a piece
    jacobian = [[-p["R"] / p["L"], 0, -p["k"] / p["L"]], [0, 0, 1], [p["k"] / p["J"], 0, -p["b"] / p["J"]]]
    before, after = times[times < p["t_step"]], times[times >= p["t_step"]]
    x = np.zeros((len(times), 3))  # at rest until the step
    sol = solve_ivp(f, (p["t_step"], times[-1]), [0.0, 0.0, 0.0], method="Radau", t_eval=after, args=(p["V0"],),
                    rtol=1e-11, atol=1e-12, jac=jacobian)
    x[len(before):] = sol.y.T
    return x


def test_a_nested_model_exchange_archive_as_exported_lands_on_the_monolithic_solution(archive):
    """As exported: the archive is schema-valid SSP 1.0, the motor's FMUs
    are instances ``SuT.edrive_el`` and ``SuT.edrive_mass``, the connection
    through ``SuT.v_in`` is a direct one, the ``.ssv``'s R is set, the
    step is the default (span / 1000: no FMU gives a step), and the three
    Model Exchange FMUs are one system: speed and current within 1e-6 of
    the monolithic solution over the start-up transient."""
    with zipfile.ZipFile(archive) as ssp:
        assert ssd_schema_errors(ssp.read("SystemStructure.ssd")) == []
    scenario = load_ssp(archive)
    assert sorted(scenario.fmus) == ["SuT.edrive_el", "SuT.edrive_mass", "supply"]
    assert scenario.step == pytest.approx(0.06 / 1000)
    with build_master(scenario) as master:
        assert [sorted(m.name for m in s.members) for s in master.me_systems] == [
            ["SuT.edrive_el", "SuT.edrive_mass", "supply"]]
        result = master.run(scenario.duration)
    exact = _monolithic(result.time)
    assert np.max(np.abs(result["SuT.edrive_mass.w"] - exact[:, 2])) < 1e-6
    assert np.max(np.abs(result["SuT.edrive_el.i"] - exact[:, 0])) < 1e-6
    assert np.max(exact[:, 2]) > 100  # the transient is there: the motor spins up to ~ 200 rad/s


def test_the_command_line_says_what_it_decided_for_the_archive(archive, tmp_path, capsys):
    """``fnn-cosim run`` of the archive: exit 0, and stderr says, once the
    inputs are taken, the step it chose (no step anywhere: span / 1000) and
    the speed's unit taken without its radian, naming the connection;
    ``--quiet`` says nothing."""
    from quadrotor_paper.cli import main

    assert main(["run", str(archive), "--out", str(tmp_path / "a"), "--no-plots"]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith("note: ")]
    assert any("communication step" in n and "span / 1000" in n for n in notes), notes
    assert any("SuT.edrive_mass.w -> SuT.edrive_el.w" in n and "radian" in n for n in notes), notes
    assert main(["run", str(archive), "--out", str(tmp_path / "b"), "--no-plots", "--quiet"]) == 0
    assert "note: " not in capsys.readouterr().err
