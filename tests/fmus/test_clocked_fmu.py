"""The clocked FMI 3.0 sampled-data FMUs (docs/fmi-export.md, "Clocks"): the
controller's periodic input clock ``sample_clock`` ticks every ``dt``; an
importer driving it through fmpy's FMI 3.0 API in Co-Simulation with Event
Mode at any communication step (1 ms, 50 ms: the FMU returns early at each
tick), in Co-Simulation without Event Mode, in Model Exchange (a time event
per tick) and in Scheduled Execution gets, at every tick, the outputs of the
FMI 2.0 controller stepped at ``dt``, bit for bit; every call the standard
forbids in an interface is refused with a message naming it."""
from __future__ import annotations

import ctypes

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Model, FMU3ScheduledExecution, FMU3Slave
from tests.catalog_fmus import fmpy_class, loaded
from tests.fmu_validation import validate_fmu


from fmu_models.export.build import cached_fmu
from fmu_models.export.model_description import CLOCK_NAME, clock_reference
from fnn_controller.controller_fmu import controller_model
from fnn_controller.split import inner_model, outer_model

VARIANT = "pd+lm"
DT = 0.01  # s: the controller's default period
TICKS = 25


@pytest.fixture(scope="module")
def fmus():
    model = controller_model(VARIANT)
    return {2: cached_fmu(model, 2), 3: cached_fmu(model, 3), "clock": clock_reference(model)}


class Log:
    def __init__(self):
        self.records = []

    def __call__(self, env, status, category, message):
        self.records.append((status, message.decode() if isinstance(message, bytes) else str(message)))


def _open(path, cls, **instantiate):
    # one reading and one folder for the process's instances, fmpy's class as a run makes its instances
    md, folder = loaded(path)
    fmu = fmpy_class(cls)(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                           instanceName="controller")
    fmu.log = Log()
    fmu.instantiate(logMessage=fmu.log, **instantiate)
    fmu.vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu.inputs = [v.valueReference for v in md.modelVariables if v.causality == "input" and v.type == "Float64"]
    fmu.watched = [v.valueReference for v in md.modelVariables  # outputs and learned states
                   if v.causality in ("output", "local") and v.type == "Float64" and v.variability == "discrete"]
    return fmu


def _u(fmu, t: float) -> list[float]:
    """A recorded input sequence: smooth, different for every input, small enough for every range."""
    return [0.2 * np.sin(3.0 * t + i) for i in range(len(fmu.inputs))]


def _fmi2_reference(path) -> np.ndarray:
    """The FMI 2.0 controller stepped at dt: set u(t_k), get, doStep."""
    from fmpy.fmi2 import FMU2Slave

    md, folder = loaded(path)
    fmu = fmpy_class(FMU2Slave)(guid=md.guid, unzipDirectory=folder,
                                 modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    inputs = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    watched = [v.valueReference for v in md.modelVariables if v.causality in ("output", "local")
               and v.variability == "discrete"]
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    rows = []
    for k in range(TICKS):
        t = k * DT
        fmu.setReal(inputs, [0.2 * np.sin(3.0 * t + i) for i in range(len(inputs))])
        rows.append(fmu.getReal(watched))
        fmu.doStep(t, DT)
    fmu.terminate()
    fmu.freeInstance()
    return np.array(rows)


def _event_mode_cs(path, h: float) -> tuple[np.ndarray, list[float]]:
    """fmpy's FMU3Slave with Event Mode and early return, communication step h:
    at each tick (Event Mode) set u(t), activate the clock, get, update; in
    between, steps of h (inputs set at every communication point) until the
    FMU says an event is due."""
    fmu = _open(path, FMU3Slave, eventModeUsed=True, earlyReturnAllowed=True)
    clock = fmu.vr[CLOCK_NAME]
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()  # in Event Mode at t = 0, the first tick
    rows, ticks, t = [], [], 0.0
    while len(rows) < TICKS:
        fmu.setFloat64(fmu.inputs, _u(fmu, t))
        fmu.setClock([clock], [True])
        rows.append(fmu.getFloat64(fmu.watched))
        ticks.append(t)
        _, _, _, _, defined, next_tick = fmu.updateDiscreteStates()
        assert defined and next_tick == pytest.approx(t + DT, abs=1e-12)
        held = fmu.getFloat64(fmu.watched)  # the outputs of the tick, the learned states after it
        fmu.enterStepMode()
        while True:
            event, _, early, t = fmu.doStep(t, h)
            assert early == (h > DT)  # returns early only when the step passes the tick
            if event:
                break
            fmu.setFloat64(fmu.inputs, _u(fmu, t))  # between ticks: changes no output
            np.testing.assert_array_equal(fmu.getFloat64(fmu.watched), held)
        fmu.enterEventMode()
    fmu.terminate()
    fmu.freeInstance()
    return np.array(rows), ticks


@pytest.mark.parametrize("h", [0.001, DT, 0.05])
def test_fmpy_event_mode_any_step_gives_the_fmi2_outputs_at_every_tick(fmus, h):
    """1 ms (ten steps a tick), dt, 50 ms (early return at each tick): the same
    outputs and learned states at each tick, and the FMI 2.0 controller's."""
    rows, ticks = _event_mode_cs(fmus[3], h)
    np.testing.assert_array_equal(rows, _fmi2_reference(fmus[2]))
    np.testing.assert_allclose(ticks, DT * np.arange(TICKS), rtol=0, atol=1e-15)


def test_without_event_mode_dostep_computes_the_ticks_it_covers(fmus):
    """eventModeUsed = false: at dt the FMI 2.0 behaviour (set, get, doStep);
    a 50 ms step computes its five ticks from the inputs set before it."""
    reference = _fmi2_reference(fmus[2])
    fmu = _open(fmus[3], FMU3Slave)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    for k in range(TICKS):
        t = k * DT
        fmu.setFloat64(fmu.inputs, _u(fmu, t))
        np.testing.assert_array_equal(fmu.getFloat64(fmu.watched), reference[k])
        fmu.doStep(t, DT)
    long = _open(fmus[3], FMU3Slave)
    long.enterInitializationMode(startTime=0.0)
    long.exitInitializationMode()
    long.setFloat64(long.inputs, _u(long, 0.0))
    event, _, early, t = long.doStep(0.0, 0.05)
    assert (event, early, t) == (False, False, 0.05)
    held = long.getFloat64(long.watched)
    one = _open(fmus[3], FMU3Slave)  # the same five ticks, one at a time, inputs held
    one.enterInitializationMode(startTime=0.0)
    one.exitInitializationMode()
    for k in range(5):
        one.setFloat64(one.inputs, _u(one, 0.0))
        one.doStep(k * DT, DT)
    np.testing.assert_array_equal(held, one.getFloat64(one.watched))


def test_model_exchange_ticks_are_time_events(fmus):
    """FMU3Model: no continuous states; nextEventTime is the next tick; the
    outputs at each tick are the FMI 2.0 controller's."""
    fmu = _open(fmus[3], FMU3Model)
    clock = fmu.vr[CLOCK_NAME]
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    rows, t = [], 0.0
    for k in range(TICKS):
        fmu.setFloat64(fmu.inputs, _u(fmu, t))
        fmu.setClock([clock], [True])
        rows.append(fmu.getFloat64(fmu.watched))
        _, _, _, _, defined, t_next = fmu.updateDiscreteStates()
        assert defined
        fmu.enterContinuousTimeMode()
        fmu.setTime(t + 0.5 * (t_next - t))  # an integrator's step inside the period: allowed
        fmu.setTime(t_next)
        fmu.completedIntegratorStep()
        fmu.enterEventMode()
        t = t_next
    np.testing.assert_array_equal(np.array(rows), _fmi2_reference(fmus[2]))


def test_scheduled_execution_activates_one_tick_per_call(fmus):
    fmu = _open(fmus[3], FMU3ScheduledExecution)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    rows = []
    for k in range(TICKS):
        fmu.setFloat64(fmu.inputs, _u(fmu, k * DT))
        fmu.activateModelPartition(fmus["clock"], k * DT)
        rows.append(fmu.getFloat64(fmu.watched))  # the tick's outputs, the learned states after it
    rows, reference = np.array(rows), _fmi2_reference(fmus[2])
    n_out = len(read_model_description(str(fmus[3])).outputs)  # the outputs come first (value references)
    np.testing.assert_array_equal(rows[:, :n_out], reference[:, :n_out])
    np.testing.assert_array_equal(rows[:-1, n_out:], reference[1:, n_out:])


def test_interval_and_shift_are_the_period_parameter(fmus):
    """intervalVariability = "fixed": the interval is dt, set (in Initialization
    Mode) or read through the clock; the shift is 0; after initialization the
    interval is refused."""
    fmu = _open(fmus[3], FMU3Slave, eventModeUsed=True)
    clock = fmu.vr[CLOCK_NAME]
    vr = (ctypes.c_uint32 * 1)(clock)  # fmpy 0.3's interval calls take ctypes arrays
    fmu.enterInitializationMode(startTime=0.0)
    fmu.setIntervalDecimal(vr, (ctypes.c_double * 1)(0.02))
    fmu.exitInitializationMode()
    interval, qualifier, shift = (ctypes.c_double * 1)(), (ctypes.c_int * 1)(), (ctypes.c_double * 1)(1.0)
    fmu.getIntervalDecimal(vr, interval, qualifier)
    assert interval[0] == 0.02 and fmu.getFloat64([fmu.vr["dt"]]) == [0.02]
    fmu.getShiftDecimal(vr, shift)
    assert shift[0] == 0.0
    _refused(fmu, lambda: fmu.setIntervalDecimal(vr, (ctypes.c_double * 1)(0.01)), "fmi3SetIntervalDecimal",
             "EventMode")


def _refused(fmu, call, *fragments):
    """``call`` fails with fmi3Error and an error message holds every fragment."""
    before = len(fmu.log.records)
    with pytest.raises(FMICallException) as info:
        call()
    assert info.value.status == 3
    new = [m for status, m in fmu.log.records[before:] if status >= 3]
    assert any(all(f in m for f in fragments) for m in new), new


def _started(path, cls, **instantiate):
    fmu = _open(path, cls, **instantiate)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    return fmu


def test_forbidden_calls_in_scheduled_execution(fmus):
    fmu = _started(fmus[3], FMU3ScheduledExecution)
    clock = fmus["clock"]
    _refused(fmu, lambda: fmu.setClock([clock], [True]), "fmi3SetClock", "Scheduled Execution")
    _refused(fmu, lambda: fmu.getClock([clock]), "fmi3GetClock", "Scheduled Execution")
    _refused(fmu, lambda: fmu.fmi3DoStep(fmu.component, 0.0, DT, True, None, None, None, None),
             "fmi3DoStep", "Scheduled Execution")
    _refused(fmu, lambda: fmu.fmi3EnterEventMode(fmu.component), "fmi3EnterEventMode", "Scheduled Execution")
    _refused(fmu, fmu.updateDiscreteStates, "fmi3UpdateDiscreteStates", "Scheduled Execution")
    _refused(fmu, lambda: fmu.activateModelPartition(clock, 0.5 * DT), "fmi3ActivateModelPartition",
             "ticks at t = 0, not at t = 0.005")
    _refused(fmu, lambda: fmu.activateModelPartition(clock + 1, 0.0), "fmi3ActivateModelPartition",
             "no clock")
    fmu.activateModelPartition(clock, 0.0)  # the instance goes on


def test_forbidden_calls_in_co_simulation(fmus):
    clock = fmus["clock"]
    fmu = _started(fmus[3], FMU3Slave, eventModeUsed=True)  # early return not allowed
    _refused(fmu, lambda: fmu.fmi3ActivateModelPartition(fmu.component, clock, 0.0), "fmi3ActivateModelPartition",
             "Co-Simulation")
    _refused(fmu, lambda: fmu.setClock([clock + 1], [True]), "fmi3SetClock", "no clock")
    fmu.enterStepMode()
    _refused(fmu, lambda: fmu.doStep(0.0, DT), "fmi3DoStep", "tick was not computed")
    fmu.enterEventMode()
    fmu.setClock([clock], [True])
    _refused(fmu, lambda: fmu.setClock([clock], [False]), "fmi3SetClock", "canBeDeactivated = false")
    _refused(fmu, fmu.enterStepMode, "fmi3EnterStepMode", "not computed")
    fmu.updateDiscreteStates()
    fmu.enterStepMode()
    _refused(fmu, lambda: fmu.setClock([clock], [True]), "fmi3SetClock", "StepComplete")
    _refused(fmu, lambda: fmu.doStep(0.0, 0.05), "fmi3DoStep", "passes the tick", "earlyReturnAllowed")
    fmu.doStep(0.0, 0.5 * DT)
    fmu.enterEventMode()
    _refused(fmu, lambda: fmu.setClock([clock], [True]), "fmi3SetClock", "ticks at t = 0.01, not at t = 0.005")
    plain = _started(fmus[3], FMU3Slave)  # eventModeUsed = false: doStep computes the ticks
    _refused(plain, lambda: plain.setClock([clock], [True]), "fmi3SetClock", "eventModeUsed = false")
    _refused(plain, lambda: plain.fmi3EnterEventMode(plain.component), "fmi3EnterEventMode", "eventModeUsed = false")


def test_forbidden_calls_in_model_exchange(fmus):
    clock = fmus["clock"]
    fmu = _started(fmus[3], FMU3Model)
    _refused(fmu, lambda: fmu.fmi3DoStep(fmu.component, 0.0, DT, True, None, None, None, None),
             "fmi3DoStep", "Model Exchange")
    _refused(fmu, lambda: fmu.fmi3ActivateModelPartition(fmu.component, clock, 0.0), "fmi3ActivateModelPartition",
             "Model Exchange")
    fmu.enterContinuousTimeMode()  # the tick at t = 0 not computed
    _refused(fmu, lambda: fmu.setTime(DT), "set time t = 0.01 refused", "passes the tick of sample_clock at t = 0")
    _refused(fmu, lambda: fmu.setClock([clock], [True]), "fmi3SetClock must not be called in ContinuousTimeMode")


def test_continuous_fmi3_fmus_have_no_clock_and_refuse_scheduled_execution():
    from fmu_models.models.quadrotor import QUADROTOR

    path = cached_fmu(QUADROTOR, 3)
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    assert not [v for v in md.modelVariables if v.type == "Clock"]
    with pytest.raises(Exception):
        _open(path, FMU3ScheduledExecution)


def test_the_split_controllers_are_clocked_and_validate():
    for model in (outer_model(VARIANT), inner_model()):
        path = cached_fmu(model, 3)
        assert validate_fmu(str(path)) == []
        md = read_model_description(str(path))
        (clock,) = [v for v in md.modelVariables if v.type == "Clock"]
        assert (clock.name, clock.causality, clock.intervalVariability) == (CLOCK_NAME, "input", "fixed")
        outputs = [v for v in md.modelVariables if v.causality == "output"]
        assert outputs and all(v.clocks == [clock] for v in outputs)


def test_the_controller_declares_its_clock(fmus):
    assert validate_fmu(str(fmus[3])) == []
    md = read_model_description(str(fmus[3]))
    (clock,) = [v for v in md.modelVariables if v.type == "Clock"]
    assert (clock.name, clock.causality, clock.variability, clock.intervalVariability) == \
        (CLOCK_NAME, "input", "discrete", "fixed")
    clocked = {v.name for v in md.modelVariables if v.clocks}
    assert clocked == {v.name for v in md.modelVariables if v.causality in ("output", "local")
                       and v.variability == "discrete"}
    assert {"Omega_1", "v_ref_x"} <= clocked
    assert md.modelExchange is not None and md.scheduledExecution is not None
    assert md.coSimulation.hasEventMode and md.coSimulation.mightReturnEarlyFromDoStep
    assert not {u.variable.name for u in md.initialUnknowns} & clocked


@pytest.fixture(scope="module")
def fmi2_circles():
    return _fly_circles({"controller.fmi_version": 2})


def _fly_circles(overrides):
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master

    scenario = load_scenario("circles", overrides)
    with build_master(scenario) as master:
        controller = master.components["controller"]
        assert controller.fmi_version == overrides["controller.fmi_version"]
        assert controller.interface == overrides.get("controller.interface", "CoSimulation")
        assert (controller.clock is not None) == (controller.fmi_version == 3)
        return master.run(scenario.duration, seed=scenario.seed, t0=scenario.start_time)


@pytest.mark.parametrize("interface", ["CoSimulation", "ModelExchange"])
def test_our_master_flies_circles_with_the_clocked_controller_bit_for_bit(fmi2_circles, interface):
    """The whole circles mission (50 s), its controller the clocked FMI 3.0
    FMU, in Co-Simulation with Event Mode or in Model Exchange (the Python
    loop: cosim.loop.master), is the FMI 2.0 controller's flight to the last bit."""
    run = _fly_circles({"controller.fmi_version": 3, "controller.interface": interface})
    assert run.status == fmi2_circles.status == "ok" and run.columns == fmi2_circles.columns
    assert run.data.shape[0] == 5001
    for i, name in enumerate(run.columns):
        np.testing.assert_array_equal(run.data[:, i], fmi2_circles.data[:, i], err_msg=name)


def test_an_interface_the_fmu_lacks_is_refused_by_name():
    """Model Exchange is for any FMU that has it (the master integrates it);
    the controller's FMI 2.0 form is Co-Simulation only."""
    from cosim.errors import FmuLoadError
    from cosim.fmi.fmu import FmuComponent

    with pytest.raises(FmuLoadError, match="interface = 'ModelExchange': the FMU has no Model Exchange interface "
                                           r"\(it has Co-Simulation only\)"):
        FmuComponent("controller", cached_fmu(controller_model(VARIANT), 2), interface="ModelExchange")


@pytest.mark.parametrize("interface", ["CoSimulation", "ModelExchange"])
def test_a_clocked_controller_is_snapshotted_and_resumed_like_any_fmu(interface):
    """A snapshot taken at a tick (the clocked FMU in Event Mode there) leaves
    the run as it was, and a run resumed from it continues the run: the
    first row exactly, the rest to round-off of the resumed time grid."""
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master

    scenario = load_scenario("circles", {"controller.fmi_version": 3, "controller.interface": interface,
                                         "simulation.duration": 5.0})
    with build_master(scenario) as master:
        plain = master.run(5.0)
        run = master.run(5.0, snapshots=[2.0])
        resumed = master.run(3.0, t0=2.0, restore=run.snapshots[0].states)
    np.testing.assert_array_equal(run.data, plain.data)
    np.testing.assert_array_equal(resumed.data[0], plain.data[200])
    np.testing.assert_allclose(resumed.data, plain.data[200:], rtol=0, atol=1e-9)
