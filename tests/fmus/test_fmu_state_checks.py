"""Restoring an FMU state checks it like any other input (``check_state`` in
``fmu_models/export/c/fmu_core.c``): a state carries its model's name and
token (the GUID), and deserializing or setting it refuses, with a log message
naming what is wrong, a state of another model, a blob of the wrong size, and
a value that a set or initialization would refuse. A valid state still
round-trips exactly. Through :class:`cosim.fmi.fmu.FmuComponent` (fmpy's
``FMU2Slave``/``FMU3Slave``), FMI 2.0 and 3.0, on the shipped controllers;
every bad state is made here from a good one."""
from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest

from cosim.errors import FmuCallError
from cosim.fmi.fmu import FmuComponent
from fmu_models.export.build import cached_fmu
from fnn_controller.controller_fmu import controller_model

VERSIONS = [2, 3]


def _controller(variant: str, version: int) -> FmuComponent:
    """An initialized controller FMU that has flown a few steps on varied inputs."""
    fmu = FmuComponent("controller", cached_fmu(controller_model(variant), version))
    fmu.bind([p.name for p in fmu.inputs], [p.name for p in fmu.outputs])
    fmu.start(0.0)
    rng = np.random.default_rng(4)
    for n in range(5):
        fmu.u[:] = rng.normal(scale=0.3, size=fmu.u.size)
        fmu.write_inputs(n * 0.01)
        fmu.read_outputs(n * 0.01)
        fmu.do_step(n * 0.01, 0.01)
    return fmu


@pytest.fixture(params=VERSIONS, ids=lambda v: f"fmi{v}")
def version(request) -> int:
    return request.param


@pytest.fixture
def pdlm(version):
    with _controller("pd+lm", version) as fmu:
        yield fmu


def _offset(fmu: FmuComponent, size: int, name: str) -> int:
    """Where ``name``'s value is in a state of ``size`` bytes: the values are
    its last 8 N bytes, in value-reference order (fmu_core.h, CoreState)."""
    n_variables = max(v.valueReference for v in fmu.variables.values() if v.type != "Clock") + 1
    return size - 8 * n_variables + 8 * fmu.variables[name].valueReference


def _with_value(fmu: FmuComponent, blob: bytes, name: str, value: float) -> bytes:
    at = _offset(fmu, len(blob), name)
    return blob[:at] + np.float64(value).astype("<f8").tobytes() + blob[at + 8:]


def _refused(fmu: FmuComponent, blob: bytes) -> str:
    """Restore ``blob``: it must be refused in one line quoting the one
    message the FMU logged, the instance's state left as it was. Returns that message."""
    before = fmu.serialize_state()
    with pytest.raises(FmuCallError) as info:
        fmu.restore_state(blob)
    error = info.value
    assert "\n" not in str(error) and "restoring a serialized FMU state failed" in str(error)
    assert error.log.startswith("[ERROR] ") and error.log.count("[ERROR]") == 1, error.log
    assert error.log in str(error)
    assert fmu.serialize_state() == before
    return error.log


def test_a_valid_state_round_trips_exactly(pdlm, version):
    blob = pdlm.serialize_state()
    later = []
    for n in range(5, 8):
        pdlm.write_inputs(n * 0.01)
        pdlm.read_outputs(n * 0.01)
        later.append(pdlm.y.copy())
        pdlm.do_step(n * 0.01, 0.01)
    with _controller("pd+lm", version) as other:  # another instance, with other inputs held
        other.restore_state(blob)
        assert other.serialize_state() == blob
        for n in range(5, 8):
            other.write_inputs(n * 0.01)
            other.read_outputs(n * 0.01)
            np.testing.assert_array_equal(other.y, later[n - 5])
            other.do_step(n * 0.01, 0.01)


def test_a_state_of_another_model_is_refused_naming_both(pdlm, version):
    with _controller("pd+smc", version) as pdsmc:
        blob = pdsmc.serialize_state()
        theirs = pdsmc.model_description.guid
    assert len(blob) == len(pdlm.serialize_state())  # same size: only the token tells them apart
    message = _refused(pdlm, blob)
    assert message == (f"[ERROR] deserialize FMU state: a state of ControllerPDSMC {theirs}, this FMU is "
                       f"ControllerPDLM {pdlm.model_description.guid}")


@pytest.mark.parametrize("name, value, said", [
    ("dt", math.nan, "dt = nan refused: not a finite number"),
    ("dt", 0.0, "dt = 0 refused: outside its range [0.0001, 1]"),
    ("seed", 1.5, "seed = 1.5 refused: not a whole number"),
    ("c1_1_x", math.inf, "c1_1_x = inf refused: not a finite number"),  # a discrete (learned) state
    ("x", math.nan, "x = nan refused: not a finite number"),  # an input
    ("time", -math.inf, "time = -inf refused: not a finite number"),
])
def test_a_value_initialization_would_refuse_is_refused_naming_it(pdlm, name, value, said):
    blob = _with_value(pdlm, pdlm.serialize_state(), name, value)
    message = _refused(pdlm, blob)
    assert message == f"[ERROR] deserialize FMU state: {said}"


def test_a_state_with_dt_nan_no_longer_lets_any_step_through(pdlm, version):
    """The case that was accepted: a restored dt = NaN made doStep take any step
    (FMI 3.0, clocked: a step past the next tick, dt away)."""
    good = pdlm.serialize_state()
    _refused(pdlm, _with_value(pdlm, good, "dt", math.nan))
    said = "communication step size = 0.5 s refused" if version == 2 else "passes the tick of sample_clock at t = 0.06"
    with pytest.raises(FmuCallError, match=said):
        pdlm.do_step(0.05, 0.5)


def test_a_refusal_quotes_what_the_restore_logged_not_an_earlier_call(pdlm):
    blob = pdlm.serialize_state()
    with pytest.raises(FmuCallError):
        pdlm.do_step(0.05, 0.5)  # refused, with a message of its own
    with pytest.raises(FmuCallError) as info:
        pdlm.restore_state(blob[:-8])
    assert info.value.log == (f"[ERROR] deserialize FMU state: {len(blob) - 8} bytes, a state of ControllerPDLM "
                              f"is {len(blob)}")


@pytest.mark.parametrize("cut", [8, 1, None])
def test_a_blob_of_the_wrong_size_is_refused(pdlm, cut):
    blob = pdlm.serialize_state()
    short = blob[:-cut] if cut else blob[:16]  # None: not even the header
    message = _refused(pdlm, short)
    assert message == f"[ERROR] deserialize FMU state: {len(short)} bytes, a state of ControllerPDLM is {len(blob)}"
    message = _refused(pdlm, blob + b"\0")
    assert message == f"[ERROR] deserialize FMU state: {len(blob) + 1} bytes, a state of ControllerPDLM is {len(blob)}"


def test_bytes_that_are_no_state_of_this_exporter_are_refused(pdlm):
    blob = pdlm.serialize_state()
    message = _refused(pdlm, bytes(8) + blob[8:])
    assert message.startswith("[ERROR] deserialize FMU state: not an FMU state of this exporter"), message


def test_setting_a_state_changed_in_memory_is_checked_too(pdlm, version):
    """fmiXSetFMUState runs the same check as deserialization (a state the
    importer holds in memory is an input too)."""
    s = pdlm._slave
    get, set_, free = ((s.getFMUstate, s.setFMUstate, s.freeFMUstate) if version == 2 else
                       (s.getFMUState, s.setFMUState, s.freeFMUState))
    size = len(pdlm.serialize_state())
    state = get()
    try:
        ctypes.memmove(state.value + _offset(pdlm, size, "dt"), np.float64(math.nan).tobytes(), 8)
        pdlm.messages.clear()
        with pytest.raises(Exception):
            set_(state)
        assert any("set FMU state: dt = nan refused: not a finite number" in m for m in pdlm.messages), \
            pdlm.messages
    finally:
        free(state)
