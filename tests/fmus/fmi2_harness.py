"""A small FMI 2.0 harness for the tests: an instance with captured log
messages, value references by name, and stepping by a step counter."""
from __future__ import annotations

import os
import shutil
from functools import lru_cache

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model, FMU2Slave

from cosim.fmi.lifecycle import fmi2_callbacks
from fmu_models.models.quadrotor import STATE_NAMES
from tests.catalog_fmus import fmpy_class


def logged(value: float) -> str:
    """``value`` as the FMU writes it in a log message (``exact`` in
    ``fmu_models/export/c/fmu_core.c``): ``%g``, with more digits only where needed
    to read back as the same double."""
    for digits in range(6, 18):
        text = "%.*g" % (digits, value)
        if float(text) == value:
            break
    return text


def model_description(fmu_path):
    """fmpy's ``read_model_description`` of ``fmu_path`` (an FMU or its extracted folder), parsed once
    while the file is unchanged: a test of every parameter of every model instantiates an FMU several
    times a parameter, and parsing the XML took more than half of its time (the EKFs' descriptions are
    large). The object is shared: read it, never change it."""
    path = os.fspath(fmu_path)
    xml = os.path.join(path, "modelDescription.xml") if os.path.isdir(path) else path
    stat = os.stat(xml)
    return _parsed(os.path.realpath(path), stat.st_mtime_ns, stat.st_size, stat.st_ino)


@lru_cache(maxsize=256)
def _parsed(path, mtime_ns, size, inode):
    return read_model_description(path)


@lru_cache(maxsize=256)
def _value_references(md) -> dict[str, int]:
    """Each variable's value reference by name, made once per parsed description (an EKF's has some 300
    variables: the dict took about 0.2 ms of every one of the ~1200 instances of the range test)."""
    return {v.name: v.valueReference for v in md.modelVariables}


class LogCollector:
    """Receives the log messages of one FMI 2.0 instance (see
    :func:`cosim.fmi.lifecycle.fmi2_callbacks`, which holds ``receive`` weakly: keep the
    collector alive as long as the instance)."""

    def __init__(self) -> None:
        self.messages: list[str] = []
        self.callbacks = fmi2_callbacks(self.receive)

    def receive(self, status, message) -> None:
        self.messages.append(message.decode())


class Fmi2Instance:
    """One instantiated, initialized FMI 2.0 instance (CS by default).

    Made of fmpy's ``FMU2Slave`` (``FMU2Model``) as the tool makes its
    instances (:func:`cosim.fmi.lifecycle._fmpy_class`): the same class
    with each FMI function's C signature worked out once per process, not
    by ``inspect`` for every instance (about 2 ms of the 3 ms an instance
    took; the test of every parameter of every model makes some 1200), the
    signatures fmpy's own constructor gives (tests/engine/test_fmpy_classes.py);
    a library kept loaded and its table of functions made once per process
    (:func:`tests.catalog_fmus.fmpy_class`)."""

    def __init__(self, fmu_path, parameters=None, model_exchange=False, unzip_dir=None, initialize=True):
        self.md = model_description(fmu_path)
        self._own_dir = unzip_dir is None
        self.unzip_dir = unzip_dir or extract(fmu_path)
        self.vr = _value_references(self.md)  # shared, as the description: read it, never change it
        self.log = LogCollector()  # messages of this instance only
        self.messages = self.log.messages
        cls = fmpy_class(FMU2Model if model_exchange else FMU2Slave)
        self.fmu = cls(guid=self.md.guid, unzipDirectory=self.unzip_dir,
                       modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="test")
        self.fmu.instantiate(callbacks=self.log.callbacks)
        self.n = 0
        self.h = 0.01
        self.initialized = False
        if initialize:
            self.initialize(parameters or {})

    def initialize(self, parameters):
        self.enter_initialization(parameters)
        self.fmu.exitInitializationMode()
        self.initialized = True

    def enter_initialization(self, parameters=None):
        """Into Initialization Mode, where a value can first be read (FMI 2.0: not in Instantiated)."""
        self.fmu.setupExperiment(startTime=0.0)
        self.set(**(parameters or {}))
        self.fmu.enterInitializationMode()

    def set(self, **values):
        if values:
            self.fmu.setReal([self.vr[k] for k in values], [float(v) for v in values.values()])

    def get(self, *names):
        return np.array(self.fmu.getReal([self.vr[k] for k in names]))

    def step(self, n_steps=1, h=None):
        h = h or self.h
        for _ in range(n_steps):
            self.fmu.doStep(currentCommunicationPoint=self.n * h, communicationStepSize=h)
            self.n += 1

    def close(self):
        if self.initialized:  # terminate is refused before initialization
            self.fmu.terminate()
        self.fmu.freeInstance()
        if self._own_dir:
            shutil.rmtree(self.unzip_dir, ignore_errors=True)


STATES = STATE_NAMES
