"""Scenario files: the shipped missions load, and every bad value is refused
with a message naming the key and the value."""
from __future__ import annotations

import tomllib

import numpy as np
import pytest

from cosim.scenario import registry
from cosim.errors import ConnectionCheckError, ScenarioError
from cosim.scenario.definition import apply_overrides, load_scenario, parse_scenario, shipped_scenarios
from cosim.scenario.assembly import build_master


def _raw(name="circles"):
    return tomllib.loads(shipped_scenarios()[name].read_text())


@pytest.mark.parametrize("name", ["circles", "figure8"])
def test_shipped_scenarios_load_and_build(name):
    sc = load_scenario(name)
    assert sc.name == name and sc.step == 0.01
    with build_master(sc) as master:
        assert set(master.components) == {"Quadrotor", "WindGust", "reference", "controller"}
        assert len(master.connections) == 3 + 6 + 3 + 12 + 4  # wind, reference (p*, dp*/dt, d2p*/dt2), state, rotors


def test_paper_values_in_the_shipped_missions():
    circles = load_scenario("circles")
    assert circles.duration == 50.0
    assert circles.fmus["Quadrotor"]["parameters"]["z_0"] == -15.0
    assert {"dir_x": -1.0, "dir_y": -1.0, "dir_z": 0.0, "t_switch_1": 17.0,
            "t_switch_2": 34.0}.items() <= circles.fmus["WindGust"]["parameters"].items()
    assert circles.components["reference"] == {
        "kind": "two_circles", "parameters": {"radius": 10.0, "speed": 2.5, "climb": 5.0, "x0": 0.0, "y0": 0.0,
                                              "z0": -15.0}}
    eight = load_scenario("figure8")
    assert eight.fmus["WindGust"]["parameters"]["v_w"] == 2.0
    assert (eight.fmus["WindGust"]["parameters"]["dir_x"], eight.fmus["WindGust"]["parameters"]["dir_y"]) == (1.0, -1.0)
    assert eight.components["reference"]["parameters"]["max_speed"] == 1.0


@pytest.mark.parametrize("overrides, message", [
    ({"simulation.durration": 5.0},
     "simulation.durration: unknown key; known keys: coupling, duration, ordering, seed, start_time, step"),
    ({"simulation.duration": "long"}, "simulation.duration = 'long': expected a number"),
    ({"simulation.duration": -5.0}, "simulation.duration = -5.0: must be positive"),
    ({"simulation.step": 0.0}, "simulation.step = 0.0: must be positive"),
    ({"simulation.duration": 1.005}, "simulation.duration = 1.005: not a whole number of steps of 0.01 s"),
    ({"simulation.seed": 1.5}, "simulation.seed = 1.5: expected an integer"),
    ({"simulation.seed": -1}, "simulation.seed = -1: must not be negative"),
    ({"fmus.Quadrotor.parameters.m": -1.07}, "fmus.Quadrotor.parameters.m: m = -1.07 kg is outside its range [0.001, inf]"),
    ({"fmus.Quadrotor.parameters.mass": 1.0}, "fmus.Quadrotor.parameters.mass: Quadrotor has no parameter 'mass'"),
    ({"fmus.Quadrotor.parameters.x": 1.0}, "fmus.Quadrotor.parameters.x: 'x' is a state of Quadrotor, not a parameter"),
    ({"fmus.Quadrotor.parameters.Ix": float("nan")}, "fmus.Quadrotor.parameters.Ix = nan: expected a finite number"),
    ({"fmus.Quadrotor.model": "Hexacopter"}, "fmus.Quadrotor.model = 'Hexacopter': unknown model; known: "
                                         + ", ".join(sorted(registry.fmu_models()))),
    ({"fmus.Quadrotor.fmi_version": 1}, "fmus.Quadrotor.fmi_version = 1: expected 2 or 3"),
    ({"fmus.Quadrotor.path": "x.fmu"}, "fmus.Quadrotor: give exactly one of 'model'"),
    ({"wind.speed": -3.0}, "wind.speed = -3.0: must not be negative"),
    ({"wind.direction": [0.0, 0.0, 0.0]}, "wind.direction = [0.0, 0.0, 0.0]: must not be the zero vector"),
    ({"wind.direction": [1.0, 1.0]}, "wind.direction = [1.0, 1.0]: expected a list of 3 numbers"),
    ({"wind.switch_times": [34.0, 17.0]}, "the second switch must not come before the first"),
    ({"wind.fmu": "Breeze"}, "wind.fmu = 'Breeze': no such FMU in [fmus]"),
    ({"wind.gusty": True}, "wind.gusty: unknown key"),
    ({"trajectory.kind": "spiral"}, "trajectory.kind = 'spiral': expected one of hover, two_circles, figure_eight"),
    ({"trajectory.radius": -10.0}, "trajectory: radius = -10.0 must be positive"),
    ({"trajectory.diameter": 20.0}, "trajectory.diameter: unknown key"),
    ({"controller.variant": "pd+nn"}, "controller.variant = 'pd+nn': expected one of pd, pd+smc, pd+lm"),
    ({"controller.position.kq": 1.0}, "controller.position.kq: unknown key; known keys: kp, kd"),
    ({"controller.position.kp": "2.5"}, "controller.position.kp = '2.5': expected a number"),
    ({"controller.position.nu": [0.85, 0.85]}, "controller.position.nu = [0.85, 0.85]: expected a list of 3 values"),
    ({"controller.geometric.tilt_max": 2.0}, "GeometricParams.tilt_max = 2.0 rad is outside its range [1e-06, 1.5708]"),
    ({"record.signals": "Quadrotor.x"}, "record.signals = 'Quadrotor.x': expected a list of strings"),
    ({"envelope": {"Quadrotor.phi": [1.2, -1.2]}}, "envelope.Quadrotor.phi = [1.2, -1.2]: low must be below high"),
    ({"metrics.position": ["Quadrotor.x"]}, "metrics: position has 1 signals but reference has 3"),
    ({"colour": "red"}, "colour: unknown key"),
])
def test_bad_value_is_refused_naming_key_and_value(overrides, message):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(apply_overrides(_raw(), overrides))
    assert message in str(info.value)


def test_missing_connections_and_fmus():
    raw = _raw()
    del raw["connections"]
    assert parse_scenario(raw).connections == ()  # one FMU flown alone needs none
    with pytest.raises(ScenarioError, match=r"fmus: at least one \[fmus.<Name>\] table is required"):
        parse_scenario({"connections": []})


def test_unknown_variable_names_are_refused_when_building():
    raw = apply_overrides(_raw(), {"record.signals": ["Quadrotor.altitude"]})
    with pytest.raises(ConnectionCheckError, match="signal 'Quadrotor.altitude'"):
        build_master(parse_scenario(raw))
    raw = _raw()
    raw["connections"] = raw["connections"] + ["WindGust.v_wind_x -> controller.wind"]
    with pytest.raises(ConnectionCheckError, match="destination controller.wind does not exist"):
        build_master(parse_scenario(raw))


def test_bad_toml_is_reported_with_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[simulation\nduration = 5")
    with pytest.raises(ScenarioError, match="broken.toml: not valid TOML"):
        load_scenario(path)
    with pytest.raises(ScenarioError, match="no such file, and not a shipped scenario"):
        load_scenario(tmp_path / "absent.toml")


def test_overrides_and_wind_shorthand():
    sc = load_scenario("circles", {"wind.speed": 5.0, "simulation.duration": 2.0})
    assert sc.fmus["WindGust"]["parameters"]["v_w"] == 5.0 and sc.duration == 2.0
    assert sc.sections["wind"] == {"fmu": "WindGust"}


def test_custom_python_component_from_a_factory(tmp_path):
    raw = _raw()
    raw["components"] = {"probe": {"factory": "quadrotor_paper.controller_component:ControllerComponent", "variant": "pd"}}
    # the factory is called with name= and the parameters; its inputs are then unconnected
    with pytest.raises(ConnectionCheckError, match="inputs of probe not connected: x_ref"):
        build_master(parse_scenario(raw))
    raw["components"] = {"probe": {"factory": "no_such_module:Thing"}}
    with pytest.raises(ScenarioError, match="components.probe.factory = 'no_such_module:Thing'"):
        build_master(parse_scenario(raw))


def test_the_sensors_scenario_puts_the_sensor_and_link_fmus_in_both_paths():
    sc = load_scenario("circles_sensors")
    with build_master(sc) as master:
        assert set(master.components) == {"Quadrotor", "WindGust", "reference", "controller", "Sensors", "Link"}
        assert len(master.connections) == 3 + 6 + 3 + 12 + 12 + 4 + 4
    assert sc.fmus["Sensors"]["seed_parameter"] == "seed"
    assert sc.fmus["Link"]["parameters"]["delay_steps"] == 1


def test_the_sensors_scenario_is_reproducible_by_its_seed():
    def fly(seed):
        with build_master(load_scenario("circles_sensors", {"simulation.duration": 2.0})) as master:
            result = master.run(2.0, seed=seed)
        assert result.status == "ok"
        return np.asarray(result.data)

    first, again, other = fly(0), fly(0), fly(1)
    np.testing.assert_array_equal(first, again)
    assert np.abs(first - other).max() > 1e-6


@pytest.mark.parametrize("key, value, message", [
    ("fmus.Link.parameters.delay_steps", 1.5, "fmus.Link.parameters.delay_steps: delay_steps = 1.5 is not a whole number"),
    ("fmus.Sensors.parameters.sample_rate", -1.0, "sample_rate = -1.0 1/s is outside its range"),
    ("fmus.Link.parameters.loss_probability", 1.5, "loss_probability = 1.5 is outside its range [0.0, 1.0]"),
])
def test_a_count_or_probability_the_sensors_would_refuse_is_refused_by_the_scenario(key, value, message):
    """Whole numbers (Variable.integer) and dimensionless ranges are checked
    when the scenario is read, as the FMU would check them at start."""
    with pytest.raises(ScenarioError) as info:
        load_scenario("circles_sensors", {key: value})
    assert message in str(info.value)


def test_with_every_realism_off_the_sensors_scenario_flies_the_clean_circles_bit_for_bit():
    """No noise, a sample every step, no delay, no motor lag: the sensor and
    link FMUs pass the values through exactly, so the flight is the clean
    one (Table 2's numbers stay what they were)."""
    off = {f"fmus.Sensors.parameters.sigma_{n}": 0.0 for n in ("x", "y", "z", "u", "v", "w", "phi", "theta",
                                                                  "psi", "p", "q", "r")}
    off.update({"fmus.Sensors.parameters.sample_rate": 0.0, "fmus.Link.parameters.delay_steps": 0,
                "fmus.Quadrotor.parameters.tau_m": 0.0})
    runs = {}
    for name, overrides in (("circles", {}), ("circles_sensors", off)):
        sc = load_scenario(name, {"simulation.duration": 5.0, "record.signals": ["Quadrotor.x", "Quadrotor.z",
                                                                                "controller.Omega_1"], **overrides})
        with build_master(sc) as master:
            runs[name] = master.run(sc.duration, seed=3)
    for signal in ("Quadrotor.x", "Quadrotor.z", "controller.Omega_1"):
        assert np.array_equal(runs["circles"][signal], runs["circles_sensors"][signal]), signal
