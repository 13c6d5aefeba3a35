"""The writer of industrial-style FMUs (tests/industrial_fmus.py) makes FMUs that fmpy validates and
flies: the mechanical part of the DC motor against its analytic solution in Model Exchange, its
Co-Simulation off Model Exchange by forward Euler's first-order error (and on the solution by RK4),
the source's time event at t_step, the bouncing mass's state event, FMU states, directional
derivatives and an error logged through the FMI calls; the DC motor's right-hand side against its
exact solution."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from tests.catalog_fmus import extracted, simulated
from tests.fmus.fmi2_harness import LogCollector
from tests.industrial_fmus import (DC_MOTOR, algebraic_loop_specs, bouncing_mass_spec, dc_motor_exact,
                                   dc_motor_rhs, dc_motor_specs)

TAU = 0.02  # N.m, the constant driving torque of the mechanical part alone


@pytest.fixture(scope="module")
def fmus(industrial_fmus):
    """Every ready-made FMU (the DC motor's mechanical part also with Co-Simulation, by Euler and by
    RK4; its source also smooth)."""
    specs = {**dc_motor_specs(), "BouncingMass": bouncing_mass_spec(), **algebraic_loop_specs()}
    built = {name: industrial_fmus(spec) for name, spec in specs.items()}
    cs = dc_motor_specs(interfaces=("ModelExchange", "CoSimulation"))["DCMotor_Mechanical"]
    built["DCMotor_Mechanical+CS"] = industrial_fmus(cs)
    built["DCMotor_Mechanical+RK4"] = industrial_fmus(replace(cs, cs_solver="rk4", fixed_step=0.01))
    built["DCMotor_Source(smooth)"] = industrial_fmus(dc_motor_specs(source="smooth")["DCMotor_Source"])
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


def test_co_simulation_by_rk4_lands_on_the_analytic_solution(fmus):
    """RK4 at h = 0.01 s on the rate b/J = 0.1/s: a local error of (r h)^5/120 ~ 1e-17 of w_ss a step,
    where forward Euler at that step would be off by 5e-4 of it."""
    result = simulated(fmus["DCMotor_Mechanical+RK4"], fmi_type="CoSimulation", start_values={"flange.tau": TAU},
                       stop_time=1.0, output_interval=0.1)
    w, phi = _mechanical_exact(result["time"])
    np.testing.assert_allclose(result["w"], w, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(result["phi"], phi, rtol=1e-12, atol=1e-12)


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
    me = result[result["time"] != events[0]]
    # Co-Simulation: forward Euler at 1 ms, the bounce at the end of the sub-step where the height
    # crossed 0: off by h g t / 2 (3 mm at 0.6 s) and the bounce's lateness (at most h v = 4.4 mm)
    cs = simulated(fmus["BouncingMass"], fmi_type="CoSimulation", stop_time=0.6, output_interval=0.1)
    np.testing.assert_allclose(cs["mass.s"], me["mass.s"], rtol=0, atol=0.0075)
    assert cs["mass.s"][-1] > cs["mass.s"][-2]  # it came back up


def test_fmu_state_and_directional_derivatives_through_the_fmi_calls(fmus):
    path = fmus["DCMotor_Electrical"]
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extracted(path), modelIdentifier="DCMotor_Electrical",
                    instanceName="electrical")
    log = LogCollector()
    fmu.instantiate(callbacks=log.callbacks)
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
        with pytest.raises(FMICallException):  # a fixed parameter after initialization
            fmu.setReal([vr["R"]], [2.0])
        assert log.messages[-1] == "fmi2SetReal: R (value reference 0) cannot be set in Event Mode"
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


def test_the_monolithic_right_hand_side_and_its_exact_solution():
    """solve_ivp of the right-hand side across the step agrees with the exact solution, which comes
    to rest where k i = b w + tau_load and R i = V0 - k w: w = (k V0 - R tau_load) / (k^2 + b R)."""
    p = DC_MOTOR
    f = dc_motor_rhs()
    times = np.array([0.0, 0.005, p["t_step"], 0.02, 0.03])
    exact = dc_motor_exact(times)
    assert (exact[:3] == 0).all()  # at rest until the step
    jacobian = np.array([[-p["R"] / p["L"], 0, -p["k"] / p["L"]], [0, 0, 1], [p["k"] / p["J"], 0, -p["b"] / p["J"]]])
    after = solve_ivp(f, (p["t_step"], times[-1]), np.zeros(3), method="BDF", t_eval=times[2:], rtol=1e-10,
                      atol=1e-12, jac=jacobian, args=(p["V0"],))
    np.testing.assert_allclose(after.y.T, exact[2:], rtol=1e-7, atol=1e-9)
    w = (p["k"] * p["V0"] - p["R"] * p["tau_load"]) / (p["k"] ** 2 + p["b"] * p["R"])
    rest = dc_motor_exact([2.0])[0]
    # i = (V0 - k w)/R cancels some 2.5 digits (12 - 11.95)
    np.testing.assert_allclose(rest[[0, 2]], [(p["V0"] - p["k"] * w) / p["R"], w], rtol=1e-10)
    np.testing.assert_allclose(f(2.0, rest), [0, w, 0], atol=1e-6)  # di/dt against V0/L = 2.4e4 A/s
    smooth = dc_motor_exact([0.0, 0.01], source="smooth")
    smooth_ivp = solve_ivp(dc_motor_rhs("smooth"), (0.0, 0.01), np.zeros(3), method="BDF", rtol=1e-10, atol=1e-12,
                           jac=jacobian).y[:, -1]
    np.testing.assert_allclose(smooth[1], smooth_ivp, rtol=1e-7, atol=1e-9)
