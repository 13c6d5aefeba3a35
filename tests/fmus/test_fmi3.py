"""The FMI 3.0 export (Model Exchange + Co-Simulation, source FMU), run through fmpy.

The FMU is built once per module (content-addressed cache) and extracted once;
every test creates its own instances. Value references come from
:func:`fmu_models.export.codegen.value_references`, never typed by hand.
"""
from __future__ import annotations

import ctypes
import re
import shutil
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3ScheduledExecution, FMU3Slave

from fmu_models.export.build import cached_fmu
from tests.catalog_fmus import simulated
from tests.fmu_validation import validate_fmu
from fmu_models.export.codegen import value_references
from fmu_models.export.model_description import SOURCE_FILES_FMI3
from fmu_models.models.quadrotor import QUADROTOR, hover_rotor_speed

VR = value_references(QUADROTOR)
STATES = [v.name for v in QUADROTOR.states]
INPUTS = [v.name for v in QUADROTOR.inputs]
OUTPUTS = [v.name for v in QUADROTOR.outputs]
ROTORS = [f"Omega_{i}" for i in range(1, 5)]
WIND = ["wind_x", "wind_y", "wind_z"]
H = 0.01  # s, communication step


# ---- fixtures and helpers -----------------------------------------------------------

@pytest.fixture(scope="module")
def fmu3() -> Path:
    return cached_fmu(QUADROTOR, 3)


@pytest.fixture(scope="module")
def fmu2() -> Path:
    return cached_fmu(QUADROTOR, 2)


@pytest.fixture(scope="module")
def unzipped(fmu3, tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("fmi3")
    with zipfile.ZipFile(fmu3) as zf:
        zf.extractall(target)
    return target


@pytest.fixture(scope="module")
def description(unzipped):
    return fmpy.read_model_description(str(unzipped))


class LogRecorder:
    """fmi3LogMessageCallback that keeps (status, category, message)."""

    def __init__(self) -> None:
        self.records: list[tuple[int, str, str]] = []

    def __call__(self, environment, status, category, message) -> None:
        self.records.append((status, category.decode(), message.decode()))

    def errors(self) -> list[str]:
        return [m for status, _, m in self.records if status >= 3]


def slave(unzipped, description, name="cs", event_mode=False, logging_on=True, **start):
    """An FMU3Slave in Step Mode (or Event Mode with ``event_mode``), with ``start`` values set."""
    fmu = FMU3Slave(guid=description.guid, unzipDirectory=str(unzipped),
                    modelIdentifier=description.coSimulation.modelIdentifier, instanceName=name)
    fmu.log = LogRecorder()
    fmu.instantiate(loggingOn=logging_on, eventModeUsed=event_mode, logMessage=fmu.log)
    if start:
        fmu.setFloat64([VR[k] for k in start], list(start.values()))
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    return fmu


def model(unzipped, description, name="me", **start):
    """An FMU3Model in Continuous-Time Mode."""
    fmu = FMU3Model(guid=description.guid, unzipDirectory=str(unzipped),
                    modelIdentifier=description.modelExchange.modelIdentifier, instanceName=name)
    fmu.log = LogRecorder()
    fmu.instantiate(loggingOn=True, logMessage=fmu.log)
    if start:
        fmu.setFloat64([VR[k] for k in start], list(start.values()))
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    assert fmu.updateDiscreteStates()[0] is False  # nothing to iterate
    fmu.enterContinuousTimeMode()
    return fmu


def close(fmu) -> None:
    fmu.terminate()
    fmu.freeInstance()


def input_sequence(n: int, seed: int = 7) -> np.ndarray:
    """Rotor speeds varied around hover (with saturation at 0 and Omega_max
    visited) and a gusty wind: n rows of the inputs in table order."""
    rng = np.random.default_rng(seed)
    omega = hover_rotor_speed() + rng.normal(0.0, 60.0, size=(n, 4))
    omega[n // 3, 0] = -50.0   # below 0: saturates
    omega[n // 2, 2] = 1200.0  # above Omega_max: saturates
    wind = rng.normal(0.0, 3.0, size=(n, 3))
    return np.hstack([omega, wind])


def run_cs(fmu, inputs: np.ndarray, t0: float = 0.0) -> np.ndarray:
    """Apply each row of ``inputs`` for one step of H; return the states after each step."""
    states = []
    in_refs = [VR[k] for k in INPUTS]
    x_refs = [VR[k] for k in STATES]
    for k, u in enumerate(inputs):
        fmu.setFloat64(in_refs, list(u))
        fmu.doStep(t0 + k * H, H)  # time from the step counter
        states.append(fmu.getFloat64(x_refs))
    return np.array(states)


# ---- the FMU as a file ------------------------------------------------------------------

def test_validate_fmu_finds_no_problems(fmu3):
    assert validate_fmu(str(fmu3)) == []


def test_source_fmu_layout(fmu3, description):
    names = set(zipfile.ZipFile(fmu3).namelist())
    assert f"binaries/{fmpy.platform_tuple}/Quadrotor.so" in names
    assert not any(n.startswith("binaries/linux64/") for n in names)  # the FMI 2.0 name
    assert "sources/buildDescription.xml" in names
    (build,) = description.buildConfigurations
    (file_set,) = build.sourceFileSets
    assert build.modelIdentifier == "Quadrotor"
    assert file_set.language == "C99"
    assert file_set.sourceFiles == list(SOURCE_FILES_FMI3)
    assert {f"sources/{f}" for f in file_set.sourceFiles} <= names
    assert {n for n in names if n.startswith("sources/") and n.endswith(".c")} == \
        {f"sources/{f}" for f in SOURCE_FILES_FMI3}  # nothing unlisted to compile


def test_every_fmi3_function_is_exported(unzipped):
    header = (unzipped / "sources" / "fmi3FunctionTypes.h").read_text()
    functions = sorted(set(re.findall(r"\b(fmi3\w+)TYPE\b", header)))
    assert len(functions) > 70
    library = ctypes.CDLL(str(unzipped / "binaries" / fmpy.platform_tuple / "Quadrotor.so"))
    missing = [f for f in functions if not hasattr(library, f)]
    assert missing == []


def test_fmi3_and_fmi2_descriptions_describe_the_same_model(fmu3, fmu2, description):
    d2 = fmpy.read_model_description(str(fmu2))
    key = lambda v: (v.name, v.valueReference, v.causality, v.variability, v.initial, v.unit, v.start,
                     v.min, v.max, v.derivative.name if v.derivative else None)
    assert [key(v) for v in description.modelVariables] == [key(v) for v in d2.modelVariables]
    # capability flags, read from the XML (fmpy 0.3.32 does not map FMI 3.0's
    # plural providesDirectionalDerivatives onto its ModelDescription)
    root = ElementTree.fromstring(zipfile.ZipFile(fmu3).read("modelDescription.xml"))
    for interface in ("ModelExchange", "CoSimulation"):
        flags = root.find(interface).attrib
        for flag in ("canGetAndSetFMUState", "canSerializeFMUState", "providesDirectionalDerivatives",
                     "providesAdjointDerivatives"):
            assert flags[flag] == "true", (interface, flag)
    assert root.find("CoSimulation").get("hasEventMode") == "true"

    def structure(unknowns):
        return [(u.variable.name, [d.name for d in u.dependencies or []], u.dependenciesKind)
                for u in unknowns]

    assert structure(description.outputs) == structure(d2.outputs)
    assert structure(description.derivatives) == structure(d2.derivatives)
    assert structure(description.initialUnknowns) == structure(d2.initialUnknowns)


# ---- simulation ---------------------------------------------------------------------------

def _signal(n: int) -> np.ndarray:
    """fmpy input signal: the input sequence held over steps of H. Each change
    is a discontinuity (two rows at one time), so fmpy's Model Exchange loop
    stops there and restarts CVode, and Co-Simulation applies the new value."""
    u = input_sequence(n)
    signal = np.zeros(2 * n, dtype=[("time", float)] + [(k, float) for k in INPUTS])
    signal["time"] = np.repeat(np.arange(n + 1) * H, 2)[1:-1]
    for j, k in enumerate(INPUTS):
        signal[k] = np.repeat(u[:, j], 2)
    return signal


def test_simulate_fmu_runs_cs_and_me(fmu3):
    common = dict(stop_time=1.0, output_interval=H, input=_signal(100), start_values={"z_0": -15.0},
                  output=STATES + OUTPUTS)
    cs = simulated(fmu3, fmi_type="CoSimulation", **common)
    cs_events = simulated(fmu3, fmi_type="CoSimulation", use_event_mode=True, **common)
    me = simulated(fmu3, fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-9,
                           record_events=False, **common)
    assert len(cs) == len(me) == 101
    assert abs(cs["z"][-1] - cs["z"][0]) > 1e-3  # it moved
    _, first = np.unique(cs_events["time"], return_index=True)  # Event Mode samples twice per step
    for name in STATES:
        assert np.all(np.isfinite(cs[name]))
        np.testing.assert_array_equal(cs_events[name][first], cs[name])  # Event Mode changes nothing
        # CVode (ME) and the internal RK4 at 1 ms (CS) solve the same ODE; measured
        # max difference 2e-6 at rtol 1e-8, 2e-8 at 1e-10
        np.testing.assert_allclose(me[name], cs[name], rtol=0, atol=2e-6, err_msg=name)


def test_hover_keeps_position_cs(fmu3):
    hover = hover_rotor_speed()
    result = simulated(fmu3, fmi_type="CoSimulation", stop_time=10.0, output_interval=H,
                               start_values={"z_0": -15.0, **{k: hover for k in ROTORS}},
                               output=["x", "y", "z"])
    assert len(result) == 1001
    drift = max(np.max(np.abs(result["x"])), np.max(np.abs(result["y"])), np.max(np.abs(result["z"] + 15.0)))
    assert drift < 1e-9


def test_fmi3_and_fmi2_give_the_same_trajectory(fmu2, unzipped, description):
    inputs = input_sequence(300)
    fmu = slave(unzipped, description, z_0=-15.0)
    x3 = run_cs(fmu, inputs)
    close(fmu)

    d2 = fmpy.read_model_description(str(fmu2))
    unzip2 = fmpy.extract(str(fmu2))
    try:
        fmu = FMU2Slave(guid=d2.guid, unzipDirectory=unzip2, modelIdentifier="Quadrotor", instanceName="fmi2")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.setReal([VR["z_0"]], [-15.0])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        x2 = []
        for k, u in enumerate(inputs):
            fmu.setReal([VR[n] for n in INPUTS], list(u))
            fmu.doStep(k * H, H)
            x2.append(fmu.getReal([VR[n] for n in STATES]))
        fmu.terminate()
        fmu.freeInstance()
    finally:
        shutil.rmtree(unzip2, ignore_errors=True)
    assert np.ptp(x3[:, STATES.index("z")]) > 0.1  # a real manoeuvre, not a hover
    np.testing.assert_allclose(x3, np.array(x2), rtol=0, atol=1e-12)


def test_event_mode_co_simulation(unzipped, description):
    inputs = input_sequence(20)
    plain = slave(unzipped, description, "plain")
    expected = run_cs(plain, inputs)
    close(plain)

    fmu = slave(unzipped, description, "events", event_mode=True)
    with pytest.raises(FMICallException):
        fmu.doStep(0.0, H)  # Event Mode first
    assert fmu.updateDiscreteStates() == (False, False, False, False, False, 0.0)
    fmu.enterStepMode()
    states = []
    for k, u in enumerate(inputs):
        fmu.setFloat64([VR[n] for n in INPUTS], list(u))
        assert fmu.doStep(k * H, H) == (False, False, False, pytest.approx((k + 1) * H, abs=1e-15))
        fmu.enterEventMode()
        fmu.updateDiscreteStates()
        fmu.enterStepMode()
        states.append(fmu.getFloat64([VR[n] for n in STATES]))
    close(fmu)
    np.testing.assert_array_equal(np.array(states), expected)


# ---- derivatives ------------------------------------------------------------------------

def _jacobian(fmu, unknowns, knowns) -> np.ndarray:
    """Columns from directional derivatives with unit seeds."""
    columns = []
    for j in range(len(knowns)):
        seed = [0.0] * len(knowns)
        seed[j] = 1.0
        columns.append(fmu.getDirectionalDerivative([VR[k] for k in unknowns], [VR[k] for k in knowns], seed))
    return np.array(columns).T


def test_directional_and_adjoint_derivatives_model_exchange(unzipped, description):
    fmu = model(unzipped, description)
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 0.5, len(STATES))
    u = input_sequence(4, seed=5)[3]  # no rotor saturated in this row
    n = len(STATES)

    def evaluate(x, u):
        fmu.setContinuousStates((ctypes.c_double * n)(*x), n)
        fmu.setFloat64([VR[k] for k in INPUTS], list(u))
        dx = (ctypes.c_double * n)()
        fmu.getContinuousStateDerivatives(dx, n)
        return np.concatenate([np.array(dx), fmu.getFloat64([VR[k] for k in OUTPUTS])])

    evaluate(x, u)
    unknowns = [f"der({k})" for k in STATES] + OUTPUTS
    J = _jacobian(fmu, unknowns, STATES + INPUTS)
    known = np.concatenate([x, u])
    fd = np.zeros_like(J)
    for j in range(len(known)):
        step = 1e-6 * max(1.0, abs(known[j]))
        plus, minus = known.copy(), known.copy()
        plus[j] += step
        minus[j] -= step
        fd[:, j] = (evaluate(plus[:n], plus[n:]) - evaluate(minus[:n], minus[n:])) / (2 * step)
    evaluate(x, u)
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-6)
    assert np.count_nonzero(J) > 40

    # adjoint derivative = v^T J, from the same AD Jacobian
    v = rng.normal(size=len(unknowns))
    adjoint = fmu.getAdjointDerivative([VR[k] for k in unknowns], [VR[k] for k in STATES + INPUTS], list(v),
                                       nSensitivity=len(STATES + INPUTS))
    np.testing.assert_allclose(adjoint, v @ J, rtol=1e-12, atol=1e-12)
    close(fmu)


def test_directional_derivatives_co_simulation(unzipped, description):
    fmu = slave(unzipped, description, z_0=-15.0)
    run_cs(fmu, input_sequence(30))  # away from hover: tilted, moving
    u = input_sequence(4, seed=11)[3]  # no rotor saturated in this row
    fmu.setFloat64([VR[k] for k in INPUTS], list(u))
    unknowns = OUTPUTS + [f"der({k})" for k in ("u", "w", "p", "r")] + ["z"]
    J = _jacobian(fmu, unknowns, INPUTS)
    fd = np.zeros_like(J)
    for j, name in enumerate(INPUTS):
        step = 1e-6 * max(1.0, abs(u[j]))
        values = []
        for sign in (1, -1):
            fmu.setFloat64([VR[name]], [u[j] + sign * step])
            values.append(np.array(fmu.getFloat64([VR[k] for k in unknowns])))
        fmu.setFloat64([VR[name]], [u[j]])
        fd[:, j] = (values[0] - values[1]) / (2 * step)
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-7)
    assert np.all(J[-1] == 0.0)  # a state does not depend on the inputs directly
    assert np.all(J[0, :4] > 0)  # more rotor speed, more thrust (no rotor saturated here)
    close(fmu)


# ---- FMU state, instances -------------------------------------------------------------

def test_fmu_state_get_set_serialize_reproduces_trajectory(unzipped, description):
    inputs = input_sequence(120)
    fmu = slave(unzipped, description, "a", z_0=-15.0)
    run_cs(fmu, inputs[:40])
    state = fmu.getFMUState()
    serialized = fmu.serializeFMUState(state)
    first = run_cs(fmu, inputs[40:], t0=40 * H)

    fmu.setFMUState(state)
    second = run_cs(fmu, inputs[40:], t0=40 * H)
    np.testing.assert_array_equal(second, first)

    # the bytes restore the state in another instance, over an existing state
    other = slave(unzipped, description, "b")
    reused = other.getFMUState()
    address = reused.value
    restored = other.deserializeFMUState(serialized, reused)
    assert restored.value == address  # overwritten in place: the importer's pointer stays valid
    other.setFMUState(restored)
    third = run_cs(other, inputs[40:], t0=40 * H)
    np.testing.assert_array_equal(third, first)

    with pytest.raises(FMICallException):
        other.deserializeFMUState(serialized[:-1])
    assert any("deserialize FMU state" in m for m in other.log.errors())
    for f, s in ((fmu, state), (other, restored)):
        f.freeFMUState(s)
        close(f)


def test_reset_returns_to_start_values(unzipped, description):
    inputs = input_sequence(50)
    fmu = slave(unzipped, description, z_0=-15.0)
    first = run_cs(fmu, inputs)
    fmu.reset()
    fmu.setFloat64([VR["z_0"]], [-15.0])
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    np.testing.assert_array_equal(run_cs(fmu, inputs), first)
    close(fmu)


def test_two_instances_do_not_interfere(unzipped, description):
    inputs_a, inputs_b = input_sequence(100, seed=1), input_sequence(100, seed=2)
    solo_a = slave(unzipped, description, "solo_a", z_0=-15.0)
    expected_a = run_cs(solo_a, inputs_a)
    close(solo_a)
    solo_b = slave(unzipped, description, "solo_b", m=1.5, Ix=0.05)
    expected_b = run_cs(solo_b, inputs_b)
    close(solo_b)

    a = slave(unzipped, description, "a", z_0=-15.0)
    b = slave(unzipped, description, "b", m=1.5, Ix=0.05)
    got_a, got_b = [], []
    for k in range(100):  # interleaved, step by step
        got_a.append(run_cs(a, inputs_a[k:k + 1], t0=k * H)[0])
        got_b.append(run_cs(b, inputs_b[k:k + 1], t0=k * H)[0])
    np.testing.assert_array_equal(np.array(got_a), expected_a)
    np.testing.assert_array_equal(np.array(got_b), expected_b)
    assert not np.allclose(expected_a, expected_b)
    close(a)
    close(b)


# ---- refused calls and values ------------------------------------------------------------

def _refused(fmu, call, *fragments):
    """``call`` fails with an FMI error status and one error message contains all ``fragments``."""
    before = len(fmu.log.records)
    with pytest.raises(FMICallException) as info:
        call()
    assert info.value.status == 3  # fmi3Error
    new = [m for status, _, m in fmu.log.records[before:] if status >= 3]
    assert any(all(f in m for f in fragments) for m in new), new


def test_bad_parameter_is_refused(unzipped, description):
    fmu = FMU3Slave(guid=description.guid, unzipDirectory=str(unzipped), modelIdentifier="Quadrotor")
    fmu.log = LogRecorder()
    fmu.instantiate(logMessage=fmu.log)
    _refused(fmu, lambda: fmu.setFloat64([VR["m"]], [-1.0]), "m = -1", "range")
    _refused(fmu, lambda: fmu.setFloat64([VR["Iz"]], [0.0]), "Iz = 0", "range")
    fmu.enterInitializationMode()
    assert fmu.getFloat64([VR["m"]]) == [1.07]  # unchanged (read from Initialization Mode on)
    fmu.exitInitializationMode()
    _refused(fmu, lambda: fmu.setFloat64([VR["m"]], [2.0]), "parameter m")  # fixed after initialization
    fmu.doStep(0.0, H)  # the instance still works
    close(fmu)


def test_non_finite_input_is_refused(unzipped, description):
    fmu = slave(unzipped, description)
    _refused(fmu, lambda: fmu.setFloat64([VR["Omega_1"]], [float("nan")]), "Omega_1 = nan")
    _refused(fmu, lambda: fmu.setFloat64([VR["wind_y"]], [float("inf")]), "wind_y = inf")
    assert fmu.getFloat64([VR["Omega_1"]]) == [pytest.approx(hover_rotor_speed())]
    fmu.doStep(0.0, H)
    close(fmu)


@pytest.mark.parametrize("step", [0.0, -0.01, float("nan")])
def test_non_positive_step_size_is_refused(unzipped, description, step):
    fmu = slave(unzipped, description)
    _refused(fmu, lambda: fmu.doStep(0.0, step), "communication step size", "refused")
    fmu.doStep(0.0, H)  # the instance still works at its time
    close(fmu)


def test_calls_in_the_wrong_mode_are_refused(unzipped, description):
    fmu = FMU3Slave(guid=description.guid, unzipDirectory=str(unzipped), modelIdentifier="Quadrotor")
    fmu.log = LogRecorder()
    fmu.instantiate(logMessage=fmu.log)
    _refused(fmu, lambda: fmu.doStep(0.0, H), "fmi3DoStep", "Instantiated")
    _refused(fmu, lambda: fmu.exitInitializationMode(), "fmi3ExitInitializationMode")
    _refused(fmu, lambda: fmu.enterConfigurationMode(), "structural parameters")
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    # a Model Exchange function (FMU3Slave has no wrapper for it)
    _refused(fmu, lambda: fmu.fmi3SetTime(fmu.component, 1.0), "fmi3SetTime", "Co-Simulation")
    _refused(fmu, lambda: fmu.enterEventMode(), "eventModeUsed")
    _refused(fmu, lambda: fmu.getInt32([VR["m"]]), "fmi3GetInt32", "no variables of that type")
    assert fmu.getInt32([]) == []  # zero value references: fine
    _refused(fmu, lambda: fmu.getDirectionalDerivative([VR["m"]], [VR["Omega_1"]], [1.0]), "value reference")
    fmu.terminate()
    _refused(fmu, lambda: fmu.doStep(0.0, H), "fmi3DoStep", "Terminated")
    _refused(fmu, lambda: fmu.setFloat64([VR["Omega_1"]], [600.0]), "fmi3SetFloat64", "Terminated")
    fmu.freeInstance()


def test_wrong_token_and_scheduled_execution_give_no_instance(unzipped, description):
    fmu = FMU3Slave(guid="{not-this-fmu}", unzipDirectory=str(unzipped), modelIdentifier="Quadrotor")
    log = LogRecorder()
    with pytest.raises(Exception, match="Failed to instantiate"):
        fmu.instantiate(logMessage=log)
    assert any("instantiation token" in m and '"{not-this-fmu}"' in m and description.guid in m
               for m in log.errors())

    se = FMU3ScheduledExecution(guid=description.guid, unzipDirectory=str(unzipped), modelIdentifier="Quadrotor")
    log = LogRecorder()
    with pytest.raises(Exception, match="Failed to instantiate"):
        se.instantiate(logMessage=log)
    assert any("Scheduled" in m for m in log.errors())


# ---- compiling the source FMU ---------------------------------------------------------------

@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is not installed")
def test_source_fmu_compiles_with_fmpy_build(fmu3, tmp_path):
    """fmpy's CMake build reads sources/buildDescription.xml (file list,
    language C99) and puts the library under binaries/<platform tuple>."""
    from fmpy.build import build_platform_binary

    from tests.fmus.test_plant_fmu import CXX_UNCHECKED

    unzipdir = tmp_path / "fmu"
    with zipfile.ZipFile(fmu3) as zf:
        zf.extractall(unzipdir)
    shutil.rmtree(unzipdir / "binaries")
    (tmp_path / "build").mkdir()
    # Debug (no optimization): the build description's file list and language are the question, not the
    # binary's speed; Release doubles the compiler's time (about 1 s of CPU). Without -ffast-math either way
    # the rebuilt FMU computes the same doubles as ours (-O1), hence the 1e-12 below. fmpy's CMakeLists
    # enables C++ as well (project() without LANGUAGES), whose compiler CMake checks by compiling and
    # linking test programs (about 0.3 s of CPU); no source is C++: that compiler is taken as it is.
    build_platform_binary(unzipdir, build_dir=tmp_path / "build", configuration="Debug",
                          cmake_options=dict(CXX_UNCHECKED))
    assert (unzipdir / "binaries" / fmpy.platform_tuple / "Quadrotor.so").is_file()

    common = dict(fmi_type="CoSimulation", stop_time=0.5, output_interval=H, input=_signal(50),
                  start_values={"z_0": -15.0}, output=STATES)
    rebuilt = fmpy.simulate_fmu(str(unzipdir), **common)
    shipped = simulated(fmu3, **common)
    for name in STATES:
        np.testing.assert_allclose(rebuilt[name], shipped[name], rtol=0, atol=1e-12, err_msg=name)
