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
from fmpy.validation import validate_fmu

from fmu_models.export.build import cached_fmu
from fmu_models.catalog import MODELS
from fmu_models.models.quadrotor import DEFAULTS, QUADROTOR, hover_rotor_speed
from fmi2_harness import STATES, Fmi2Instance, LogCollector, logged

HOVER = hover_rotor_speed()
ROTORS_AT_HOVER = {f"Omega_{i}": HOVER for i in range(1, 5)}


@pytest.fixture
def instance(quadrotor_fmu2):
    instances = []

    def make(**kwargs):
        inst = Fmi2Instance(quadrotor_fmu2, **kwargs)
        instances.append(inst)
        return inst

    yield make
    for inst in instances:
        inst.close()


def test_fmu_validates_with_no_problems(quadrotor_fmu2):
    assert validate_fmu(str(quadrotor_fmu2)) == []


def test_hover_at_analytic_rotor_speed_holds_position_for_10_s(quadrotor_fmu2):
    result = simulate_fmu(str(quadrotor_fmu2), stop_time=10.0, output_interval=0.01,
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


def test_trajectory_matches_independent_cvodes_integration(instance):
    """The FMU's RK4 (internal step 1 ms) against CasADi's CVODES (BDF,
    tolerance 1e-12) on the same CasADi model, inputs held over each 10 ms."""
    dt, n = 0.01, 300
    inputs = _input_sequence(n, dt)
    p = QUADROTOR.parameter_values(z_0=-15.0)
    fmu = instance(parameters={"z_0": -15.0})
    names = [v.name for v in QUADROTOR.inputs]

    s = QUADROTOR.symbols
    f = QUADROTOR.functions["ode"]
    integrator = ca.integrator("reference", "cvodes",
                               {"x": s["x"], "p": ca.vertcat(s["u"], s["p"]),
                                "ode": f(0, s["x"], s["u"], s["p"])},
                               0.0, dt, {"abstol": 1e-12, "reltol": 1e-12})
    x_ref = np.array(QUADROTOR.functions["init"](p)).ravel()
    worst = 0.0
    for k in range(n):
        fmu.set(**dict(zip(names, inputs[k])))
        fmu.step()
        x_ref = np.array(integrator(x0=x_ref, p=np.concatenate([inputs[k], p]))["xf"]).ravel()
        worst = max(worst, np.abs(fmu.get(*STATES) - x_ref).max())
    # the trajectory really moved (not a trivial agreement at hover)
    assert np.abs(x_ref[:3] - [0, 0, -15]).max() > 0.5
    assert worst < 1e-8


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


def test_directional_derivatives_agree_with_finite_differences(quadrotor_fmu2):
    """A and B of the linearization (Model Exchange: d der(x) / d[x, u]) and
    the feedthrough d y / d u, against central differences of the FMU itself."""
    fmu = Fmi2Instance(quadrotor_fmu2, model_exchange=True, initialize=False)
    try:
        fmu.fmu.setupExperiment(startTime=0.0)
        fmu.fmu.enterInitializationMode()
        fmu.fmu.exitInitializationMode()
        fmu.fmu.enterContinuousTimeMode()

        def set_states(xv):
            xv = np.ascontiguousarray(xv, dtype=float)
            fmu.fmu.setContinuousStates(xv.ctypes.data_as(POINTER(c_double)), len(xv))

        x = np.array([1.0, -2.0, -15.0, 2.0, -1.0, 0.3, 0.2, -0.15, 0.7, 0.3, -0.2, 0.1])
        set_states(x)
        u = {"Omega_1": 600.0, "Omega_2": 650.0, "Omega_3": 620.0, "Omega_4": 640.0,
             "wind_x": 3.0, "wind_y": -1.0, "wind_z": 0.5}
        fmu.set(**u)
        derivatives = [f"der({s})" for s in STATES]
        unknowns = derivatives + ["T", "tau_phi", "tau_theta", "tau_psi", "x", "psi"]  # states as outputs too
        knowns = list(STATES) + list(u)

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
            checked += np.count_nonzero(ad)
        assert checked > 40  # the Jacobian is far from empty
    finally:
        fmu.close()


def test_saved_and_restored_state_reproduces_the_trajectory_exactly(instance):
    fmu = instance(parameters={"z_0": -15.0})
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
        return fmu.get(*STATES)

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
            directories[identifier] = extract(cached_fmu(MODELS[identifier], 2), unzipdir=target)
        return directories[identifier]

    return get


def _declared_range(directory, name):
    """(min, max) of parameter ``name`` in the modelDescription; +-inf where none is declared."""
    variable = next(v for v in read_model_description(directory).modelVariables if v.name == name)
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
        assert fmu.get(name)[0] == start
    finally:
        fmu.close()


def _assert_fmu_accepts(directory, name, value, run=True):
    """``value`` set before initialization is taken exactly; with ``run`` the
    instance then initializes and takes a step without a complaint."""
    fmu = Fmi2Instance(directory, unzip_dir=directory, initialize=False)
    try:
        fmu.set(**{name: value})  # raises FMICallException if refused
        assert fmu.get(name)[0] == value
        if run:
            fmu.initialize({})
            fmu.step()
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
    build_platform_binary(unzipped.resolve(), build_dir=tmp_path / "cmake")
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
