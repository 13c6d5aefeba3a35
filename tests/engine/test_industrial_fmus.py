"""The writer of industrial-style FMUs (tests/industrial_fmus.py) makes FMUs that fmpy validates and
flies: the mechanical part of the DC motor against its analytic solution, its Co-Simulation
interface against Model Exchange to forward Euler's first order, the source's time event at t_step,
the bouncing mass's state event, FMU states and directional derivatives through the FMI calls."""
from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Model
from fmpy.validation import validate_fmu

from tests.catalog_fmus import extracted, simulated
from tests.industrial_fmus import (DC_MOTOR, algebraic_loop_specs, bouncing_mass_spec, build, dc_motor_reference,
                                   dc_motor_rhs, dc_motor_specs)

TAU = 0.02  # N.m, the constant driving torque of the mechanical part alone


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """Every ready-made FMU, built once (the DC motor's mechanical part also with Co-Simulation)."""
    folder = tmp_path_factory.mktemp("industrial_fmus")
    specs = {**dc_motor_specs(), "BouncingMass": bouncing_mass_spec(), **algebraic_loop_specs()}
    built = {name: build(folder, spec) for name, spec in specs.items()}
    cs = dc_motor_specs(interfaces=("ModelExchange", "CoSimulation"))["DCMotor_Mechanical"]
    built["DCMotor_Mechanical+CS"] = build(folder, cs)
    return built


def test_every_ready_made_fmu_passes_fmpy_validation(fmus):
    assert {name: validate_fmu(str(path)) for name, path in fmus.items()} == {name: [] for name in fmus}


def test_the_names_and_units_are_those_of_a_modelling_tool(fmus):
    md = read_model_description(str(fmus["DCMotor_Mechanical"]))
    names = [v.name for v in md.modelVariables]
    assert {"x[1]", "x[2]", "der(x[1])", "flange.tau"} <= set(names)
    assert [d.variable.name for d in md.derivatives] == ["der(x[1])", "der(x[2])"]
    assert [d.variable.derivative.name for d in md.derivatives] == ["x[1]", "x[2]"]
    assert [v.valueReference for v in md.modelVariables] == list(range(len(names)))
    rad_per_s = next(u for u in md.unitDefinitions if u.name == "rad/s").baseUnit
    assert (rad_per_s.rad, rad_per_s.s) == (0, -1)  # the radian left out, as many tools write it
    electrical = read_model_description(str(fmus["DCMotor_Electrical"]))
    assert next(u for u in electrical.unitDefinitions if u.name == "rad/s").baseUnit.rad == 1
    dependencies = {o.variable.name: sorted(d.name for d in o.dependencies) for o in electrical.outputs}
    assert dependencies == {"i": ["i"], "flange.tau": ["i"]}
    assert md.coSimulation is None and md.modelExchange.modelIdentifier == "DCMotor_Mechanical"


def _mechanical_exact(t):
    """J w' = tau - b w - tau_load from rest, phi' = w: w = w_ss (1 - exp(-t b/J))."""
    w_ss, rate = (TAU - DC_MOTOR["tau_load"]) / DC_MOTOR["b"], DC_MOTOR["b"] / DC_MOTOR["J"]
    w = w_ss * (1 - np.exp(-rate * t))
    return w, w_ss * t - w / rate


def test_the_mechanical_part_alone_matches_its_analytic_solution_in_model_exchange(fmus):
    result = simulated(fmus["DCMotor_Mechanical"], fmi_type="ModelExchange", start_values={"flange.tau": TAU},
                       stop_time=1.0, output_interval=0.1, relative_tolerance=1e-10)
    w, phi = _mechanical_exact(result["time"])
    np.testing.assert_allclose(result["w"], w, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(result["phi"], phi, rtol=1e-9, atol=1e-12)


def test_co_simulation_is_forward_euler_at_the_fixed_step(fmus):
    """Forward Euler at h on w' = r (w_ss - w) leaves (1 - r h)^n of the distance to w_ss where the
    solution leaves exp(-r n h): to first order in h it runs ahead by (h/2) t r^2 w_ss exp(-r t),
    and the Co-Simulation run (h = fixed_step) is ahead of the Model Exchange run by that much."""
    path = fmus["DCMotor_Mechanical+CS"]
    h = dc_motor_specs()["DCMotor_Mechanical"].fixed_step
    options = dict(start_values={"flange.tau": TAU}, stop_time=1.0, output_interval=0.1)
    cs = simulated(path, fmi_type="CoSimulation", **options)
    me = simulated(path, fmi_type="ModelExchange", relative_tolerance=1e-10, **options)
    t = cs["time"]
    w_ss, rate = (TAU - DC_MOTOR["tau_load"]) / DC_MOTOR["b"], DC_MOTOR["b"] / DC_MOTOR["J"]
    first_order = h / 2 * t * rate ** 2 * w_ss * np.exp(-rate * t)
    np.testing.assert_allclose(cs["w"] - me["w"], first_order, rtol=0.01, atol=1e-9)


def test_the_source_steps_at_t_step_through_a_time_event(fmus):
    t_step = DC_MOTOR["t_step"]
    result = simulated(fmus["DCMotor_Source"], fmi_type="ModelExchange", stop_time=0.03, output_interval=0.004)
    at_step = result[result["time"] == t_step]  # fmpy records the values before and after an event
    assert list(at_step["v"]) == [0.0, DC_MOTOR["V0"]]
    assert (result["v"][result["time"] < t_step] == 0).all() and (result["v"][result["time"] > t_step] == 12).all()


def test_the_bouncing_mass_bounces_at_its_state_event(fmus):
    result = simulated(fmus["BouncingMass"], fmi_type="ModelExchange", stop_time=0.6, output_interval=0.1,
                       relative_tolerance=1e-10)
    bounce = math.sqrt(2 * 1.0 / 9.81)
    events = np.unique(result["time"][np.diff(result["time"], prepend=-1) == 0])
    assert len(events) == 1 and events[0] == pytest.approx(bounce, rel=1e-8)


def test_fmu_state_and_directional_derivatives_through_the_fmi_calls(fmus):
    path = fmus["DCMotor_Electrical"]
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extracted(path), modelIdentifier="DCMotor_Electrical",
                    instanceName="electrical")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setReal([vr["pin_p.v"], vr["w"], vr["i"]], [12.0, 100.0, 2.0])
        fmu.exitInitializationMode()
        p = DC_MOTOR
        assert fmu.getReal([vr["der(i)"], vr["flange.tau"]]) == [(12 - p["R"] * 2 - p["k"] * 100) / p["L"],
                                                                p["k"] * 2]
        seed = [1.0, 0.5, -2.0]
        directional = fmu.getDirectionalDerivative([vr["der(i)"], vr["flange.tau"]],
                                                   [vr["i"], vr["pin_p.v"], vr["w"]], seed)
        expected = [(-p["R"] * seed[0] + seed[1] - p["k"] * seed[2]) / p["L"], p["k"] * seed[0]]
        np.testing.assert_allclose(directional, expected, rtol=1e-15)
        state = fmu.getFMUstate()
        serialized = fmu.serializeFMUstate(state)
        fmu.setReal([vr["pin_p.v"]], [0.0])
        assert fmu.getReal([vr["der(i)"]])[0] < 0
        fmu.setFMUstate(fmu.deSerializeFMUstate(serialized))
        assert fmu.getReal([vr["pin_p.v"], vr["der(i)"]]) == [12.0, (12 - p["R"] * 2 - p["k"] * 100) / p["L"]]
        fmu.freeFMUstate(state)
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_the_algebraic_loop_pair_feeds_through(fmus):
    a, b = algebraic_loop_specs()["GainA"], algebraic_loop_specs()["GainB"]
    md = read_model_description(str(fmus["GainA"]))
    assert [(o.variable.name, [d.name for d in o.dependencies]) for o in md.outputs] == [("y", ["u"])]
    for spec in (a, b):
        result = simulated(fmus[spec.model_identifier], fmi_type="CoSimulation", start_values={"u": 2.0},
                           stop_time=0.1, output_interval=0.1)
        k, offset = (v.start for v in spec.variables[:2])
        assert list(result["y"]) == [k * 2.0 + offset] * 2


def test_the_monolithic_reference_reaches_the_motor_s_steady_state():
    """At rest after the start-up: k i = b w + tau_load and R i = V0 - k w, so
    w = (k V0 - R tau_load) / (k^2 + b R)."""
    p = DC_MOTOR
    x = dc_motor_reference(np.array([0.0, p["t_step"], 1.0]))
    assert (x[:2] == 0).all()
    w = (p["k"] * p["V0"] - p["R"] * p["tau_load"]) / (p["k"] ** 2 + p["b"] * p["R"])
    np.testing.assert_allclose(x[2, [0, 2]], [(p["V0"] - p["k"] * w) / p["R"], w], rtol=1e-8)
    np.testing.assert_allclose(dc_motor_rhs()(1.0, x[2]), [0, w, 0], atol=1e-5)
