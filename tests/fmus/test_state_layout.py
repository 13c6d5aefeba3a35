"""The bytes of a serialized FMU state (``CoreState`` in ``fmu_models/export/c/fmu_core.h``):
the fixed fields (magic, token, model name, mode, step and tick counters: 168 bytes), a
stochastic model's random stream and pending draws, then the values in value-reference
order. The core reads its model's sizes at run time (the descriptor in ``model_start.c``),
where it was once compiled with them; the layout is what saved states and the engine's
snapshots (``FmuComponent.state_values``: the last 8 N bytes) rely on, so it is pinned here
byte for byte, for a continuous model and for a stochastic sampled-data one."""
from __future__ import annotations

import struct

import numpy as np
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave

from fmu_models.export.build import cached_fmu
from fmu_models.export.codegen import value_references
from fmu_models.models.magnetometer import MAGNETOMETER
from tests.catalog_fmus import extracted
from tests.fmus.test_build_cache import _toy

FIXED = 168  # StateHeader (8 + 40 + 64) + 4 int32 + 5 eight-byte counters
MAGIC = 0x464E4E43 << 32 | 3  # "FNNC", layout 3
PCG64 = 32  # NpPcg64: four uint64


def _state_after_steps(model, steps: int, h: float) -> tuple[bytes, list[float], str]:
    """The serialized state of ``model``'s FMI 2.0 FMU after ``steps`` steps, every value
    read through fmi2GetReal at that point, and its GUID."""
    path = cached_fmu(model, 2)
    description = read_model_description(str(path))
    fmu = FMU2Slave(guid=description.guid, unzipDirectory=extracted(path),
                    modelIdentifier=description.coSimulation.modelIdentifier, instanceName="layout")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for n in range(steps):
            fmu.doStep(n * h, h)
        state = fmu.getFMUstate()
        blob = bytes(fmu.serializeFMUstate(state))
        fmu.freeFMUstate(state)
        n_variables = len(value_references(model))
        values = list(fmu.getReal(list(range(n_variables))))
    finally:
        fmu.freeInstance()
    return blob, values, description.guid


def _header(blob: bytes, model, guid: str, steps: int, h: float) -> None:
    magic, = struct.unpack_from("<Q", blob, 0)
    assert magic == MAGIC
    assert blob[8:48] == guid.encode() + b"\0" * (40 - len(guid))
    assert blob[48:112] == model.identifier.encode() + b"\0" * (64 - len(model.identifier))
    mode, failed, held, clock_active = struct.unpack_from("<4i", blob, 112)
    assert (mode, failed) == (4, 0)  # MODE_STEP_COMPLETE, no failed step
    step_base, step_size, step_count = struct.unpack_from("<ddQ", blob, 128)
    assert (step_base, step_size, step_count) == (0.0, h, steps)


def test_a_continuous_model_s_state_is_the_fixed_fields_then_its_values():
    model = _toy()
    blob, values, guid = _state_after_steps(model, 3, 0.1)
    n = len(value_references(model))
    assert len(blob) == FIXED + 8 * n
    _header(blob, model, guid, 3, 0.1)
    np.testing.assert_array_equal(np.frombuffer(blob[FIXED:], "<f8"), values)


def test_a_stochastic_model_s_state_holds_its_stream_and_draws_before_its_values():
    h = MAGNETOMETER.variable("dt").start
    blob, values, guid = _state_after_steps(MAGNETOMETER, 2, h)
    n, draws = len(value_references(MAGNETOMETER)), MAGNETOMETER.sampled.n_random_step
    assert len(blob) == FIXED + PCG64 + 8 * draws + 8 * n
    _header(blob, MAGNETOMETER, guid, 2, h)
    np.testing.assert_array_equal(np.frombuffer(blob[FIXED + PCG64 + 8 * draws:], "<f8"), values)
    pending = np.frombuffer(blob[FIXED + PCG64:FIXED + PCG64 + 8 * draws], "<f8")
    assert np.all((pending >= 0.0) & (pending < 1.0)) and len(set(pending)) == draws  # uniform draws
