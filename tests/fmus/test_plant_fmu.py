"""The quadrotor plant FMU (FMI 2.0): validity, physics, numerics, API robustness."""
from __future__ import annotations

import math
import sys
from ctypes import POINTER, byref, c_double

import casadi as ca
import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2CoSimulation
from tests.fmu_validation import validate_fmu
from tests.catalog_fmus import catalog_fmu, extracted, simulated

from fmu_models.export.build import cached_fmu
from fmu_models.export.model import FmuModel
from fmu_models.catalog import MODELS
from fmu_models.models.quadrotor import DEFAULTS, QUADROTOR, ROTOR_STATE_NAMES, STATE_NAMES, hover_rotor_speed
from fmi2_harness import STATES, Fmi2Instance, LogCollector, logged, model_description

HOVER = hover_rotor_speed()
ROTORS_AT_HOVER = {f"Omega_{i}": HOVER for i in range(1, 5)}
ALL_STATES = [v.name for v in QUADROTOR.states]  # the 12 rigid-body states, then the 4 rotor speeds
TAU_M = 0.02  # s, a typical small-quadrotor motor
# fmpy's CMakeLists (fmpy/c-code) enables C++ as well as C (project() without LANGUAGES), and CMake
# checks that compiler by compiling and linking test programs: about 0.3 s of CPU of a configure. No
# source of an FMU of ours is C++ (buildDescription.xml: C99), so fmpy's builds here take it unchecked.
CXX_UNCHECKED = {"CMAKE_CXX_COMPILER_FORCED:BOOL": "TRUE"}


@pytest.fixture(scope="module")
def quadrotor_folder(quadrotor_fmu2):
    """The FMI 2.0 plant extracted once for the module: every instance of
    :func:`instance` loads the one library, as the instances of a process
    do in a run (each extracted a copy of its own, about 12 ms)."""
    return extracted(quadrotor_fmu2)


@pytest.fixture
def instance(quadrotor_fmu2, quadrotor_folder):
    instances = []

    def make(**kwargs):
        inst = Fmi2Instance(quadrotor_fmu2, unzip_dir=quadrotor_folder, **kwargs)
        instances.append(inst)
        return inst

    yield make
    for inst in instances:
        inst.close()


def test_fmu_validates_with_no_problems(quadrotor_fmu2):
    assert validate_fmu(str(quadrotor_fmu2)) == []


def test_hover_at_analytic_rotor_speed_holds_position_for_10_s(quadrotor_fmu2):
    result = simulated(quadrotor_fmu2, stop_time=10.0, output_interval=0.01,
                          start_values={"z_0": -15.0, **ROTORS_AT_HOVER})
    assert result["time"][-1] == pytest.approx(10.0)
    drift = np.sqrt(result["x"] ** 2 + result["y"] ** 2 + (result["z"] + 15.0) ** 2)
    assert drift.max() < 1e-9


def test_free_fall_matches_g_t_squared_over_two(instance):
    fmu = instance(parameters={"k_drag_lin": 0.0, "k_drag_quad": 0.0})
    fmu.set(**{f"Omega_{i}": 0.0 for i in range(1, 5)})
    fmu.step(200)  # 2 s
    z, w, t = *fmu.get("z", "w"), 2.0
    g = DEFAULTS["g"]
    assert z == pytest.approx(g * t**2 / 2, abs=1e-9)  # z points down: falling is +z
    assert w == pytest.approx(g * t, abs=1e-9)


def _input_sequence(n_steps, dt):
    """A varied, piecewise-constant input sequence: rotor speeds swinging
    around hover with different phases, and a changing wind."""
    t = np.arange(n_steps) * dt
    rotors = [HOVER * (1 + 0.02 * np.sin(2.1 * t + k) + 0.01 * np.sin(7.3 * t * (k + 1))) for k in range(4)]
    wind = [3 * np.sin(0.5 * t), -2 * np.cos(0.3 * t), 0.5 * np.sin(1.7 * t)]
    return np.column_stack(rotors + wind)


@pytest.mark.parametrize("tau_m", [0.0, TAU_M])
def test_trajectory_matches_independent_cvodes_integration(instance, tau_m):
    """The FMU's RK4 (internal step 1 ms) against CasADi's CVODES (BDF,
    tolerance 1e-12) on the same CasADi model, inputs held over each 10 ms,
    with instantaneous rotors and with the motor lag (all 16 states)."""
    dt, n = 0.01, 300
    inputs = _input_sequence(n, dt)
    p = QUADROTOR.parameter_values(z_0=-15.0, tau_m=tau_m)
    fmu = instance(parameters={"z_0": -15.0, "tau_m": tau_m})
    names = [v.name for v in QUADROTOR.inputs]

    s = QUADROTOR.symbols
    f = QUADROTOR.functions["ode"]
    integrator = ca.integrator("reference", "cvodes",
                               {"x": s["x"], "p": ca.vertcat(s["u"], s["p"]),
                                "ode": f(0, s["x"], s["u"], s["p"])},
                               0.0, dt, {"abstol": 1e-12, "reltol": 1e-12})
    x_ref = np.array(QUADROTOR.functions["init"](p)).ravel()
    worst = worst_rotor = 0.0
    for k in range(n):
        fmu.set(**dict(zip(names, inputs[k])))
        fmu.step()
        x_ref = np.array(integrator(x0=x_ref, p=np.concatenate([inputs[k], p]))["xf"]).ravel()
        error = np.abs(fmu.get(*ALL_STATES) - x_ref)
        worst = max(worst, error[:12].max())
        worst_rotor = max(worst_rotor, error[12:].max())
    # the trajectory really moved (not a trivial agreement at hover)
    assert np.abs(x_ref[:3] - [0, 0, -15]).max() > 0.5
    assert worst < 1e-8
    # RK4 on the lag: relative error (h/tau_m)^4 / 120 = 5e-8 per tau_m of the
    # jump in the command, a few rad/s every 10 ms here
    assert worst_rotor < 1e-9 * HOVER


def _steps_from_hover(instance, n_steps=50, **inputs):
    fmu = instance(parameters={"z_0": -15.0})
    fmu.set(**{**ROTORS_AT_HOVER, **inputs})
    fmu.step(n_steps)
    return dict(zip(STATES, fmu.get(*STATES))), dict(zip(("T", "tau_phi", "tau_theta", "tau_psi"),
                                                         fmu.get("T", "tau_phi", "tau_theta", "tau_psi")))


def test_more_thrust_climbs_that_is_moves_towards_negative_z(instance):
    state, applied = _steps_from_hover(instance, **{f"Omega_{i}": HOVER * 1.05 for i in range(1, 5)})
    assert applied["T"] > DEFAULTS["m"] * DEFAULTS["g"]
    assert state["w"] < 0 and state["z"] < -15.0


def test_front_rotor_pitches_nose_up_and_vehicle_moves_backwards(instance):
    state, applied = _steps_from_hover(instance, n_steps=60, Omega_1=HOVER * 1.02, Omega_3=HOVER * 0.98)
    assert applied["tau_theta"] > 0
    assert state["q"] > 0 and state["theta"] > 0
    assert state["u"] < 0  # tilted thrust points aft (eq. 10 with theta > 0)


def test_left_rotor_rolls_right_wing_down_and_vehicle_moves_right(instance):
    state, applied = _steps_from_hover(instance, n_steps=60, Omega_4=HOVER * 1.02, Omega_2=HOVER * 0.98)
    assert applied["tau_phi"] > 0
    assert state["p"] > 0 and state["phi"] > 0
    assert state["v"] > 0  # east, i.e. +y_W


def test_yaw_torque_turns_heading(instance):
    state, applied = _steps_from_hover(instance, Omega_2=HOVER * 1.02, Omega_4=HOVER * 1.02,
                                       Omega_1=HOVER * 0.98, Omega_3=HOVER * 0.98)
    assert applied["tau_psi"] > 0
    assert state["r"] > 0 and state["psi"] > 0
    assert abs(state["phi"]) < 1e-9 and abs(state["theta"]) < 1e-9


def test_wind_drag_pushes_the_vehicle_downwind(instance):
    state, _ = _steps_from_hover(instance, n_steps=100, wind_x=5.0, wind_y=-3.0)
    assert state["u"] > 0 and state["v"] < 0
    assert state["x"] > 0 and state["y"] < 0


def test_rotor_speeds_are_saturated_to_zero_and_omega_max(instance):
    _, applied = _steps_from_hover(instance, n_steps=1, **{f"Omega_{i}": 5000.0 for i in range(1, 5)})
    assert applied["T"] == pytest.approx(4 * DEFAULTS["b"] * DEFAULTS["Omega_max"] ** 2)
    _, applied = _steps_from_hover(instance, n_steps=1, **{f"Omega_{i}": -100.0 for i in range(1, 5)})
    assert applied["T"] == 0.0


@pytest.mark.parametrize("tau_m", [0.0, TAU_M])
def test_directional_derivatives_agree_with_finite_differences(quadrotor_fmu2, tau_m):
    """A and B of the linearization (Model Exchange: d der(x) / d[x, u]) and
    the feedthrough d y / d u, against central differences of the FMU itself,
    over all 16 states: with tau_m = 0 the rotor states have no effect and a
    zero derivative, with tau_m > 0 the thrust depends on them, not on the
    commands."""
    fmu = Fmi2Instance(quadrotor_fmu2, model_exchange=True, initialize=False)
    try:
        fmu.fmu.setupExperiment(startTime=0.0)
        fmu.set(tau_m=tau_m)
        fmu.fmu.enterInitializationMode()
        fmu.fmu.exitInitializationMode()
        fmu.fmu.enterContinuousTimeMode()

        def set_states(xv):
            xv = np.ascontiguousarray(xv, dtype=float)
            fmu.fmu.setContinuousStates(xv.ctypes.data_as(POINTER(c_double)), len(xv))

        x = np.array([1.0, -2.0, -15.0, 2.0, -1.0, 0.3, 0.2, -0.15, 0.7, 0.3, -0.2, 0.1,
                      610.0, 660.0, 615.0, 645.0])  # rotor speeds differ from the commands
        set_states(x)
        u = {"Omega_1": 600.0, "Omega_2": 650.0, "Omega_3": 620.0, "Omega_4": 640.0,
             "wind_x": 3.0, "wind_y": -1.0, "wind_z": 0.5}
        fmu.set(**u)
        derivatives = [f"der({s})" for s in ALL_STATES]
        unknowns = derivatives + ["T", "tau_phi", "tau_theta", "tau_psi", "x", "psi",
                                  "Omega_r_2"]  # states as outputs too
        knowns = list(ALL_STATES) + list(u)

        def evaluate(xv, uv):
            set_states(xv)
            fmu.set(**dict(zip(u, uv)))
            return fmu.get(*unknowns)

        u0 = np.array(list(u.values()))
        checked = 0
        for j, known in enumerate(knowns):
            seed = np.zeros(len(knowns))
            seed[j] = 1.0
            set_states(x)
            fmu.set(**u)
            ad = np.array(fmu.fmu.getDirectionalDerivative([fmu.vr[k] for k in unknowns], [fmu.vr[known]], [1.0]))
            step = 1e-6 * max(1.0, abs(np.concatenate([x, u0])[j]))
            if j < len(x):
                dx = np.zeros_like(x)
                dx[j] = step
                fd = (evaluate(x + dx, u0) - evaluate(x - dx, u0)) / (2 * step)
            else:
                du = np.zeros_like(u0)
                du[j - len(x)] = step
                fd = (evaluate(x, u0 + du) - evaluate(x, u0 - du)) / (2 * step)
            np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-6, err_msg=f"column d/d{known}")
            assert np.isfinite(ad).all()
            if known in ROTOR_STATE_NAMES and tau_m == 0:  # frozen and unused: only "Omega_r_2 = Omega_r_2"
                assert np.count_nonzero(ad) == (known == "Omega_r_2")
            if known.startswith("Omega_") and known not in ROTOR_STATE_NAMES:  # a command
                rows = dict(zip(unknowns, ad))
                if tau_m == 0:  # acts on the thrust at once
                    assert rows["T"] > 0 and rows[f"der(Omega_r_{known[-1]})"] == 0
                else:  # acts only through its rotor's speed
                    assert rows["T"] == 0 and rows[f"der(Omega_r_{known[-1]})"] == pytest.approx(1 / tau_m)
            checked += np.count_nonzero(ad)
        assert checked > 40  # the Jacobian is far from empty
    finally:
        fmu.close()


@pytest.mark.parametrize("tau_m", [0.0, TAU_M])
def test_saved_and_restored_state_reproduces_the_trajectory_exactly(instance, tau_m):
    fmu = instance(parameters={"z_0": -15.0, "tau_m": tau_m})
    names = [v.name for v in QUADROTOR.inputs]
    inputs = _input_sequence(200, 0.01)
    for k in range(100):
        fmu.set(**dict(zip(names, inputs[k])))
        fmu.step()
    saved = fmu.fmu.getFMUstate()
    serialized = fmu.fmu.serializeFMUstate(saved)

    def run_rest():
        fmu.n = 100
        for k in range(100, 200):
            fmu.set(**dict(zip(names, inputs[k])))
            fmu.step()
        return fmu.get(*ALL_STATES, "T", "tau_phi")

    first = run_rest()
    fmu.fmu.setFMUstate(saved)
    second = run_rest()
    restored = fmu.fmu.deSerializeFMUstate(serialized)
    fmu.fmu.setFMUstate(restored)
    third = run_rest()
    fmu.fmu.freeFMUstate(saved)
    fmu.fmu.freeFMUstate(restored)
    assert np.abs(first[:3] - [0, 0, -15]).max() > 0.1  # it moved
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(first, third)


def test_two_instances_do_not_interfere(instance, quadrotor_fmu2):
    names = [v.name for v in QUADROTOR.inputs]
    seq_a, seq_b = _input_sequence(100, 0.01), _input_sequence(100, 0.013)[:, ::-1].copy()
    seq_b[:, :4] = HOVER * 1.01

    def solo(seq, **params):
        fmu = instance(parameters=params)
        for row in seq:
            fmu.set(**dict(zip(names, row)))
            fmu.step()
        return fmu.get(*STATES)

    alone_a, alone_b = solo(seq_a, z_0=-15.0), solo(seq_b, m=1.3)
    a, b = instance(parameters={"z_0": -15.0}), instance(parameters={"m": 1.3})
    for row_a, row_b in zip(seq_a, seq_b):
        a.set(**dict(zip(names, row_a)))
        b.set(**dict(zip(names, row_b)))
        a.step()
        b.step()
    np.testing.assert_array_equal(a.get(*STATES), alone_a)
    np.testing.assert_array_equal(b.get(*STATES), alone_b)
    assert not np.allclose(alone_a, alone_b)


@pytest.mark.parametrize("name, value", [
    ("m", -1.0), ("m", 0.0), ("Ix", 0.0), ("Iz", -0.02), ("b", 0.0), ("Omega_max", -5.0),
    ("internal_step", 0.0), ("theta_0", 2.0), ("k_drag_lin", math.nan), ("g", math.inf),
])
def test_non_physical_parameters_are_refused_with_the_name_and_value(instance, name, value):
    fmu = instance(initialize=False)
    with pytest.raises(FMICallException):
        fmu.set(**{name: value})
    assert any(name in m and f"{value:g}" in m for m in fmu.messages), fmu.messages
    # the refused value did not stick and the instance still works
    fmu.initialize({})
    fmu.step(10)
    assert np.isfinite(fmu.get(*STATES)).all()


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_inputs_are_refused(instance, value):
    fmu = instance()
    with pytest.raises(FMICallException):
        fmu.set(Omega_2=value)
    assert any("Omega_2" in m and f"{value:g}" in m for m in fmu.messages), fmu.messages
    fmu.step(5)
    assert np.isfinite(fmu.get(*STATES)).all()


@pytest.mark.parametrize("h", [0.0, -0.01, math.nan])
def test_non_positive_step_size_is_refused(instance, h):
    fmu = instance()
    with pytest.raises(FMICallException):
        fmu.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=h)
    assert any("step size" in m and f"{h:g}" in m for m in fmu.messages), fmu.messages
    fmu.step(5)  # still usable


def test_calls_in_the_wrong_state_are_refused(instance):
    fmu = instance(initialize=False)
    with pytest.raises(FMICallException):
        fmu.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
    assert any("fmi2DoStep" in m and "Instantiated" in m for m in fmu.messages), fmu.messages
    fmu.initialize({})
    with pytest.raises(FMICallException):
        fmu.set(m=2.0)  # parameters are fixed after initialization
    assert any("parameter m" in m for m in fmu.messages)
    with pytest.raises(FMICallException):
        fmu.fmu.enterInitializationMode()
    with pytest.raises(FMICallException):
        fmu.fmu.doStep(currentCommunicationPoint=5.0, communicationStepSize=0.01)  # not where the FMU is
    assert any("t = 5" in m for m in fmu.messages)
    fmu.step(3)
    assert np.isfinite(fmu.get(*STATES)).all()


def test_a_value_read_before_initialization_and_a_stop_before_the_start_are_refused(instance):
    """issue 28: fmi2GetReal answered in Instantiated (nothing is computed yet),
    and fmi2SetupExperiment took a stop time before the start; each is now an
    error, the FMU's log naming the call."""
    fmu = instance(initialize=False)
    with pytest.raises(FMICallException):
        fmu.get("x")
    assert any("fmi2GetReal" in m and "Instantiated" in m for m in fmu.messages), fmu.messages
    with pytest.raises(FMICallException):
        fmu.fmu.setupExperiment(startTime=10.0, stopTime=1.0)
    assert any(m.startswith("fmi2SetupExperiment: stop time 1 refused: before the start time 10")
               for m in fmu.messages), fmu.messages
    fmu.initialize({})  # still usable
    fmu.step(2)
    assert np.isfinite(fmu.get(*STATES)).all()


def test_a_derivative_that_overflows_is_refused_naming_the_call(quadrotor_fmu2):
    """issue 28: at u = 1e308 (finite, so accepted) the drag overflows and
    fmi2GetDerivatives returned -inf with status OK; now an error whose log
    names the call, the derivative and the states."""
    fmu = Fmi2Instance(quadrotor_fmu2, model_exchange=True)
    try:
        fmu.fmu.enterContinuousTimeMode()
        n = len(fmu.md.derivatives)
        x = np.zeros(n)
        fmu.fmu.getContinuousStates(x.ctypes.data_as(POINTER(c_double)), n)
        x[STATE_NAMES.index("u")] = 1e308
        fmu.fmu.setContinuousStates(x.ctypes.data_as(POINTER(c_double)), n)
        dx = np.zeros(n)
        with pytest.raises(FMICallException):
            fmu.fmu.getDerivatives(dx.ctypes.data_as(POINTER(c_double)), n)
        assert any(m.startswith("fmi2GetDerivatives: der(u) = -inf") and "u = 1e+308" in m
                   for m in fmu.messages), fmu.messages
    finally:
        fmu.close()


def test_unknown_value_reference_is_refused(instance):
    fmu = instance()
    with pytest.raises(FMICallException):
        fmu.fmu.getReal([10_000])
    assert any("10000" in m for m in fmu.messages)


def _fail_a_step(instance):
    """Fly 10 steps at hover, save the FMU state, then make the next step
    overflow with a finite, admissible but absurd wind of 1e200 m/s (the wind
    inputs are unbounded; |v_rel|^2 in the drag overflows). Returns the
    instance, the saved state and the states before the failed step."""
    fmu = instance(parameters={"z_0": -15.0})
    fmu.set(**ROTORS_AT_HOVER)
    fmu.step(10)
    saved = fmu.fmu.getFMUstate()
    before = fmu.get(*STATES)
    fmu.set(wind_x=1e200)
    with pytest.raises(FMICallException):
        fmu.step()
    return fmu, saved, before


def test_a_diverging_step_is_reported_and_rolled_back(instance):
    """The step fails with the state's name, and the state and time before
    the step are kept."""
    fmu, saved, before = _fail_a_step(instance)
    assert any("became" in m for m in fmu.messages), fmu.messages
    np.testing.assert_array_equal(fmu.get(*STATES), before)
    assert fmu.get("time")[0] == 10 * fmu.h
    fmu.fmu.freeFMUstate(saved)


def test_the_diverging_step_message_names_time_inputs_and_parameters(instance):
    """The log alone says when the step failed and every input and parameter
    in effect, each value exact enough to reproduce the step."""
    fmu, saved, _ = _fail_a_step(instance)
    fmu.fmu.freeFMUstate(saved)
    message = next(m for m in fmu.messages if "became" in m)
    t0 = 10 * fmu.h
    assert f"during the step from t = {logged(t0)} to t = {logged(t0 + fmu.h)}" in message
    assert "wind_x = 1e+200" in message and f"Omega_1 = {logged(HOVER)}" in message
    assert f"m = {logged(DEFAULTS['m'])}" in message and "z_0 = -15" in message
    for v in QUADROTOR.inputs + QUADROTOR.parameters:  # all of them, none cut
        assert f" {v.name} = " in message, v.name
    assert not message.endswith("...")


def test_the_instance_survives_a_diverging_step(instance):
    """Further steps are refused until a saved state is restored or the
    instance is reset; then it flies again."""
    fmu, saved, before = _fail_a_step(instance)
    with pytest.raises(FMICallException):
        fmu.step()
    assert any("earlier step failed" in m for m in fmu.messages), fmu.messages

    fmu.fmu.setFMUstate(saved)
    fmu.fmu.freeFMUstate(saved)
    np.testing.assert_array_equal(fmu.get(*STATES), before)
    fmu.step(5)  # the saved state had no wind
    assert np.isfinite(fmu.get(*STATES)).all() and fmu.get("time")[0] == pytest.approx(15 * fmu.h)

    fmu.fmu.reset()
    fmu.n = 0
    fmu.initialize({"z_0": -15.0})
    fmu.step(5)
    assert np.isfinite(fmu.get(*STATES)).all() and fmu.get("wind_x")[0] == 0.0


def test_wrong_guid_is_refused_naming_both_guids(quadrotor_fmu2, tmp_path):
    """The message repeats the GUID given (bounded, "(null)" for NULL) and the
    FMU's own, as the FMI 3.0 layer does with the instantiation token."""
    guid = read_model_description(quadrotor_fmu2).guid
    unzipped = extract(quadrotor_fmu2, unzipdir=tmp_path)
    log = LogCollector()
    fmu = FMU2Slave(guid="{wrong}", unzipDirectory=unzipped, modelIdentifier="Quadrotor", instanceName="wrong")
    with pytest.raises(Exception, match="Failed to instantiate"):
        fmu.instantiate(callbacks=log.callbacks)
    assert any('"{wrong}"' in m and guid in m for m in log.messages), log.messages

    long_guid = "{" + "x" * 1000 + "}"
    for given, shown in ((None, '"(null)"'), (long_guid.encode(), '"{' + "x" * 63 + '"')):
        component = fmu.fmi2Instantiate(b"wrong", fmi2CoSimulation, given, b"", byref(log.callbacks),
                                        False, False)
        assert component is None
        assert shown in log.messages[-1] and guid in log.messages[-1], log.messages[-1]


# ---- declared bounds against the FMU's checks, every parameter of every model ----

_PARAMETERS = [(model.identifier, v.name) for model in MODELS.values() for v in model.parameters]


@pytest.fixture(scope="module")
def unzipped_fmu2(tmp_path_factory):
    """The extracted FMI 2.0 FMU of a catalog model, by identifier, extracted once."""
    directories = {}

    def get(identifier):
        if identifier not in directories:
            target = tmp_path_factory.mktemp(identifier)
            directories[identifier] = extract(catalog_fmu(MODELS[identifier], 2), unzipdir=target)
        return directories[identifier]

    return get


def _declared_range(directory, name):
    """(min, max) of parameter ``name`` in the modelDescription; +-inf where none is declared."""
    variable = next(v for v in model_description(directory).modelVariables if v.name == name)
    low = -math.inf if variable.min is None else float(variable.min)
    high = math.inf if variable.max is None else float(variable.max)
    return low, high


def _python_accepts(variable, value):
    try:
        variable.check(value)
    except ValueError:
        return False
    return True


def _assert_fmu_refuses(directory, name, value, start):
    """``value`` set on a fresh instance is refused with a message naming it, and changes nothing."""
    fmu = Fmi2Instance(directory, unzip_dir=directory, initialize=False)
    try:
        with pytest.raises(FMICallException):
            fmu.set(**{name: value})
        assert any(m.startswith(f"{name} = {logged(value)} refused") for m in fmu.messages), fmu.messages
        fmu.enter_initialization()  # a value is read from Initialization Mode on
        assert fmu.get(name)[0] == start
    finally:
        fmu.close()


def _assert_fmu_accepts(directory, name, value, run=True):
    """``value`` set before initialization is taken exactly; with ``run`` the
    instance then initializes and takes a step without a complaint."""
    fmu = Fmi2Instance(directory, unzip_dir=directory, initialize=False)
    try:
        fmu.set(**{name: value})  # raises FMICallException if refused
        fmu.enter_initialization()  # a value is read from Initialization Mode on
        assert fmu.get(name)[0] == value
        if run:
            fmu.fmu.exitInitializationMode()
            fmu.step(h=value if name == "dt" else None)  # a sampled-data FMU steps by its own dt only
        assert not fmu.messages, fmu.messages
    finally:
        fmu.close()


@pytest.mark.parametrize("identifier, name", _PARAMETERS)
def test_declared_range_is_exactly_what_the_fmu_accepts(unzipped_fmu2, identifier, name):
    """FMI's min and max are inclusive: each declared bound is accepted by the
    FMU (set, initialize, step), the next double beyond it is refused, and
    Variable.check agrees at both points. Where no bound is declared, the FMU
    and Variable.check take the most negative (positive) finite double."""
    directory = unzipped_fmu2(identifier)
    variable = MODELS[identifier].variable(name)
    low, high = _declared_range(directory, name)
    assert (low, high) == (variable.min, variable.max)  # the XML says what the table says
    assert low <= variable.start <= high
    for bound, outward in ((low, -math.inf), (high, math.inf)):
        if math.isinf(bound):
            extreme = math.copysign(sys.float_info.max, outward)
            assert _python_accepts(variable, extreme)
            _assert_fmu_accepts(directory, name, extreme, run=False)  # may well overflow in a step
            continue
        beyond = float(np.nextafter(bound, outward))
        assert _python_accepts(variable, bound)
        _assert_fmu_accepts(directory, name, bound)
        assert not _python_accepts(variable, beyond)
        _assert_fmu_refuses(directory, name, beyond, variable.start)


def test_source_fmu_compiles_on_its_own_with_fmpy_build(quadrotor_fmu2, tmp_path):
    """Users on other platforms compile the FMU from its sources: drop our
    binary, rebuild with fmpy's CMake build from the listed source files, fly."""
    import shutil
    import zipfile

    from fmpy.build import build_platform_binary

    unzipped = tmp_path / "unzipped"
    with zipfile.ZipFile(quadrotor_fmu2) as zf:
        zf.extractall(unzipped)
    shutil.rmtree(unzipped / "binaries")
    (tmp_path / "cmake").mkdir()
    # Debug (no optimization): whether the listed sources compile and link on their own is the question,
    # not how fast the binary runs; Release doubles the compiler's time (about 1 s of CPU)
    build_platform_binary(unzipped.resolve(), build_dir=tmp_path / "cmake", configuration="Debug",
                          cmake_options=dict(CXX_UNCHECKED))
    result = simulate_fmu(str(unzipped), stop_time=1.0, output_interval=0.01,
                          start_values={"z_0": -15.0, **ROTORS_AT_HOVER})
    assert abs(result["z"][-1] + 15.0) < 1e-9


def test_log_messages_reach_the_instance_that_wrote_them(instance):
    """fmpy keeps one FMI 2.0 logger per process; with two live instances each
    refusal must still be reported to its own instance."""
    first, second = instance(initialize=False), instance(initialize=False)
    with pytest.raises(FMICallException):
        first.set(m=-1.0)
    with pytest.raises(FMICallException):
        second.set(Ix=-2.0)
    assert any("m = -1" in m for m in first.messages) and not any("Ix" in m for m in first.messages)
    assert any("Ix = -2" in m for m in second.messages) and not any("m = -1" in m for m in second.messages)


# ---- motor dynamics: the first-order rotor-speed lag tau_m -------------------------------

def test_motor_lag_is_an_optional_parameter_and_the_plant_state_stays_the_rigid_body():
    """tau_m in s, default 0 (the paper's instantaneous rotors), inclusive range
    [0, 1] s; the four rotor speeds are states after the 12 rigid-body states,
    which alone are STATE_NAMES, and start at hover like the commands."""
    tau_m = QUADROTOR.variable("tau_m")
    assert (tau_m.causality, tau_m.unit, tau_m.start, tau_m.min, tau_m.max) == ("parameter", "s", 0.0, 0.0, 1.0)
    assert STATE_NAMES == ("x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")
    assert ROTOR_STATE_NAMES == ("Omega_r_1", "Omega_r_2", "Omega_r_3", "Omega_r_4")
    assert tuple(ALL_STATES) == STATE_NAMES + ROTOR_STATE_NAMES
    assert [v.name for v in QUADROTOR.variables[:12]] == list(STATE_NAMES)
    for name in ROTOR_STATE_NAMES:
        assert QUADROTOR.variable(name).unit == "rad/s"
        start = QUADROTOR.variable(f"{name}_0")
        assert (start.unit, start.start, start.min) == ("rad/s", HOVER, 0.0)
    x0 = np.array(QUADROTOR.functions["init"](QUADROTOR.parameter_values())).ravel()
    np.testing.assert_array_equal(x0, [0.0] * 12 + [HOVER] * 4)
    # an initial rotor speed is clipped to [0, Omega_max], as the commands are
    x0 = np.array(QUADROTOR.functions["init"](QUADROTOR.parameter_values(Omega_r_1_0=5000.0))).ravel()
    assert x0[12] == DEFAULTS["Omega_max"]


def _instantaneous_rotor_model() -> FmuModel:
    """The plant as it was before the motor lag: the table without tau_m, the
    rotor states and their initial values, and the equations with tau_m the
    constant 0, which CasADi folds away (the thrust is then the expression
    sq(fmin(fmax(Omega_i, 0), Omega_max)) of the instantaneous model)."""
    motor = {"tau_m", *ROTOR_STATE_NAMES, *(f"{name}_0" for name in ROTOR_STATE_NAMES)}

    def equations(t, s):
        derivatives, outputs = QUADROTOR.equations(
            t, {**s, "tau_m": ca.SX(0), **{name: ca.SX(0) for name in ROTOR_STATE_NAMES}})
        return {name: derivatives[name] for name in STATE_NAMES}, outputs

    return FmuModel(identifier="QuadrotorInstantaneousRotors", description="reference of the tests",
                    variables=tuple(v for v in QUADROTOR.variables if v.name not in motor),
                    equations=equations,
                    initial_state=lambda s: {name: s[f"{name}_0"] for name in STATE_NAMES})


def _saturating_input_history(n_steps=300, dt=0.01):
    """3 s of rotor commands swinging around hover (5 % and 3 %), one rotor
    commanded above Omega_max for 0.1 s and one below 0 for 0.1 s, and a
    changing wind."""
    t = np.arange(n_steps) * dt
    rotors = [HOVER * (1 + 0.05 * np.sin(2.1 * t + k) + 0.03 * np.sin(7.3 * t * (k + 1))) for k in range(4)]
    rotors[0][50:60] = 5000.0
    rotors[2][120:130] = -50.0
    wind = [3 * np.sin(0.5 * t), -2 * np.cos(0.3 * t), 0.5 * np.sin(1.7 * t)]
    return np.column_stack(rotors + wind)


# The outputs x..r, T, tau_phi, tau_theta, tau_psi at t = 3 s of that history
# (z_0 = -15, psi_0 = 0.3), as the plant FMU gave them before the motor lag
# existed; the new FMU with tau_m = 0 gave them bit for bit on the machine that
# introduced it. Compared to 1e-9 here, as Tables 2-3 are: another libm may
# differ in the last bit of a sine, and the vehicle tumbles.
_BEFORE_THE_MOTOR_LAG_AT_3_S = [
    0.002510667085148252, -7.810726734860205, 1.6614085598477026, -0.9025158870091315, -3.4101912418626497,
    12.005137134538822, 4.024956986411413, 0.4712992740432575, -2.5007363542616288, 2.3896444116110938,
    2.7302106338518044, -2.5637394904481354, 10.95878129829306, -0.03907647178351165, -0.05069149320726592,
    -0.006198988671949206,
]


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_tau_m_zero_is_bit_identical_to_the_instantaneous_rotor_plant(fmi_version):
    """With the default tau_m = 0 every output over a varied 3 s input history
    (saturating at both ends) is exactly that of the plant without motor
    dynamics, at every step; the rotor states stay at their initial values."""
    names = [v.name for v in QUADROTOR.inputs]
    outputs = list(STATE_NAMES) + ["T", "tau_phi", "tau_theta", "tau_psi"]
    inputs = _saturating_input_history()
    parameters = {"z_0": -15.0, "psi_0": 0.3}

    def fly(path, extra=()):
        if fmi_version == 2:
            fmu = Fmi2Instance(str(path), parameters=parameters)
            try:
                rows = []
                for row in inputs:
                    fmu.set(**dict(zip(names, row)))
                    fmu.step()
                    rows.append(fmu.get(*outputs, *extra))
            finally:
                fmu.close()
            return np.array(rows)
        signal = np.zeros(len(inputs), dtype=[("time", float)] + [(n, float) for n in names])
        signal["time"] = np.arange(len(inputs)) * 0.01
        for i, n in enumerate(names):
            signal[n] = inputs[:, i]
        result = simulate_fmu(str(path), stop_time=3.0, output_interval=0.01, step_size=0.01,
                              start_values=parameters, input=signal, output=outputs + list(extra),
                              fmi_type="CoSimulation")
        return np.column_stack([result[n] for n in outputs + list(extra)])[1:]

    with_motor = fly(cached_fmu(QUADROTOR, fmi_version), extra=ROTOR_STATE_NAMES)
    reference = fly(cached_fmu(_instantaneous_rotor_model(), fmi_version))
    assert np.abs(reference[:, :3] - [0, 0, -15]).max() > 1.0  # it really flew
    np.testing.assert_array_equal(with_motor[:, :16], reference)
    assert np.array_equal(np.signbit(with_motor[:, :16]), np.signbit(reference))
    assert (with_motor[:, 16:] == HOVER).all()
    np.testing.assert_allclose(reference[-1], _BEFORE_THE_MOTOR_LAG_AT_3_S, rtol=1e-9, atol=1e-9)


def _rk4_factor(z):
    """One classical RK4 step of y' = -y/tau with z = h/tau multiplies y by this."""
    return 1 - z + z**2 / 2 - z**3 / 6 + z**4 / 24


@pytest.mark.parametrize("internal_step", [1e-3, 5e-4])
def test_a_step_in_the_command_gives_the_exponential_rotor_response_to_rk4_accuracy(instance, internal_step):
    """From hover, a step in the four commands (one above Omega_max, one below
    0): Omega_r(t) = c + (Omega_r0 - c) exp(-t / tau_m) with c the saturated
    command, to RK4's error (t/tau) (h/tau)^4 / 120 relative, and exactly
    RK4's own (1 - z + z^2/2 - z^3/6 + z^4/24)^n to round-off, at two
    internal steps."""
    fmu = instance(parameters={"z_0": -15.0, "tau_m": TAU_M, "internal_step": internal_step})
    command = {"Omega_1": 1.1 * HOVER, "Omega_2": 0.8 * HOVER, "Omega_3": 5000.0, "Omega_4": -100.0}
    target = np.array([1.1 * HOVER, 0.8 * HOVER, DEFAULTS["Omega_max"], 0.0])
    fmu.set(**command)
    z = internal_step / TAU_M
    worst = 0.0
    for n in range(1, 11):  # 0.1 s = 5 tau_m
        fmu.step()
        t = n * fmu.h
        rotors = fmu.get(*ROTOR_STATE_NAMES)
        exact = target + (HOVER - target) * math.exp(-t / TAU_M)
        rk4 = target + (HOVER - target) * _rk4_factor(z) ** round(t / internal_step)
        np.testing.assert_allclose(rotors, rk4, rtol=1e-13, atol=1e-10)
        # exp(-n z) - R^n = n exp(-(n-1) z) (z^5/120 - z^6/720 + ...)
        bound = np.abs(HOVER - target) * (t / TAU_M) * z**4 / 120 * math.exp(z - t / TAU_M) + 1e-10
        assert (np.abs(rotors - exact) <= bound).all(), (t, rotors - exact, bound)
        worst = max(worst, np.abs(rotors - exact).max())
        assert 0.0 <= rotors.min() and rotors.max() <= DEFAULTS["Omega_max"]  # the limits are kept
    assert worst > 0  # RK4, not the exact solution: its error is what the bound says


def test_the_thrust_and_torques_lag_behind_the_commands(instance):
    """With tau_m the applied thrust and torques are those of the rotor speeds,
    not of the commands: right after a step in the commands they are still the
    hover ones, after 5 tau_m within 1 % of the commanded ones; without the lag
    they follow the command at once."""
    b, l, d = DEFAULTS["b"], DEFAULTS["l"], DEFAULTS["d"]
    command = {"Omega_1": 1.1 * HOVER, "Omega_2": 0.9 * HOVER, "Omega_3": 1.0 * HOVER, "Omega_4": 1.05 * HOVER}
    c = np.array(list(command.values()))
    commanded_thrust = b * (c**2).sum()

    lagged = instance(parameters={"z_0": -15.0, "tau_m": TAU_M})
    lagged.set(**command)
    assert lagged.get("T")[0] == pytest.approx(DEFAULTS["m"] * DEFAULTS["g"], rel=1e-14)
    thrust = []
    for _ in range(10):
        lagged.step()
        o = lagged.get(*ROTOR_STATE_NAMES)
        applied = lagged.get("T", "tau_phi", "tau_theta", "tau_psi")
        np.testing.assert_allclose(applied, [b * (o**2).sum(), b * l * (o[3]**2 - o[1]**2),
                                             b * l * (o[0]**2 - o[2]**2),
                                             d * (-o[0]**2 + o[1]**2 - o[2]**2 + o[3]**2)], rtol=1e-12)
        thrust.append(applied[0])
    hover_thrust = DEFAULTS["m"] * DEFAULTS["g"]
    expected = [b * ((c + (HOVER - c) * math.exp(-n * 0.01 / TAU_M)) ** 2).sum() for n in range(1, 11)]
    np.testing.assert_allclose(thrust, expected, rtol=1e-7)
    assert np.all(np.diff(thrust) > 0)  # rises monotonically towards the command
    assert abs(thrust[-1] - commanded_thrust) < 0.01 * abs(commanded_thrust - hover_thrust)

    instant = instance(parameters={"z_0": -15.0})
    instant.set(**command)
    assert instant.get("T")[0] == pytest.approx(commanded_thrust, rel=1e-14)


def test_hover_with_the_motor_lag_holds_position_exactly(quadrotor_fmu2):
    """The rotor speeds start at the commanded hover speed: their lag is then
    exactly zero and the vehicle hovers as without it."""
    result = simulated(quadrotor_fmu2, stop_time=10.0, output_interval=0.01,
                          start_values={"z_0": -15.0, "tau_m": TAU_M, **ROTORS_AT_HOVER})
    drift = np.sqrt(result["x"] ** 2 + result["y"] ** 2 + (result["z"] + 15.0) ** 2)
    assert drift.max() < 1e-9
    assert (result["Omega_r_1"] == HOVER).all()


def test_a_motor_lag_the_internal_step_cannot_resolve_is_reported_not_flown(instance):
    """RK4 is stable on the lag only for internal_step < 2.78 tau_m: at
    tau_m = 0.1 ms with the default 1 ms step the rotor speed grows by about
    290 a step, becomes infinite and the step is refused naming it."""
    fmu = instance(parameters={"z_0": -15.0, "tau_m": 1e-4})
    fmu.set(Omega_1=1.1 * HOVER)
    with pytest.raises(FMICallException):
        fmu.step(30)
    assert any("state Omega_r_1 became" in m for m in fmu.messages), fmu.messages


def test_closed_loop_circles_with_a_20_ms_motor_lag_fly_without_diverging():
    """The circles mission (controller at 100 Hz, the plant FMU in the master)
    with tau_m = 20 ms: 5 s without the guard tripping, the rotor speeds
    really lag the commands, and the flight stays close to the one with
    instantaneous rotors."""
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master

    def fly(tau_m):
        base = load_scenario("circles", {"fmus.Quadrotor.parameters.tau_m": tau_m, "simulation.duration": 5.0})
        scenario = load_scenario("circles", {"fmus.Quadrotor.parameters.tau_m": tau_m, "simulation.duration": 5.0,
                                             "record.signals": [*base.record,
                                                                *(f"Quadrotor.{n}" for n in ROTOR_STATE_NAMES)]})
        with build_master(scenario) as master:
            return master.run(scenario.duration)

    lagged, instant = fly(TAU_M), fly(0.0)
    assert lagged.status == "ok" and instant.status == "ok"
    assert lagged.time[-1] == pytest.approx(5.0)
    position = np.column_stack([lagged[f"Quadrotor.{a}"] for a in "xyz"])
    assert np.isfinite(lagged.data).all()
    assert np.abs(position[-1]).max() > 0.5  # it flew
    moved_apart = np.abs(position - np.column_stack([instant[f"Quadrotor.{a}"] for a in "xyz"])).max()
    assert 1e-6 < moved_apart < 0.5
    commanded = np.column_stack([lagged[f"controller.Omega_{i}"] for i in range(1, 5)])
    rotors = np.column_stack([lagged[f"Quadrotor.{name}"] for name in ROTOR_STATE_NAMES])
    assert np.abs(rotors - commanded).max() > 1.0  # the lag acts
    assert 0.0 <= rotors.min() and rotors.max() <= DEFAULTS["Omega_max"]
