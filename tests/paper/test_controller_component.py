"""The controller as a co-simulation component: its nominal vehicle tied to
the plant FMU by default, a mismatch only when the scenario names it; its
learned state published as internal signals that record like outputs."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cosim.errors import ScenarioError
from cosim.scenario.definition import load_scenario
from cosim.scenario.assembly import build_master
from fmu_models.models.quadrotor import DEFAULTS
from fnn_controller import VehicleParams, initial_state, variant
from fnn_controller.fnn import AXIS_STATE_PORTS, F
from quadrotor_paper.controller_component import ControllerComponent


def _vehicle(overrides=None) -> VehicleParams:
    """The nominal vehicle the controller FMU is given (its ``vehicle.*`` parameters)."""
    sc = load_scenario("circles", {"simulation.duration": 0.1, **(overrides or {})})
    with build_master(sc) as master:
        given = master.components["controller"].base_parameters
    return VehicleParams(**{f.name: given[f"vehicle.{f.name}"] for f in dataclasses.fields(VehicleParams)})


# a plant unlike the controller's defaults in every field the nominal vehicle has
OTHER_PLANT = {"m": 1.31, "g": 9.79, "Ix": 0.033, "Iy": 0.047, "Iz": 0.025, "l": 0.19, "b": 7.1e-6, "d": 1.9e-7,
               "Omega_max": 950.0, "arm_angle": 0.7853981633974483}


def test_the_nominal_vehicle_is_the_plants():
    """Every field of the nominal vehicle is read from the plant: the plant's
    values differ from the controller's defaults in each, so nothing else
    passes."""
    assert set(OTHER_PLANT) == {f.name for f in dataclasses.fields(VehicleParams)}
    assert all(OTHER_PLANT[k] != DEFAULTS[k] for k in OTHER_PLANT)
    vehicle = _vehicle({f"fmus.Quadrotor.parameters.{k}": v for k, v in OTHER_PLANT.items()})
    assert dataclasses.asdict(vehicle) == OTHER_PLANT


def test_a_parameter_set_that_makes_the_plant_an_x_makes_the_mixer_an_x(tmp_path):
    """The plant's parameter_set (.ssv) reaches the controller's nominal vehicle:
    an X plant gets an X mixer with no other setting."""
    from cosim.calibration.outputs import write_parameter_set

    ssv = write_parameter_set({"arm_angle": (0.7853981633974483, "rad"), "m": (1.2, "kg")}, tmp_path / "x.ssv", "X")
    vehicle = _vehicle({"fmus.Quadrotor.parameter_set": str(ssv)})
    assert (vehicle.arm_angle, vehicle.m, vehicle.b) == (0.7853981633974483, 1.2, DEFAULTS["b"])


def test_a_heavier_plant_makes_a_heavier_nominal_model():
    vehicle = _vehicle({"fmus.Quadrotor.parameters.m": 1.3, "fmus.Quadrotor.parameters.Ix": 0.05})
    assert (vehicle.m, vehicle.Ix, vehicle.Iy) == (1.3, 0.05, DEFAULTS["Iy"])


def test_a_mismatch_is_a_named_setting():
    vehicle = _vehicle({"fmus.Quadrotor.parameters.m": 1.3, "controller.nominal": {"m": 1.07, "b": 7e-6}})
    assert (vehicle.m, vehicle.b, vehicle.Iz) == (1.07, 7e-6, DEFAULTS["Iz"])


@pytest.mark.parametrize("overrides, message", [
    ({"controller.nominal": {"mass": 1.0}}, "controller.nominal.mass: unknown key"),
    ({"controller.plant": "Hexacopter"}, "controller.plant = 'Hexacopter': no such FMU in [fmus]"),
    ({"controller.geometric": {"vehicle": {"m": 2.0}}}, "controller.geometric.vehicle: the nominal vehicle is the plant's"),
])
def test_a_wrong_tie_is_refused_naming_the_key(overrides, message):
    with pytest.raises(ScenarioError, match=message.replace("[", r"\[").replace("]", r"\]")):
        sc = load_scenario("circles", overrides)
        build_master(sc).close()


def test_the_learned_state_records_like_an_output():
    """Both forms record the learned state by the same names, bit for bit: at
    t_n the state the control at t_n was computed with (the FMU's local
    variables), so at t0 the seed's f_ij(0)."""
    names = [f"controller.{name}_{axis}" for axis in "xyz" for name, _ in AXIS_STATE_PORTS]
    learned = {}
    for form in ("fmu", "python"):
        sc = load_scenario("circles", {"simulation.duration": 1.0, "record.signals": ["Quadrotor.x"] + names,
                                       "controller.form": form})
        with build_master(sc) as master:
            result = master.run(sc.duration, seed=3)
        learned[form] = np.column_stack([result[n] for n in names])
        assert result.units[result.columns.index("controller.f_11_x")] == "m/s"
    position = ControllerComponent.from_parameters("controller", sc.components["controller"]["parameters"]).position
    start = initial_state(variant("pd+lm"), 3, position)[:len(names)]
    np.testing.assert_array_equal(learned["fmu"], learned["python"])
    np.testing.assert_array_equal(learned["fmu"][0], start)
    f_x = slice(F.start, F.stop)
    assert not np.allclose(learned["fmu"][-1, f_x], start[f_x])  # the FNN of x has learned in 1 s
    assert np.all(np.isfinite(learned["fmu"]))


@pytest.mark.parametrize("ordering", ["feedthrough", "exchange"])
def test_the_controller_as_its_fmu_flies_as_the_python_path(ordering):
    """A scenario chooses the controller's form; under the same step semantics
    both give the same trajectory (bit for bit here; 1e-9 m is the promise)."""
    runs = {}
    for form in ("python", "fmu"):
        sc = load_scenario("circles", {"controller.form": form, "simulation.ordering": ordering,
                                       "simulation.duration": 10.0})
        with build_master(sc) as master:
            kinds = {type(c).__name__ for c in master.fmus}
            runs[form] = master.run(sc.duration, seed=4)
        assert ("LearnedControllerFmu" in kinds) == (form == "fmu")
    for name in ("Quadrotor.x", "Quadrotor.y", "Quadrotor.z", "controller.tau_n_x", "controller.Omega_1"):
        assert np.max(np.abs(runs["python"][name] - runs["fmu"][name])) <= 1e-9, name


def test_in_the_exchange_ordering_a_python_controller_behind_a_sensor_fmu_starts_from_the_plant():
    """At t0 the sensor FMU (direct feedthrough) must pass the plant's initial
    state on before the Python controller's first step, as libcosim's initial
    transfer does for the controller FMU: both forms then fly alike (before
    the fix the Python form read the sensor's zero start inputs, commanded
    full rotor speed and ended 0.27 m apart in z)."""
    runs = {}
    for form in ("python", "fmu"):
        sc = load_scenario("circles_sensors", {"controller.form": form, "simulation.ordering": "exchange",
                                               "simulation.duration": 2.0,
                                               "record.signals": ["Quadrotor.z", "controller.Omega_1"]})
        with build_master(sc) as master:
            runs[form] = master.run(sc.duration, seed=1)
    assert runs["python"]["controller.Omega_1"][0] == runs["fmu"]["controller.Omega_1"][0]
    assert np.max(np.abs(runs["python"]["Quadrotor.z"] - runs["fmu"]["Quadrotor.z"])) <= 1e-9
