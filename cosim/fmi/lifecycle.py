"""The lifecycle of an FMU instance, a part of
:class:`cosim.fmi.fmu.FmuComponent` (:class:`Lifecycle`): its library
loaded, instantiated with its log, set up, reset between runs and freed; and
the one place an FMI call's error status becomes this tool's exception.

* the FMU is extracted once and instantiated once per component;
  :meth:`Lifecycle.start` resets it between runs (``fmiXReset``); fmpy's
  classes are made with each FMI function's C signature worked out once per
  class (:func:`_fmpy_class`), one constructor at a time in the process;
* initialization by the standard: start values each set in the state the
  standard allows (:func:`~cosim.fmi.description.start_value_rule`), and
  Initialization Mode entered and left apart
  (:meth:`Lifecycle.enter_initialization`,
  :meth:`Lifecycle.exit_initialization`) so a master sets connected inputs
  there;
* the FMU's own log: it is instantiated with logging on, filtered by the
  level of the Python logger ``cosim.fmu.<instance>`` (:func:`cosim.fmi.log.fmu_log`,
  ``fnn-cosim run --fmu-log debug``, which also asks the FMU for every log
  category); its messages go to that logger, the last ones are kept
  (``FmuComponent.messages``, every message of status warning or worse
  whatever the level), and a failed call becomes an
  :class:`~cosim.errors.FmuCallError` quoting them; no message shows the
  temporary folder the FMU was extracted to (the FMU file's name stands for
  it); an instantiation the FMU refuses is an
  :class:`~cosim.errors.FmuLoadError` quoting its log;
* the one place FMI status codes become exceptions of this tool: fmpy's
  ``FMICallException`` (raised by its wrappers and by the fast path of
  :mod:`cosim.fmi.step`, one check) is turned into an
  :class:`~cosim.errors.FmuCallError` by :meth:`Lifecycle._fail`, which every
  call of the component goes through; no module but the component's
  (:mod:`cosim.fmi.fmu` and its parts) catches fmpy's exceptions or
  imports ``fmpy.fmi2``, ``fmpy.fmi3`` or ``fmpy.extract``;
* the random streams of a run's FMUs (:func:`stream_seed`), set at start as
  a seed parameter.
"""
from __future__ import annotations

import ctypes
import itertools
import shutil
import sys
import tempfile
import threading
import weakref
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from fmpy.fmi1 import FMICallException

from .description import start_value_rule
from ..errors import FmuCallError, FmuLoadError, ScenarioError
from .step import _Api

__all__ = ["Lifecycle", "fmi2_callbacks", "stream_seed"]

# fmpy loads an FMU's library from inside its folder: its constructor (fmi1._FMU.__init__) reads the
# working directory, changes to the library's folder and back. Two threads constructing at once (a
# study on a cluster of threads) left the process in one FMU's extracted folder, removed later with
# its cache: every later os.getcwd() failed. One constructor at a time in this process.
_LOADING = threading.Lock()

# fmpy's constructor gives every FMI function it loads from the library its C signature
# (fmpy.fmi1._FMU._loadFunctions, fmpy 0.3): it walks the instance's members (inspect.getmembers) and
# reads the annotations of every fmi2.../fmi3... method (inspect.signature), about 1.5 ms per instance for
# an answer that depends on the class only (an FMI 2.0 or 3.0 function has the same name in every
# library). The instances are made of subclasses of fmpy's classes (_fmpy_class) whose _loadFunctions runs
# fmpy's for the first instance of a class and keeps what it set on each function; a later instance sets
# the same on its own library's functions, in the same order (a library missing a function fails at the
# same name, with ctypes' own AttributeError). Decided: this reaches into fmpy's _loadFunctions and
# _functions; when fmpy no longer has them its classes are used as they are (docs/cosim.md, "Start-up of
# a run"). fmpy class -> ((method, C function, argnames, argtypes, restype), ...), as _loadFunctions set them.
_SIGNATURES: dict[type, tuple[tuple[str, str, Any, Any, Any], ...]] = {}
_FMPY_CLASSES: dict[type, type] = {}


def _load_functions(self) -> None:
    """fmpy's ``_loadFunctions`` for the first instance of a class, the kept signatures for the others."""
    base = type(self).__mro__[1]
    table = _SIGNATURES.get(base)
    if table is None:
        base._loadFunctions(self)
        _SIGNATURES[base] = tuple((name, f.__name__, f.argnames, f.argtypes, f.restype)
                                  for name, f in self._functions.items())
        return
    dll, functions = self.dll, self._functions
    for name, c_name, argnames, argtypes, restype in table:
        f = getattr(dll, c_name)
        f.argnames, f.argtypes, f.restype = argnames, argtypes, restype
        functions[name] = f


def _fmpy_class(base: type) -> type:
    """The class to construct for fmpy's ``base`` (``FMU2Slave``, ``FMU2Model``,
    ``FMU3Slave``, ``FMU3Model``): a subclass whose FMI functions' signatures
    are worked out once per process (see above), of the same name (fmpy's
    ``_loadFunctions`` picks the FMI version by it)."""
    made = _FMPY_CLASSES.get(base)
    if made is None:
        from fmpy.fmi1 import _FMU

        kept = callable(getattr(_FMU, "_loadFunctions", None)) and "_loadFunctions" not in vars(base)
        made = _FMPY_CLASSES[base] = type(base.__name__, (base,), {
            "_loadFunctions": _load_functions, "__module__": __name__, "__doc__": base.__doc__}) if kept else base
    return made


# The FMUs' log goes through the logging module (cosim.fmi.log), imported when an FMU first logs: a
# process that has not imported logging has configured no logger, so every level is the root's default
# (logging.WARNING) and nothing below it is asked for (a run of FMUs that log nothing imports no logging).
_UNCONFIGURED_LEVEL, _DEBUG = 30, 10  # logging.WARNING, logging.DEBUG


_FMI2_LOGGER = None
_FMI2_LOG_RECEIVERS: dict[int, weakref.WeakMethod] = {}
_KEYS = itertools.count(1)


def _dispatch_fmi2_log(env, instance, status, category, message) -> None:
    ref = _FMI2_LOG_RECEIVERS.get(env or 0)
    receiver = ref() if ref is not None else None
    if receiver is not None:
        receiver(status, message)


def fmi2_callbacks(receive_log):
    """FMI 2.0 callbacks whose log messages reach ``receive_log(status, message)``
    (a bound method, held weakly), formatted by fmpy's variadic-logger proxy.

    fmpy's proxy keeps one Python logger per process, so every FMI 2.0
    instance shares one dispatcher and is told apart by its
    componentEnvironment, a key into the receivers. Keep the returned
    structure alive as long as the instance.
    """
    from fmpy.fmi1 import calloc, free
    from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                           fmi2CallbackLoggerTYPE)
    from fmpy.logging import addLoggerProxy

    global _FMI2_LOGGER
    if _FMI2_LOGGER is None:
        _FMI2_LOGGER = fmi2CallbackLoggerTYPE(_dispatch_fmi2_log)
    key = next(_KEYS)
    _FMI2_LOG_RECEIVERS[key] = weakref.WeakMethod(receive_log)
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _FMI2_LOGGER
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = key
    addLoggerProxy(ctypes.byref(callbacks))
    return callbacks


def stream_seed(seed: int, stream: int) -> int:
    """The seed of random stream ``stream`` of a run seeded ``seed``: the run's
    seed itself for stream 0 (what the Python components draw from), for
    stream k > 0 a 53-bit number from numpy's ``SeedSequence(seed,
    spawn_key=(k,))``, the child stream numpy spawns for independent
    generators. Two FMUs of one run on different streams draw independent
    numbers; on the same stream, the same numbers."""
    if stream == 0:
        return int(seed)
    state = np.random.SeedSequence(int(seed), spawn_key=(int(stream),)).generate_state(1, np.uint64)[0]
    return int(state) >> 11  # 64 - 11 = 53 bits: exact as a double parameter


class Lifecycle:
    """The lifecycle of :class:`cosim.fmi.fmu.FmuComponent`'s instance
    (a part of that class, not used alone): instantiate, set up (start,
    Initialization Mode), reset, close, and :meth:`_fail`."""

    _abandoned: list = []  # instances that returned fmiFatal, never freed (close), with what they call back

    def _hide_folder(self, text: str) -> str:
        """``text`` with the temporary extraction folder (a path or a file
        URI, as the FMU was given it) replaced by the FMU file's name: a
        message never shows a temporary folder (docs/security.md)."""
        for shown, name in self._hidden:
            if shown in text:
                text = text.replace(shown, name)
        return text

    def _log(self, status: int, message: bytes | str) -> None:
        """One message of the FMU's own log: to the instance's logger, and
        kept for the errors that quote it (every message of status warning or
        worse; those of status OK only at level info or debug, when asked
        for, so that chatter never pushes the reason out)."""
        import logging

        from .log import STATUS_LABEL, STATUS_LEVEL

        text = self._hide_folder(message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message))
        known = 0 <= status < len(STATUS_LABEL)
        label = STATUS_LABEL[status] if known else str(status)
        level = STATUS_LEVEL[status] if known else logging.ERROR
        if level >= logging.WARNING or self._log_level <= logging.INFO:
            self.messages.append(f"[{label}] {text}")
        if self.logger.isEnabledFor(level):
            self.logger.log(level, " ".join(text.split()))

    def _apply_log_level(self) -> None:
        """At level ``debug``, ask the FMU for every log category
        (``fmiXSetDebugLogging(loggingOn, 0 categories)``: all of those its
        LogCategories declare, FMI 2.0 section 2.1.5, FMI 3.0 section 2.3.2).
        Below it the FMU logs as instantiated with logging on, and the level
        filters in Python (:meth:`_log`): asking for fewer categories would
        lose what some FMUs log under none (PythonFMU 0.7 reports a failed
        step's exception without a category, and drops it once categories are
        named), and an error must quote every message of status warning or
        worse."""
        if self._log_level > _DEBUG:
            return
        try:
            self._slave.setDebugLogging(True, [])
        except FMICallException as exc:  # a log refused is no reason to refuse the run: said, not raised
            self.logger.warning("fmiSetDebugLogging(all categories) refused (%s)", exc)

    def instantiate(self) -> None:
        """Extract (once, within the limits of :func:`cosim.files.extract_zip`)
        and instantiate the FMU with logging on, then set its log categories
        (:meth:`_apply_log_level`); idempotent. An instantiation the FMU
        refuses is an :class:`~cosim.errors.FmuLoadError` quoting what the FMU
        logged (e.g. a PythonFMU's ``ModuleNotFoundError``)."""
        if self._slave is not None:
            return
        if self.path.is_dir():
            self._unzipdir = self.path
        else:
            self._unzipdir = self._claim_extracted()
            if self._unzipdir is None:
                from ..files import extract_zip

                try:
                    self._unzipdir = extract_zip(self.path, tempfile.mkdtemp(prefix="fmu-"),
                                                 "cannot extract the archive", only=self._run_time_files())
                except ScenarioError as exc:
                    raise FmuLoadError(self.name, self.path, str(exc)) from None
                self._owns_unzipdir = True
            folder = Path(self._unzipdir)
            forms = {folder.as_uri(): self.path.name, str(folder): self.path.name,
                     folder.resolve().as_uri(): self.path.name, str(folder.resolve()): self.path.name}
            self._hidden = tuple(sorted(forms.items(), key=lambda kv: -len(kv[0])))  # the URI before the path
        md = self.model_description
        common = dict(guid=md.guid, unzipDirectory=str(self._unzipdir),
                      modelIdentifier=self.kind.modelIdentifier, instanceName=self.name)
        self.messages.clear()
        self._log_level = self.logger.getEffectiveLevel() if "logging" in sys.modules else _UNCONFIGURED_LEVEL
        model_exchange = self.interface == "ModelExchange"
        try:
            if self.fmi_version == 2:
                from fmpy.fmi2 import FMU2Model, FMU2Slave

                with _LOADING:
                    slave = _fmpy_class(FMU2Model if model_exchange else FMU2Slave)(**common)
                self._callbacks = fmi2_callbacks(self._log)  # keep alive as long as the instance
                slave.instantiate(callbacks=self._callbacks, loggingOn=True)
            else:
                from fmpy.fmi3 import FMU3Model, FMU3Slave

                log = lambda env, status, category, message: self._log(status, message)  # noqa: E731
                with _LOADING:
                    slave = _fmpy_class(FMU3Model if model_exchange else FMU3Slave)(**common)
                if model_exchange:
                    slave.instantiate(loggingOn=True, logMessage=log)
                else:
                    slave.instantiate(loggingOn=True, eventModeUsed=self.clock is not None, logMessage=log)
        except Exception as exc:  # fmpy raises plain Exceptions here; the FMU's log says why
            said = "; ".join(self.messages)
            reason = self._hide_folder(said or str(exc))
            self.close()
            raise FmuLoadError(self.name, self.path, f"instantiation failed: {reason}") from None
        self._slave = slave
        self._api = _Api(slave, self.fmi_version, self.interface == "CoSimulation")
        self._apply_log_level()

    def close(self) -> None:
        """Free the instance and remove what :meth:`instantiate` extracted.
        An instance that returned ``fmiFatal`` is left alone: after it the
        standard allows no call, ``fmiXFreeInstance`` included (FMI 2.0
        section 2.1.3, FMI 3.0 section 2.2.3), and a PythonFMU freed then
        corrupts the embedded interpreter; its library stays loaded."""
        if self._slave is not None:
            if not self._fatal:
                try:
                    self._slave.terminate()
                except Exception:
                    pass
                try:
                    self._slave.freeInstance()
                except Exception:
                    pass
            else:
                self._abandoned.append((self._slave, getattr(self, "_callbacks", None)))  # its callbacks stay valid
            self._slave = None
            if self.system is not None:
                self.system.close()
        if self._owns_unzipdir and self._unzipdir is not None:
            shutil.rmtree(self._unzipdir, ignore_errors=True)
            self._unzipdir = None
            self._owns_unzipdir = False

    def __enter__(self) -> "FmuComponent":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _fail(self, what: str, exc: Exception, t: float | None = None, variable: str | None = None,
              value: float | None = None) -> FmuCallError:
        """The one place an FMI call's error status (fmpy's ``FMICallException``,
        or what a caller found wrong) becomes this tool's exception: an
        :class:`~cosim.errors.FmuCallError` saying what was asked, and
        quoting the FMU's own log."""
        if getattr(exc, "status", None) == 4:  # fmiFatal: no further call (close)
            self._fatal = True
        when = f"at t = {t:.4f} s: " if t is not None else ""
        log = "; ".join(self.messages)
        return FmuCallError(self.name, self.path,
                            self._hide_folder(f"{when}{what} failed ({exc}); FMU log: "
                                              f"{log or '(the FMU logged nothing)'}"),
                            variable, value, log)

    def start(self, t0: float, parameters: Mapping[str, float] | None = None,
              inputs: Mapping[str, float] | None = None) -> None:
        """Reset (after the first run), set ``parameters`` (start values of
        any variable the standard lets an importer set, :func:`start_value_rule`),
        initialize at ``t0`` with ``inputs`` set in Initialization Mode, and
        read the bound outputs at ``t0`` into :attr:`y`: :meth:`enter_initialization`
        then :meth:`exit_initialization`, which a master calls apart to set
        connected inputs in between."""
        self.enter_initialization(t0, parameters)
        if inputs:
            self.set_inputs(inputs, t0)
        self.exit_initialization(t0)

    def enter_initialization(self, t0: float, parameters: Mapping[str, float] | None = None) -> None:
        """Reset (after the first run), set the start values ``parameters``
        in the state the standard allows for each (FMI 2.0 §3.2.3 / §4.2.4,
        FMI 3.0 §2.3.4: Instantiated, else Initialization Mode) and enter
        Initialization Mode at ``t0``; the outputs are read into :attr:`y`
        (the initial unknowns, computed from the start values and the inputs
        set so far).

        Values are set one by one, so a refusal names the variable
        (:attr:`FmuCallError.variable`) and quotes the FMU's reason.
        """
        self.instantiate()
        s = self._slave
        self.messages.clear()
        if self.system is not None:  # a Model Exchange system waits for every member to leave Initialization Mode
            self.system.entering(self)
        self._tick_pending = False  # a clocked FMU ticks from Event Mode on, after initialization
        parameters = dict(parameters or {})
        rules = self._start_rules
        for key, value in parameters.items():
            if key not in rules:
                rules[key] = self._start_rule(key)
            why = rules[key][0]
            if why:
                raise FmuCallError(self.name, self.path, f"{key!r} {why}", key, value)
        try:
            if self._initialized_once:
                s.reset()
        except FMICallException as exc:
            raise self._fail("reset", exc) from None
        self._initialized_once = True  # from here on, parameters may be set: the next start resets
        later = {k: v for k, v in parameters.items() if not rules[k][1]}
        self._set_start_values({k: v for k, v in parameters.items() if k not in later}, together=True)
        self._initial_parameters = parameters
        try:
            if self.fmi_version == 2:
                s.setupExperiment(startTime=t0)
                s.enterInitializationMode()
            else:
                s.enterInitializationMode(startTime=t0)
        except FMICallException as exc:
            raise self._fail("initialization with " + (repr(parameters) if parameters else "default parameters"),
                             exc) from None
        self._set_start_values(later)
        self._initializing = True
        self.read_outputs(t0)

    def _start_rule(self, name: str) -> tuple[str | None, bool]:
        """Whether the variable ``name`` takes a start value (why not:
        :func:`start_value_rule`) and whether in the Instantiated state
        (fmpy's ``settable_in_instantiated``; else in Initialization Mode):
        facts of the model description, asked once per variable (a study
        starts an FMU with the same 20 names thousands of times)."""
        from fmpy.simulation import settable_in_instantiated

        variable = self.variables.get(name)
        why = start_value_rule(variable)
        return why, why is None and settable_in_instantiated(variable)

    def exit_initialization(self, t0: float) -> None:
        """Leave Initialization Mode at ``t0`` (a Model Exchange instance: the
        initial event iteration, Continuous-Time Mode, its solver at ``t0``;
        a clocked FMU: Event Mode at its first tick) and read the outputs."""
        s = self._slave
        try:
            s.exitInitializationMode()
        except FMICallException as exc:
            parameters = self._initial_parameters
            raise self._fail("initialization with " + (repr(parameters) if parameters else "default parameters"),
                             exc) from None
        self._initializing = False
        if self.model_exchange:
            if self.system is None:  # not given one by a master: a system of one
                from .me_system import ModelExchangeSystem

                ModelExchangeSystem([self])
            self.system.initialized(self, t0)
            self._t = t0
            self._u_set = None
        self._tick_pending = self.clock is not None
        self.read_outputs(t0)
