"""A sampled FMU of the catalog stepped by fmpy, row by row: the sensor,
link and estimator tests' harness (tests/fmus/test_sensors_fmu.py and the
files after it; the estimators' outputs of tests/paper/test_estimation_gating.py)."""
from __future__ import annotations

from ctypes import c_double, c_uint

import numpy as np
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from tests.catalog_fmus import catalog_fmu, fmpy_class, loaded

from cosim.fmi.lifecycle import fmi2_callbacks
from fmu_models.models.sensors import MEASUREMENT_12

__all__ = ["DT", "Sensor"]

DT = 0.01


class Sensor:
    """One initialized instance of a sensor FMU through fmpy (its classes as
    the tool makes its instances, :func:`cosim.fmi.lifecycle._fmpy_class`:
    the FMI functions' C signatures worked out once per process, which fmpy's
    own constructor does by ``inspect`` for each instance, 10-20 ms of an
    FMI 3.0 one)."""

    def __init__(self, model=MEASUREMENT_12, version=2, parameters=None, initialize=True):
        self.md, folder = loaded(catalog_fmu(model, version))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages = []
        self.inputs = [v.name for v in model.inputs]
        self.outputs = [v.name for v in model.outputs]
        common = dict(guid=self.md.guid, unzipDirectory=folder,
                      modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="sensor")
        if version == 2:
            self.fmu = fmpy_class(FMU2Slave)(**common)
            self._callbacks = fmi2_callbacks(self._receive)
            self.fmu.instantiate(callbacks=self._callbacks)
            self.set, self.get = self.fmu.setReal, self.fmu.getReal
        else:
            self.fmu = fmpy_class(FMU3Slave)(**common)
            self.fmu.instantiate(logMessage=lambda env, status, cat, msg: self.messages.append(msg.decode()))
            self.set, self.get = self.fmu.setFloat64, self.fmu.getFloat64
        self.version = version
        self.n = 0
        if initialize:
            self.initialize(parameters or {})

    def _receive(self, status, message):
        self.messages.append(message.decode())

    def initialize(self, parameters):
        for name, value in parameters.items():
            self.set([self.vr[name]], [float(value)])
        if self.version == 2:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def sample(self, u, read_before=True) -> np.ndarray:
        """Set the inputs of t_n, (read the outputs,) step, read the held outputs."""
        self.set([self.vr[n] for n in self.inputs], [float(x) for x in u])
        before = np.array(self.get([self.vr[n] for n in self.outputs])) if read_before else None
        self.fmu.doStep(self.n * DT, DT)
        self.n += 1
        after = np.array(self.get([self.vr[n] for n in self.outputs]))
        if before is not None:
            np.testing.assert_array_equal(before, after)  # sample and hold, same draws
        return after

    def run(self, inputs, read_before=True) -> np.ndarray:
        if read_before:
            return np.array([self.sample(u, read_before) for u in inputs])
        # sample's calls (fmpy's FMI functions, its status checks included) on the value references and
        # on each row of the inputs and of the outputs as C arrays made once, not converted from and to
        # Python lists at every step: the same calls and values, a third (a sensor) to a half (an EKF) less
        # CPU over the statistics' and the estimators' thousands of steps
        ins, outs = [self.vr[n] for n in self.inputs], [self.vr[n] for n in self.outputs]
        u = np.ascontiguousarray(inputs, dtype=np.float64)
        rows = np.empty((len(u), len(outs)))
        vr_in, vr_out = (c_uint * len(ins))(*ins), (c_uint * len(outs))(*outs)
        row_in = c_double * len(ins)
        row_out = c_double * len(outs)
        fmu, instance = self.fmu, self.fmu.component
        for k in range(len(u)):
            given, taken = row_in.from_buffer(u, k * u.strides[0]), row_out.from_buffer(rows, k * rows.strides[0])
            if self.version == 2:
                fmu.fmi2SetReal(instance, vr_in, len(ins), given)
                fmu.doStep(self.n * DT, DT)
                fmu.fmi2GetReal(instance, vr_out, len(outs), taken)
            else:
                fmu.fmi3SetFloat64(instance, vr_in, len(ins), given, len(ins))
                fmu.doStep(self.n * DT, DT)
                fmu.fmi3GetFloat64(instance, vr_out, len(outs), taken, len(outs))
            self.n += 1
        return rows
