"""The controller FMUs (one per variant, FMI 2.0 and 3.0 Co-Simulation):
generated from the very function the Python fast path evaluates, so the two
agree bit for bit; sample-and-hold outputs; learned state kept in FMU state;
refusals that name the variable and the value."""
from __future__ import annotations

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from tests.catalog_fmus import fmpy_class, loaded
from tests.fmu_validation import validate_fmu

import fnn_controller as fc
from cosim.fmi.lifecycle import fmi2_callbacks
from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import STATE_NAMES
from fnn_controller.step import OUTPUTS
from fnn_controller.controller_fmu import ACCELERATION_INPUTS, REFERENCE_INPUTS, controller_model, fmu_identifier
from fnn_controller.parametric import parameter_table, parameter_vector, parametric_step_function

INPUTS = [name for name, _, _ in REFERENCE_INPUTS] + list(STATE_NAMES) + [name for name, _, _ in ACCELERATION_INPUTS]
PSI_REF = 0.3  # rad: the commanded yaw, a parameter held for the run (not the default 0: it acts)
OUTS = [name for name, _, _ in OUTPUTS]


class Log:
    def __init__(self):
        self.messages = []

    def receive(self, status, message):
        self.messages.append(message.decode() if isinstance(message, bytes) else str(message))


class Controller:
    """One instance of a controller FMU, FMI 2.0 or 3.0, through fmpy."""

    def __init__(self, variant: str, version: int, parameters=None):
        path = cached_fmu(controller_model(variant), version)
        self.md, folder = loaded(path)  # one reading and one folder for the process's instances
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.log = Log()
        common = dict(guid=self.md.guid, unzipDirectory=folder,
                      modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="controller")
        if version == 2:
            self.fmu = fmpy_class(FMU2Slave)(**common)  # signatures once per process, as a run
            self._callbacks = fmi2_callbacks(self.log.receive)
            self.fmu.instantiate(callbacks=self._callbacks)
            self.set, self.get = self.fmu.setReal, self.fmu.getReal
        else:
            self.fmu = fmpy_class(FMU3Slave)(**common)
            self.fmu.instantiate(logMessage=lambda env, status, cat, msg: self.log.receive(status, msg))
            self.set, self.get = self.fmu.setFloat64, self.fmu.getFloat64
        self.version = version
        for name, value in {"psi_ref": PSI_REF, **(parameters or {})}.items():
            self.set([self.vr[name]], [float(value)])
        if version == 2:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def outputs(self, u) -> np.ndarray:
        assert u[6] == PSI_REF  # the step's psi_ref argument is the FMU's parameter
        self.set([self.vr[n] for n in INPUTS], list(u[:6]) + list(u[7:]))
        return np.array(self.get([self.vr[n] for n in OUTS]))

    def step(self, t: float, h: float = 0.01) -> None:
        self.fmu.doStep(t, h)

    def values(self, names) -> np.ndarray:
        return np.array(self.get([self.vr[n] for n in names]))


def _inputs(rng) -> np.ndarray:
    """x_ref..vz_ref, psi_ref (:data:`PSI_REF`), the 12 plant states, ax_ref..az_ref: the step's arguments."""
    rng.uniform(-1, 1)  # the draw psi_ref had when it was an input: the other inputs stay as they were
    return np.r_[rng.normal(size=3), rng.normal(size=3), PSI_REF, rng.normal(size=6),
                 rng.normal(size=3) * 0.3, rng.normal(size=3), rng.normal(size=3)]


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("variant", fc.variant_names())
def test_every_variant_builds_and_validates(variant, version):
    path = cached_fmu(controller_model(variant), version)
    assert path.name == f"{fmu_identifier(variant)}.fmu"
    assert validate_fmu(str(path)) == []


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("variant", ["pd+smc", "pd+lm"])
def test_the_fmu_is_the_python_fast_path_bit_for_bit(variant, version):
    """Same inputs, same seed: identical outputs at every step, held over the
    step, and the same learned state."""
    ctrl = Controller(variant, version, {"seed": 7})
    f, p = parametric_step_function(variant), parameter_vector(variant)
    state = fc.initial_state(fc.variant(variant), 7)
    rng = np.random.default_rng(0)
    for k in range(300):
        u = _inputs(rng)
        y, state_next, _ = f(u[0:3], u[3:6], u[7:19], u[6], state, p, u[19:22])
        y = np.array(y).ravel()
        np.testing.assert_array_equal(ctrl.outputs(u), y)
        ctrl.step(k * 0.01)
        np.testing.assert_array_equal(ctrl.values(OUTS), y)  # sample and hold
        state = np.array(state_next).ravel()
    names = [f"{n}_{a}" for a in "xyz" for n, _ in fc.variant(variant).axis_state_ports]
    np.testing.assert_array_equal(ctrl.values(names), state[:len(names)])


@pytest.mark.parametrize("version", [2, 3])
def test_the_acceleration_feed_forward_is_the_python_fast_path_bit_for_bit(version):
    """With accel_feedforward = 1 the FMU's inputs ax_ref..az_ref reach the
    desired force exactly as in Python; with 0 (the default) they change nothing."""
    ctrl = Controller("pd+lm", version, {"seed": 3, "accel_feedforward": 1.0})
    paper = Controller("pd+lm", version, {"seed": 3})
    position = fc.PositionParams(accel_feedforward=1.0)
    f, p = parametric_step_function("pd+lm"), parameter_vector("pd+lm", position)
    state = fc.initial_state(fc.variant("pd+lm"), 3, position)
    rng = np.random.default_rng(4)
    for k in range(50):
        u = _inputs(rng)
        y, state_next, _ = f(u[0:3], u[3:6], u[7:19], u[6], state, p, u[19:22])
        np.testing.assert_array_equal(ctrl.outputs(u), np.array(y).ravel())
        without = u.copy()
        without[19:22] = 0.0
        assert not np.array_equal(ctrl.outputs(u), paper.outputs(u))  # the acceleration acts
        np.testing.assert_array_equal(paper.outputs(u), paper.outputs(without))  # ... only with the option
        ctrl.step(k * 0.01)
        paper.step(k * 0.01)
        state = np.array(state_next).ravel()


def test_the_seed_draws_f_ij_0_as_numpy_does():
    ctrl = Controller("pd+lm", 2, {"seed": 12345})
    expected = fc.initial_state(fc.variant("pd+lm"), 12345)
    names = [f"f_{i}{j}_{a}" for a in "xyz" for j in (1, 2, 3) for i in (1, 2, 3)]
    f_slice = np.r_[12:21, 37:46, 62:71]
    np.testing.assert_array_equal(ctrl.values(names), expected[f_slice])


def test_parameters_with_units_ranges_and_descriptions():
    md = read_model_description(str(cached_fmu(controller_model("pd+lm"), 2)))
    by_name = {v.name: v for v in md.modelVariables}
    for p in parameter_table("pd+lm"):
        v = by_name[p.name]
        assert v.causality == "parameter" and v.unit == p.unit and v.description
        assert float(v.start) == p.default
    assert by_name["gamma_lm_z"].unit == "m/s2" and float(by_name["kp"].start) == 2.5
    assert by_name["f_12_x"].causality == "local" and by_name["f_12_x"].variability == "discrete"
    assert by_name["Omega_1"].causality == "output" and by_name["seed"].causality == "parameter"


@pytest.mark.parametrize("version", [2, 3])
def test_a_changed_gain_changes_the_control_as_in_python(version):
    ctrl = Controller("pd+lm", version, {"kp": 3.0, "vehicle.m": 1.2})
    position, geometric = fc.PositionParams(kp=3.0), fc.GeometricParams(vehicle=fc.VehicleParams(m=1.2))
    f = parametric_step_function("pd+lm")
    u = _inputs(np.random.default_rng(3))
    state = fc.initial_state(fc.variant("pd+lm"), 0, position)
    y = np.array(f(u[0:3], u[3:6], u[7:19], u[6], state, parameter_vector("pd+lm", position, geometric),
                   u[19:22])[0]).ravel()
    np.testing.assert_array_equal(ctrl.outputs(u), y)


@pytest.mark.parametrize("version", [2, 3])
def test_fmu_state_save_restore_and_serialize_resume_learning(version):
    ctrl = Controller("pd+lm", version)
    rng = np.random.default_rng(1)
    for k in range(50):
        ctrl.outputs(_inputs(rng))
        ctrl.step(k * 0.01)
    saved = ctrl.fmu.getFMUState()
    blob = ctrl.fmu.serializeFMUState(saved)
    later = []
    for k in range(50, 80):
        later.append(ctrl.outputs(_inputs(np.random.default_rng(k))))
        ctrl.step(k * 0.01)
    ctrl.fmu.setFMUState(ctrl.fmu.deserializeFMUState(blob))
    for k in range(50, 80):
        np.testing.assert_array_equal(ctrl.outputs(_inputs(np.random.default_rng(k))), later[k - 50])
        ctrl.step(k * 0.01)
    # restored into another instance, a run that starts at t = 0 continues the learning
    other = Controller("pd+lm", version)
    other.fmu.setFMUState(other.fmu.deserializeFMUState(blob))
    np.testing.assert_array_equal(other.outputs(_inputs(np.random.default_rng(50))), later[0])
    other.step(0.0)  # the clock re-bases: a sampled-data controller does not depend on time
    np.testing.assert_array_equal(other.outputs(_inputs(np.random.default_rng(51))), later[1])


@pytest.mark.parametrize("version", [2, 3])
def test_refusals_name_the_variable_and_the_value_and_the_instance_survives(version):
    ctrl = Controller("pd+lm", version)
    if version == 2:  # the FMI 3.0 controller is clocked: any step (tests/fmus/test_clocked_fmu.py)
        with pytest.raises(FMICallException):
            ctrl.step(0.0, 0.02)
        assert any("communication step size = 0.02" in m and "dt = 0.01" in m for m in ctrl.log.messages)
    with pytest.raises(FMICallException):
        ctrl.set([ctrl.vr["x"]], [float("nan")])
    assert any("x = nan refused" in m for m in ctrl.log.messages)
    with pytest.raises(FMICallException):
        ctrl.set([ctrl.vr["f_11_x"]], [float("nan")])  # a discrete state is settable between steps, not to NaN
    assert any("f_11_x = nan refused" in m for m in ctrl.log.messages)
    ctrl.outputs(_inputs(np.random.default_rng(0)))
    ctrl.step(0.0)  # still usable
    with pytest.raises(FMICallException):
        Controller("pd+lm", version, {"bounds.f_max": -1.0})
    with pytest.raises(FMICallException):
        Controller("pd+lm", version, {"seed": 1.5})
