"""An FMU as a component of the master: a thin, fast wrapper over fmpy's
instances, Co-Simulation (``FMU2Slave``, ``FMU3Slave``) or Model Exchange
(``FMU2Model``, ``FMU3Model``, integrated by :mod:`cosim.fmi.me_system`).

fmpy's classes do the loading, instantiation and status checking (every
failed call raises fmpy's ``FMICallException`` in one place). This module
adds what the master needs:

* the FMU is extracted once and instantiated once per :class:`FmuComponent`;
  :meth:`FmuComponent.start` resets it between runs (``fmiXReset``);
* ports read from the modelDescription (:mod:`cosim.fmi.description`: name,
  causality, type, shape, unit and its ``UnitDefinitions`` meaning), so the
  master can check connections before the first step;
* initialization by the standard: start values each set in the state the
  standard allows (:func:`~cosim.fmi.description.start_value_rule`), and
  Initialization Mode entered and left apart
  (:meth:`FmuComponent.enter_initialization`,
  :meth:`FmuComponent.exit_initialization`) so a master sets connected
  inputs there;
* a per-step fast path: the value references of the connected inputs and of
  the wanted outputs are bound once (:meth:`bind`) into ctypes arrays, and each
  step is one ``set`` of all inputs, one ``doStep`` and one ``get`` of all
  outputs, the values passing through preallocated numpy buffers with no
  per-step allocation;
* the FMU's own log: it is instantiated with logging on, filtered by the
  level of the Python logger ``cosim.fmu.<instance>`` (:func:`cosim.fmi.log.fmu_log`,
  ``fnn-cosim run --fmu-log debug``, which also asks the FMU for every log
  category); its messages go to
  that logger, the last ones are kept (:attr:`FmuComponent.messages`, every
  message of status warning or worse whatever the level), and a failed call
  becomes an :class:`~cosim.errors.FmuCallError` quoting them; no message
  shows the temporary folder the FMU was extracted to (the FMU file's name
  stands for it);
* the one place FMI status codes become exceptions of this tool: fmpy's
  ``FMICallException`` (raised by its wrappers and by the fast path, one
  check) is turned into an :class:`~cosim.errors.FmuCallError` by
  :meth:`FmuComponent._fail`, which every call of this module goes through;
  no other module catches fmpy's exceptions or imports ``fmpy.fmi2``,
  ``fmpy.fmi3`` or ``fmpy.extract``;
* the one reader of the modelDescription's extras fmpy does not read
  (annotations, the FMI 3.0 directional-derivative flag):
  :meth:`FmuComponent._extras`;
* the Model Exchange calls a linearizer needs (continuous states,
  derivatives, nominals, event indicators, directional derivatives) and
  the editing of a serialized FMU state on the live instance
  (:meth:`FmuComponent.state_values`, :meth:`FmuComponent.state_with`);
* a file that is no usable FMU (not a zip archive, a broken
  modelDescription.xml, no binary for this platform, an instantiation the FMU
  refuses) is an :class:`~cosim.errors.FmuLoadError` that names the file and
  the cause in one line, raised when the component is made;
* a sampled-data FMU's declaration of its period parameter (an annotation of
  its modelDescription, :data:`PERIOD_ANNOTATION`) is read into
  :attr:`FmuComponent.sample_period`, so a master can refuse a communication
  step the FMU cannot take before anything runs;
* a clocked FMI 3.0 FMU (a periodic input clock, this project's sampled-data
  FMUs: docs/fmi-export.md, "Clocks") runs in Co-Simulation with Event Mode:
  at each communication point, a tick, the clock is activated before the
  inputs are set, and :meth:`FmuComponent.do_step` computes the tick
  (``fmi3UpdateDiscreteStates``), steps to the next tick and enters Event Mode
  again. The values are those of the FMI 2.0 FMU, bit for bit; the master runs
  such an FMU in its Python loop (the compiled loop makes set, get and doStep
  calls only).
"""
from __future__ import annotations

import ctypes
import functools
import itertools
import os
import shutil
import sys
import tempfile
import threading
import weakref
from collections import deque
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from fmpy import platform, platform_tuple, read_model_description, sharedLibraryExtension
from fmpy.fmi1 import FMICallException

from ..component import element_of, typed_value
from .description import TYPE_OF, PERIOD_ANNOTATION, shape_of, fmu_ports, start_value_rule
from ..errors import FmuCallError, FmuLoadError, ScenarioError, SimulationTerminated
from ..limits import SEED_LIMIT
from .c_calls import Call, KernelFmu

__all__ = ["FmuComponent", "fmi2_callbacks", "stream_seed", "read_description"]

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


@functools.lru_cache(maxsize=64)
def _parsed_model_description(path: str, size: int, mtime_ns: int, validate: bool):
    """fmpy's parse of the FMU at ``path`` as it is now (its size and time of
    change in the key: a rewritten file is read again). A study's worker
    builds a master per case over the same FMU files: each was parsed again
    (lxml, about 3.5 ms each, a fifth of a master's build). Nothing changes
    the parsed description; a failure is not kept."""
    return read_model_description(path, validate=validate)


def read_description(name: str, path: Path, validate: bool = False):
    """fmpy's reading of the modelDescription of the FMU ``path`` (instance
    ``name``), and the XML's bytes if it is an archive; its failures told in
    one line (:class:`FmuLoadError`). The archive is looked at first (a
    regular file, every entry within the limits of :mod:`cosim.files`): an
    FMU file is data from anyone. Loads nothing."""
    import zipfile

    from ..files import read_entry, regular_file, zip_members
    from ..limits import MAX_DOCUMENT_BYTES

    path, xml = Path(path), None
    try:
        if not path.is_dir():
            regular_file(path, "FMU")
            with zipfile.ZipFile(path) as archive:
                entry = zip_members(archive, "the archive").get("modelDescription.xml")
                if entry is not None and entry.file_size > 4 * MAX_DOCUMENT_BYTES:
                    raise FmuLoadError(name, path, f"modelDescription.xml is {entry.file_size} bytes; at most "
                                                   f"{4 * MAX_DOCUMENT_BYTES} are read")
                if entry is not None:  # corrupt data is told here, naming the entry (read again by fmpy)
                    xml = read_entry(archive, entry, "the archive")
    except ScenarioError as exc:
        raise FmuLoadError(name, path, str(exc).removeprefix(f"FMU {str(path)!r}: ")) from None
    except (zipfile.BadZipFile, OSError, NotImplementedError, RuntimeError, EOFError, ValueError) as exc:
        raise FmuLoadError(name, path, f"not an FMU: not a zip archive ({exc})") from None
    try:
        where = path / "modelDescription.xml" if path.is_dir() else path
        stat = where.stat()
        return _parsed_model_description(str(path), stat.st_size, stat.st_mtime_ns, validate), xml
    except zipfile.BadZipFile as exc:
        reason = f"not an FMU: not a zip archive ({exc})"
    except KeyError:
        reason = "not an FMU: the archive holds no modelDescription.xml"
    except OSError as exc:
        reason = f"cannot read modelDescription.xml: {exc.strerror or exc}"
    except Exception as exc:  # lxml's syntax errors, fmpy's validation and attribute errors
        reason = f"broken modelDescription.xml: {type(exc).__name__}: {exc}"
    raise FmuLoadError(name, path, reason) from None


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


def _bare(slave, name: str):
    """The FMI function ``name`` of ``slave``'s library without fmpy's Python
    wrapper and without ctypes argument types: called with ctypes objects
    prepared once, it costs about half as much per call (measured 1.0 against
    2.1 us); the status is checked by the caller."""
    address = ctypes.cast(slave._functions[name], ctypes.c_void_p).value
    return ctypes.CFUNCTYPE(ctypes.c_int)(address)


class _Api:
    """The three calls of the per-step fast path for one FMI version (set,
    get, step), each raising fmpy's ``FMICallException`` on an error status
    as fmpy's own wrappers do."""

    def __init__(self, slave, version: int, co_simulation: bool = True):
        self.slave, self.version = slave, version
        self._component = ctypes.c_void_p(slave.component)
        names = ("fmi2SetReal", "fmi2GetReal", "fmi2DoStep") if version == 2 else \
            ("fmi3SetFloat64", "fmi3GetFloat64", "fmi3DoStep")
        self._names = names  # indexed by Call
        self._set, self._get = (_bare(slave, n) for n in names[:2])
        self._step = _bare(slave, names[2]) if co_simulation else None  # Model Exchange: the master integrates
        if version == 2:
            self._step_tail = (ctypes.c_int(1),)  # noSetFMUStatePriorToCurrentPoint
        else:
            self.terminate = ctypes.c_bool()  # fmi3DoStep's terminateSimulation, read after each step
            self._step_tail = (ctypes.c_bool(True), ctypes.byref(ctypes.c_bool()), ctypes.byref(self.terminate),
                               ctypes.byref(ctypes.c_bool()), ctypes.byref(ctypes.c_double()))

    def _check(self, status: int, which: Call) -> None:
        if status > 1:  # fmiWarning is fine; discard, error, fatal are not
            raise FMICallException(function=self._names[which], status=status)

    def set(self, vrs, n: ctypes.c_size_t, values_ptr) -> None:
        if self.version == 2:
            self._check(self._set(self._component, vrs, n, values_ptr), Call.SET)
        else:
            self._check(self._set(self._component, vrs, n, values_ptr, n), Call.SET)

    def get(self, vrs, n: ctypes.c_size_t, values_ptr) -> None:
        if self.version == 2:
            self._check(self._get(self._component, vrs, n, values_ptr), Call.GET)
        else:
            self._check(self._get(self._component, vrs, n, values_ptr, n), Call.GET)

    def do_step(self, t: float, h: float) -> None:
        self._check(self._step(self._component, ctypes.c_double(t), ctypes.c_double(h), *self._step_tail), Call.STEP)


class FmuComponent:
    """One instance of a co-simulation FMU (FMI 2.0 or 3.0).

    Parameters
    ----------
    name : str
        Instance name, used in connections (``name.variable``) and messages.
    path : path of the ``.fmu`` file, or of an already extracted FMU directory.
    validate : bool
        Validate the modelDescription against the FMI schema while reading it
        (fmpy's check). Off by default: our FMUs are validated by their own
        tests, and third-party FMUs often carry harmless schema problems.
    parameters : parameter values set at every start (before run-level ones).
    seed_parameter : the name of a parameter set to the run's seed at every
        start (an FMU that draws random numbers, seeded like the Python
        components).
    seed_stream : which of the run's random streams seeds it
        (:func:`stream_seed`; 0: the run's seed itself).
    interface : ``"CoSimulation"`` or ``"ModelExchange"``; by default
        Co-Simulation where the FMU has it, else Model Exchange. A Model
        Exchange instance is integrated by the master's solver, with the Model
        Exchange FMUs connected to it (:mod:`cosim.fmi.me_system`); a clocked FMI 3.0 FMU
        without continuous states in Model Exchange has its ticks as time
        events and nothing to integrate (docs/cosim.md, "Clocked FMUs").
    solver : :class:`~cosim.fmi.model_exchange.SolverSettings` of a Model
        Exchange instance (default: CVODE at the tolerance of the FMU's
        default experiment, else 1e-5).

    Attributes
    ----------
    sample_period : str or None
        The parameter a sampled-data FMU declares as its period, the one
        communication step it takes (:data:`PERIOD_ANNOTATION`); ``None`` if
        it declares none.
    clock : int or None
        The value reference of a clocked FMI 3.0 FMU's input clock, which
        ticks at every communication point; ``None`` for an FMU without one.
    """

    _abandoned: list = []  # instances that returned fmiFatal, never freed (close), with what they call back

    def __init__(self, name: str, path: str | Path, validate: bool = False,
                 parameters: Mapping[str, float] | None = None, seed_parameter: str | None = None,
                 seed_stream: int = 0, interface: str | None = None, solver=None):
        self.name = name
        self.path = Path(path)
        self.base_parameters = dict(parameters or {})
        self.seed_parameter = seed_parameter
        self.seed_stream = seed_stream
        self.model_description = md = self._read_model_description(validate)
        self.fmi_version = int(md.fmiVersion.split(".")[0])
        if self.fmi_version not in (2, 3):
            raise FmuLoadError(name, self.path, f"FMI {md.fmiVersion} is not supported (2.0 or 3.0)")
        if interface is None:
            interface = "CoSimulation" if md.coSimulation is not None else "ModelExchange"
        if interface not in ("CoSimulation", "ModelExchange"):
            raise FmuLoadError(name, self.path, "expected 'CoSimulation' or 'ModelExchange'",
                               setting=("interface", interface))
        self.interface = interface
        self.kind = md.coSimulation if interface == "CoSimulation" else md.modelExchange
        if md.coSimulation is None and md.modelExchange is None:
            raise FmuLoadError(name, self.path, "the FMU has neither Co-Simulation nor Model Exchange (Scheduled "
                               "Execution only: the master does not drive it; docs/fmi-support.md)")
        if self.kind is None:
            has = "Model Exchange" if md.modelExchange is not None else "Co-Simulation"
            raise FmuLoadError(name, self.path, f"the FMU has no {'Co-Simulation' if interface == 'CoSimulation' else 'Model Exchange'} "
                               f"interface (it has {has} only)", setting=("interface", interface))
        self._solver_given, self._solver = solver, None  # resolved when first asked for (solver)
        self._check_binary()
        groups = fmu_ports(md)
        self.inputs, self.outputs, self.parameters = groups["input"], groups["output"], groups["parameter"]
        self.internals = groups["local"]  # recorded and bounded like outputs, read with them (cosim.loop.plan)
        self.variables = {v.name: v for v in md.modelVariables}
        self.sample_period = self._declared_period()
        self.clock = self._input_clock()
        self.model_exchange = interface == "ModelExchange" and self.clock is None  # integrated by the master
        self.system = None  # Model Exchange: the cosim.fmi.me_system.ModelExchangeSystem integrating it
        self._me_member = None  # its MeMember in that system's C structure
        self._tick_pending = False  # clocked: in Event Mode at a tick whose clock is not yet activated
        if seed_parameter is not None and getattr(self.variables.get(seed_parameter), "causality", None) != "parameter":
            raise FmuLoadError(name, self.path, "no parameter of the FMU", setting=("seed_parameter", seed_parameter))
        self.feedthrough = self._feedthrough(md)
        self.messages: deque[str] = deque(maxlen=20)
        self._log_level = _UNCONFIGURED_LEVEL  # the logger's, read at instantiation
        self._hidden: tuple[tuple[str, str], ...] = ()  # (the extraction folder as written, what stands for it)
        self._fatal = False  # the FMU returned fmiFatal: no call may follow
        self._slave = None
        self._unzipdir: Path | None = None
        self._owns_unzipdir = False
        self._initialized_once = False
        self._initializing = False
        self._kernel_exception: BaseException | None = None
        self._initial_parameters: dict[str, Any] = {}
        self._u_set: np.ndarray | None = None  # Model Exchange: the inputs last set (the solver restarts on a change)
        self._t = 0.0
        self.bind((), ())
        self._keep_description(validate)

    @property
    def solver(self):
        """How the master integrates this FMU in Model Exchange
        (:class:`cosim.fmi.model_exchange.SolverSettings`, the one given or the
        defaults, its tolerance resolved for this FMU), made when first asked
        for: a Co-Simulation FMU never asks."""
        if self._solver is None:
            from .model_exchange import SolverSettings

            given = self._solver_given
            self._solver = (given if given is not None else SolverSettings()).for_fmu(self.model_description)
        return self._solver

    @property
    def logger(self):
        """The Python logger of this instance's FMU log, ``cosim.fmu.<instance>``
        (:mod:`cosim.fmi.log`; logging imported when first asked for)."""
        import logging

        from .log import FMU_LOGGER

        return logging.getLogger(f"{FMU_LOGGER}.{self.name}")

    def python_loop_reason(self, signals: Sequence[str] = ()) -> str | None:
        """Why the master's compiled loop, which makes set, get and doStep
        calls of Float64 scalars only, cannot drive this FMU (the plan then
        takes the Python loop: :attr:`cosim.loop.plan.Plan.python_loop`); ``None``
        if it can. ``signals``: the inputs set and outputs read in the run
        (elements ``y[i]`` of arrays): one of another type than Float64, or
        an array's, is a reason."""
        if self.clock is not None:
            return "a clocked FMU: its ticks are Event Mode calls"
        types, arrays = {}, []
        for name in signals:
            var = self._element(name)[0]
            port_type = TYPE_OF.get(var.type, var.type)
            if port_type != "Float64":
                types.setdefault(port_type, name)
            elif var.dimensions and var.name not in arrays:
                arrays.append(var.name)
        if types:
            told = ", ".join(f"{t} ({n})" for t, n in types.items())
            return f"signals of type {told}: the compiled loop carries Float64 scalars only"
        if arrays:
            return f"array variable(s) {', '.join(arrays)}: the compiled loop carries Float64 scalars only"
        return None

    def _feedthrough(self, md) -> dict[str, frozenset[str]]:
        """Output name -> the inputs it depends on directly (ModelStructure;
        an output without a dependencies list depends on all of them)."""
        inputs = frozenset(p.name for p in self.inputs)
        out = {}
        for unknown in md.outputs:
            deps = unknown.dependencies
            out[unknown.variable.name] = inputs if deps is None else frozenset(d.name for d in deps) & inputs
        return out

    def _read_model_description(self, validate: bool):
        """fmpy's ModelDescription of the FMU: kept from an earlier reading of
        the same bytes (:mod:`cosim.fmi.description_cache`: no XML parsed, no
        archive opened), else read (:func:`read_description`)."""
        from .description_cache import kept_description

        self._kept = None if validate or self.path.is_dir() else kept_description(self.path)
        if self._kept is not None:
            self._description_xml = None
            return self._kept.model_description
        md, self._description_xml = read_description(self.name, self.path, validate)
        return md

    def _keep_description(self, validate: bool) -> None:
        """Keep what was read of an FMU file, now checked in full
        (:mod:`cosim.fmi.description_cache`), for the next reading of its bytes."""
        if getattr(self, "_kept", None) is None and not validate and not self.path.is_dir():
            from .description_cache import KeptDescription, keep_description

            keep_description(self.path, KeptDescription(self.model_description, self._period_declaration(),
                                                        tuple(self._file_names())))

    def _claim_extracted(self) -> Path | None:
        """The folder the cache holds this FMU's run-time entries in, extracted
        once for every run (:func:`cosim.fmi.description_cache.claim_extracted`:
        an FMU this tool built, read from the cache before, the first instance
        of its file in this process), or ``None``: extract it here."""
        kept = getattr(self, "_kept", None)
        if kept is None:
            return None
        from .description_cache import claim_extracted

        return claim_extracted(self.path, kept, self._run_time_files())

    def _period_declaration(self) -> tuple[bool, str | None]:
        """Whether the FMU declares a period (:data:`PERIOD_ANNOTATION`), and
        the parameter it names as written (``None`` if it names none)."""
        kept = getattr(self, "_kept", None)
        if kept is not None:
            return kept.period
        root = self._extras()
        annotation = (f"VendorAnnotations/Tool[@name='{PERIOD_ANNOTATION}']" if self.fmi_version == 2 else
                      f"Annotations/Annotation[@type='{PERIOD_ANNOTATION}']")
        declaration = root.find(f"{annotation}/SampledData")
        return (False, None) if declaration is None else (True, declaration.get("periodParameter"))

    def _declared_period(self) -> str | None:
        """The parameter a sampled-data FMU declares as its period
        (:data:`PERIOD_ANNOTATION`), or ``None`` for an FMU that declares
        none. fmpy does not read annotations, so the modelDescription (which
        fmpy has read already) is parsed here, entities and network off."""
        declared, name = self._period_declaration()
        if not declared:
            return None
        if getattr(self.variables.get(name), "causality", None) != "parameter":
            raise FmuLoadError(self.name, self.path, f"its {PERIOD_ANNOTATION} annotation declares "
                               f"periodParameter = {name!r}, which is no parameter of the FMU")
        return name

    def _extras(self):
        """The modelDescription's XML root, for what fmpy does not read
        (annotations, FMI 3.0's ``providesDirectionalDerivatives``): the one
        reader of these extras, parsed once, entities and network off (the
        file's size was checked by :meth:`_read_model_description`)."""
        root = getattr(self, "_extras_root", None)
        if root is None:
            from lxml import etree

            if self.path.is_dir():
                xml = (self.path / "modelDescription.xml").read_bytes()
            else:
                xml = getattr(self, "_description_xml", None)  # read, and checked, by _read_model_description
                if xml is None:
                    import zipfile

                    from ..files import read_entry

                    with zipfile.ZipFile(self.path) as archive:
                        xml = read_entry(archive, archive.getinfo("modelDescription.xml"), str(self.path))
            root = self._extras_root = etree.fromstring(xml, etree.XMLParser(resolve_entities=False,
                                                                                no_network=True))
        return root

    @property
    def provides_directional_derivatives(self) -> bool:
        """The interface's flag (FMI 2.0 ``providesDirectionalDerivative``,
        FMI 3.0 ``providesDirectionalDerivatives``). fmpy 0.3 reads FMI 3.0's
        under FMI 2.0's singular name and so reports False: for FMI 3.0 the
        attribute is read from the XML."""
        if self.fmi_version == 2:
            return bool(self.kind.providesDirectionalDerivative)
        node = self._extras().find(self.interface)
        return node is not None and node.get("providesDirectionalDerivatives") == "true"

    def _input_clock(self) -> int | None:
        """The input clock of a clocked FMI 3.0 FMU: one periodic input clock,
        ticking at the period it declares (:data:`PERIOD_ANNOTATION`)."""
        clocks = [v for v in self.model_description.modelVariables if v.type == "Clock"]
        if not clocks:
            return None
        if len(clocks) > 1 or clocks[0].causality != "input" or self.sample_period is None:
            raise FmuLoadError(self.name, self.path, f"clocks {[c.name for c in clocks]}: only one input clock, "
                               f"ticking at the period its {PERIOD_ANNOTATION} annotation declares, is supported")
        return clocks[0].valueReference

    def _run_time_files(self) -> set[str]:
        from ..files import run_time_entries

        return run_time_entries(self._file_names())

    def _file_names(self) -> list[str]:
        kept = getattr(self, "_kept", None)
        if kept is not None:
            return list(kept.names)
        if self.path.is_dir():
            return [Path(root, f).relative_to(self.path).as_posix()
                    for root, _, files in os.walk(self.path) for f in files]
        import zipfile

        with zipfile.ZipFile(self.path) as archive:
            return archive.namelist()

    def _check_binary(self) -> None:
        """Refuse, before any extraction, an FMU with no binary where fmpy
        will look for one on this platform; name the platforms it has."""
        folder = platform if self.fmi_version == 2 else platform_tuple
        wanted = f"binaries/{folder}/{self.kind.modelIdentifier}{sharedLibraryExtension}"
        names = self._file_names()
        if wanted in names:
            return
        has = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
        sources = any(n.startswith("sources/") for n in names)
        raise FmuLoadError(self.name, self.path,
                           f"no binary for this platform ({wanted} is missing); the FMU has binaries for: "
                           f"{', '.join(has) if has else 'no platform'}"
                           + ("; it carries C sources: compile them with fmpy.build.build_platform_binary"
                              if sources else ""))

    # ---- lifecycle ---------------------------------------------------------

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
        for key, value in parameters.items():
            why = start_value_rule(self.variables.get(key))
            if why:
                raise FmuCallError(self.name, self.path, f"{key!r} {why}", key, value)
        try:
            if self._initialized_once:
                s.reset()
        except FMICallException as exc:
            raise self._fail("reset", exc) from None
        self._initialized_once = True  # from here on, parameters may be set: the next start resets
        from fmpy.simulation import settable_in_instantiated

        later = {k: v for k, v in parameters.items() if not settable_in_instantiated(self.variables[k])}
        self._set_start_values({k: v for k, v in parameters.items() if k not in later})
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

    def _set_start_values(self, values: Mapping[str, Any]) -> None:
        """Each start value by its type's set call (:meth:`_set_typed`), one by
        one, so a refusal names the variable and quotes the FMU."""
        for key, value in values.items():
            try:
                self._set_typed({key: value})
            except FMICallException as exc:
                what = "parameter" if self.variables[key].causality == "parameter" else "the start value of"
                raise self._fail(f"setting {what} {key} = {value!r}", exc, variable=key, value=value) from None

    def bind(self, input_names: Sequence[str], output_names: Sequence[str],
             y: np.ndarray | None = None, objects: np.ndarray | None = None,
             object_inputs: tuple[Sequence[str], np.ndarray] = ((), ()),
             object_reads: tuple[Sequence[str], slice] = ((), slice(0, 0))) -> None:
        """Fix the inputs set and the outputs read every step, in this order.

        Afterwards :attr:`u` (inputs) and :attr:`y` (outputs) are float64
        arrays the master fills and reads; :meth:`write_inputs`,
        :meth:`do_step` and :meth:`read_outputs` move them through the FMU.
        ``y`` may be given: a contiguous float64 array (e.g. a slice of the
        master's signal array) the outputs are then read straight into.

        Signals of other types (docs/cosim.md, "Signal types"): names may be
        elements of FMI 3.0 arrays (``y[2]``); inputs and outputs of the
        types a double holds exactly pass through :attr:`u` and :attr:`y`
        too; those of Int64, UInt64, String and Binary are taken from and
        read into the master's object slots ``objects``
        (``object_inputs``: names and their source slots; ``object_reads``:
        names and the slice they are read into). Any of these makes the
        calls typed (:meth:`_get_typed`, :meth:`_set_typed`: one get or set
        per type, an array in one call with ``nValues``); Float64 scalars
        alone keep the one-call fast path.
        """
        names = list(input_names) + list(output_names) + list(object_inputs[0]) + list(object_reads[0])
        self._objects = objects
        self._object_inputs = (tuple(object_inputs[0]), np.asarray(object_inputs[1], dtype=np.intp))
        self._object_reads = (tuple(object_reads[0]),
                              objects[object_reads[1]] if objects is not None and object_reads[0] else None)
        self._typed = any(n not in self.variables or self.variables[n].dimensions
                          or TYPE_OF.get(self.variables[n].type) != "Float64" for n in names)
        if self._typed:
            for n in names:
                self._element(n)  # a name that is none is refused now
            self.input_names, self.output_names = tuple(input_names), tuple(output_names)
            self._n_in, self._n_out = len(input_names), len(output_names)
            self.u = np.zeros(max(self._n_in, 1))
            self.y = y if y is not None else np.zeros(max(self._n_out, 1))
            # the compiled loop gathers the float inputs into u and calls this component (kernel_entry)
            self._u_ptr = self.u.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
            self._y_ptr = self.y.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
            self._in_vr = self._out_vr = (ctypes.c_uint32 * 1)()  # its typed calls take their own references
            self._u_set = None
            return

        def vrs(names):
            missing = [n for n in names if n not in self.variables]
            if missing:
                raise KeyError(f"{self.name} has no variable(s) {missing}")
            refs = [self.variables[n].valueReference for n in names]
            return (ctypes.c_uint32 * max(len(refs), 1))(*refs)

        self.input_names, self.output_names = tuple(input_names), tuple(output_names)
        self._in_vr, self._out_vr = vrs(self.input_names), vrs(self.output_names)
        self._n_in, self._n_out = len(self.input_names), len(self.output_names)
        self._c_in, self._c_out = ctypes.c_size_t(self._n_in), ctypes.c_size_t(self._n_out)
        self.u = np.zeros(max(self._n_in, 1))
        if y is not None:
            if y.dtype != np.float64 or not y.flags.c_contiguous or y.size != self._n_out:
                raise ValueError(f"{self.name}: output buffer must be {self._n_out} contiguous float64 values")
            self.y = y
        else:
            self.y = np.zeros(max(self._n_out, 1))
        self._u_ptr = self.u.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        self._u_set = None
        self._y_ptr = self.y.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    # ---- typed values (docs/cosim.md, "Signal types") ---------------------------------------------

    def _element(self, name: str) -> tuple[object, int]:
        """``(variable, k)``: the variable a signal name is (``k`` = -1) or
        the element ``k`` (0-based, row-major) of an array it names."""
        var = self.variables.get(name)
        if var is not None:
            return var, -1
        base, index = element_of(name)
        var = self.variables.get(base)
        shape = shape_of(var) if var is not None else ()
        if var is None or index is None or len(index) != len(shape) or \
                not all(1 <= i <= k for i, k in zip(index, shape)):
            raise KeyError(f"{self.name} has no variable(s) {[name]}")
        k = 0
        for i, size in zip(index, shape):
            k = k * size + (i - 1)
        return var, k

    def _calls(self, port_type: str):
        """``(get, set)`` of the instance for values of ``port_type``: FMI 2.0
        getReal/Integer/Boolean/String (an Enumeration is an Integer), FMI
        3.0 getFloat32 .. getBinary (an Enumeration is an Int64, section
        2.2.6.1), each taking ``nValues`` for arrays."""
        s = self._slave
        if self.fmi_version == 2:
            name = {"Float64": "Real", "Int32": "Integer", "Enumeration": "Integer"}.get(port_type, port_type)
            get, set_ = getattr(s, "get" + name), getattr(s, "set" + name)
            return (lambda vrs, n: get(vrs)), set_
        name = "Int64" if port_type == "Enumeration" else port_type
        return getattr(s, "get" + name), getattr(s, "set" + name)

    def _array_start(self, var) -> list:
        """The start values of an array variable (its modelDescription's, one
        per element, row-major), the values of elements no connection sets."""
        port_type = TYPE_OF.get(var.type, var.type)
        tokens = str(var.start).split() if var.start is not None else []
        size = int(np.prod(shape_of(var))) if shape_of(var) else 1
        zero = {"String": "", "Binary": b"", "Boolean": False}.get(port_type, 0)
        values = [typed_value(port_type, t, f"{self.name}.{var.name} start") for t in tokens[:size]]
        return values + [zero] * (size - len(values))

    def _get_typed(self, names: Sequence[str]) -> list:
        """The values of ``names`` (variables or array elements) as Python
        values (:func:`cosim.component.typed_value`), one get call per type."""
        wanted = [self._element(n) for n in names]
        by_type: dict[str, list] = {}
        for var, _ in wanted:
            group = by_type.setdefault(TYPE_OF.get(var.type, var.type), [])
            if var not in group:
                group.append(var)
        got: dict[int, list] = {}
        for port_type, variables in by_type.items():
            sizes = [int(np.prod(shape_of(v))) if v.dimensions else 1 for v in variables]
            values = self._calls(port_type)[0]([v.valueReference for v in variables], sum(sizes))
            offset = 0
            for v, size in zip(variables, sizes):
                got[id(v)] = values[offset:offset + size]
                offset += size
        out = []
        for (var, k), name in zip(wanted, names):
            value = got[id(var)][max(k, 0)]
            port_type = TYPE_OF.get(var.type, var.type)
            if isinstance(value, bytes) and port_type == "String":  # fmpy's FMI 2.0 getString
                value = value.decode("utf-8", "replace")
            elif port_type == "Binary" and value is None:
                value = b""
            elif port_type == "Enumeration" and abs(int(value)) > 2 ** 53:
                raise FmuCallError(self.name, self.path, f"Enumeration {name} = {int(value)}: beyond 2^53, no "
                                   f"double holds it exactly (the master holds an Enumeration as a double)")
            out.append(value)
        return out

    def _set_typed(self, values: Mapping[str, object]) -> None:
        """Set ``values`` (by variable or array element name) with one set
        call per type, an array whole: its elements not given keep their
        start values. A value the type cannot hold is refused in one line
        (:func:`cosim.component.typed_value`), never rounded."""
        arrays: dict[int, list] = {}
        by_type: dict[str, list] = {}
        for name, value in values.items():
            var, k = self._element(name)
            port_type = TYPE_OF.get(var.type, var.type)
            try:
                value = typed_value(port_type, value, f"{self.name}.{name}")
            except ValueError as exc:
                raise FmuCallError(self.name, self.path, str(exc), name, value) from None
            group = by_type.setdefault(port_type, [])
            if var not in group:
                group.append(var)
            if var.dimensions:
                if id(var) not in arrays:
                    arrays[id(var)] = self._array_start(var)
                if k < 0:
                    raise FmuCallError(self.name, self.path, f"{name}: an array variable is set by its elements",
                                       name, value)
                arrays[id(var)][k] = value
            else:
                arrays[id(var)] = [value]
        for port_type, variables in by_type.items():
            flat = [x for v in variables for x in arrays[id(v)]]
            self._calls(port_type)[1]([v.valueReference for v in variables], flat)

    def kernel_entry(self, direct: bool, in_idx: np.ndarray, python: bool = False,
                     time: np.ndarray | None = None) -> KernelFmu:
        """This FMU as the compiled loop sees it (:mod:`cosim.loop.kernel`):
        function pointers, value references and buffers as :meth:`bind` set
        them; ``in_idx``, the signal slots of the inputs' sources, is kept
        alive with this component.

        ``python``: an FMU whose calls the compiled loop cannot make itself
        (:meth:`python_loop_reason`): its set, get and step are this
        component's :meth:`write_inputs`, :meth:`read_outputs` and
        :meth:`do_step` behind C callbacks (``time[0]``, the signal array's
        time slot, says when), so only this FMU takes the Python path; an
        exception there is kept and raised by :meth:`kernel_failure`."""
        api = self._api
        address = lambda f: ctypes.cast(f, ctypes.c_void_p).value  # noqa: E731
        vrs = lambda refs: ctypes.cast(refs, ctypes.POINTER(ctypes.c_uint32))  # noqa: E731
        self._kernel_in_idx = np.ascontiguousarray(in_idx, dtype=np.int64)
        self._kernel_exception = None
        version, component, calls = self.fmi_version, api._component.value, (api._set, api._get, api._step)
        if python:
            version, component, calls = 2, None, self._python_calls(time)  # the callbacks take FMI 2.0's shape
        elif self.system is not None:  # Model Exchange: its system's calls (FMI 2.0's shape), cosim/fmi/me_system.c
            from .me_system import library

            lib = library()
            version, component, calls = 2, self._me_member.value, (lib.me_member_set, lib.me_member_get,
                                                                    lib.me_member_step)
        entry = KernelFmu(version, component, *map(address, calls), vrs(self._in_vr), self._n_in,
                          self._kernel_in_idx.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), self._u_ptr,
                          vrs(self._out_vr), self._n_out, self._y_ptr, int(direct))
        entry.python = int(python)
        return entry

    def _python_calls(self, time: np.ndarray):
        """C callbacks (FMI 2.0 signatures) over this component's loop calls;
        kept alive with it. Each returns fmi2Error after keeping the exception."""
        def guarded(work):
            def call(*args):
                try:
                    work(*args)
                    return 0
                except BaseException as exc:  # raised again by kernel_failure, in the master's thread
                    self._kernel_exception = exc
                    return 3
            return call

        u32p, f64p = ctypes.POINTER(ctypes.c_uint32), ctypes.POINTER(ctypes.c_double)
        values = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, u32p, ctypes.c_size_t, f64p)
        step = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)
        self._callbacks_kept = (
            values(guarded(lambda c, vr, n, v: self.write_inputs(float(time[0])))),
            values(guarded(lambda c, vr, n, v: self.read_outputs(float(time[0])))),
            step(guarded(lambda c, t, h, flag: self.do_step(t, h))))
        return self._callbacks_kept

    def _call_failure(self, call: Call, exc: FMICallException, t: float, h: float = 0.0) -> FmuCallError:
        """The error of a failed loop call: what was asked, with the inputs' values when setting them."""
        if call == Call.SET:
            values = ", ".join(f"{n} = {float(v)!r}" for n, v in zip(self.input_names, self.u))
            return self._fail(f"setting inputs ({values})", exc, t)
        if call == Call.GET:
            return self._fail("getting outputs", exc, t)
        return self._fail(f"doStep from t = {t!r} by {h!r} s", exc, t)

    def kernel_failure(self, call: Call, status: int, t: float, h: float) -> FmuCallError:
        """The error the Python path raises for the same failed call (for an
        FMU driven through its Python calls, the very exception it raised)."""
        if self._kernel_exception is not None:
            exc, self._kernel_exception = self._kernel_exception, None
            return exc
        if self.system is not None:  # its system says why (the failure may be another member's)
            return self.system.failure()
        call = Call(call)
        if call == Call.STEP and self._asked_to_terminate(status):
            return self._terminated(t, h)
        return self._call_failure(call, FMICallException(function=self._api._names[call], status=status), t, h)

    def _activate_clock(self, t: float) -> None:
        """A clocked FMU at a tick: its clock activated (once), so the inputs
        set next are the tick's and a get returns the tick's outputs."""
        self._tick_pending = False
        try:
            self._slave.setClock([self.clock], [True])
        except FMICallException as exc:
            raise self._fail("activating its clock", exc, t) from None

    def write_inputs(self, t: float) -> None:
        """Set all bound inputs from :attr:`u` in one call (a clocked FMU's
        clock activated first: the inputs are its tick's; a Model Exchange
        instance: only when they changed, in Event Mode if a discrete one
        did); typed inputs (:meth:`bind`) one call per type."""
        if self._tick_pending:
            self._activate_clock(t)
        if self._typed:
            names, sources = self._object_inputs
            values = dict(zip(self.input_names, self.u.tolist()))
            if names:
                values.update(zip(names, self._objects[sources]))
            if values and (self.system is None or values != self._u_set):  # Model Exchange: when they change
                self._set_values(values, t)
                self._u_set = values
            return
        if self._n_in and self.system is not None:
            return self.system.set_inputs(self, t)
        if self._n_in:
            try:
                self._api.set(self._in_vr, self._c_in, self._u_ptr)
            except FMICallException as exc:
                raise self._call_failure(Call.SET, exc, t) from None

    def integration_failure(self, exc: "Exception | int", t: float) -> Exception:
        """The error of this member's Model Exchange system at ``t``
        (:meth:`cosim.fmi.me_system.ModelExchangeSystem.failure`): the FMU asking
        to end the run, or an :class:`~cosim.errors.FmuCallError` naming the
        time, the FMU and the reason (an FMI status, given as the number, or
        the solver's failure, an :class:`~cosim.fmi.model_exchange.IntegrationError`)."""
        from .model_exchange import IntegrationError

        if isinstance(exc, int):
            exc = FMICallException(function="a Model Exchange call", status=exc)
        method = self.system.settings.method if self.system is not None else self.solver.method
        if isinstance(exc, IntegrationError):
            if exc.terminate:
                return SimulationTerminated(self.name, self.path, exc.time, f"asked to terminate the simulation at "
                                            f"t = {exc.time!r} s; the run ends at t = {exc.time!r} s")
            return self._fail(f"Model Exchange integration ({method})", exc, exc.time)
        return self._fail(f"Model Exchange integration ({method}) at t = {t!r} s", exc, t)

    def serialize_state(self) -> bytes:
        """The FMU's state, serialized (FMI getFMUState + serializeFMUState)."""
        s = self._slave
        self.messages.clear()  # an error quotes what this call logged, not an earlier call
        try:
            state = s.getFMUState()
            try:
                return bytes(s.serializeFMUState(state))
            finally:
                s.freeFMUState(state)
        except FMICallException as exc:
            raise self._fail("serializing the FMU state", exc) from None

    def restore_state(self, blob: bytes) -> None:
        """Restore a serialized FMU state (deserializeFMUState + setFMUState).

        A state the FMU refuses (this project's FMUs refuse one of another
        model, of the wrong size, or holding a value they would refuse on a
        set or at initialization) is an :class:`~cosim.errors.FmuCallError`
        quoting the FMU's log, in one line; the instance keeps its state.
        """
        s = self._slave
        self.messages.clear()  # an error quotes what this call logged, not an earlier call
        try:
            state = s.deserializeFMUState(blob)
            try:
                s.setFMUState(state)
            finally:
                s.freeFMUState(state)
        except FMICallException as exc:
            raise self._fail("restoring a serialized FMU state", exc) from None
        if self.clock is not None:  # a state this component saved: at a tick, in Event Mode
            self._tick_pending = True
        if self.system is not None:  # new states: an event there gives the next time event; the solver restarts
            self.system.state_changed(self, self._t)
            self._u_set = None

    def set_inputs(self, values: Mapping[str, float], t: float) -> None:
        """Set some inputs by name (the slow path, outside the step loop);
        elements of arrays (``u[2]``) and values of any type (docs/cosim.md,
        "Signal types") by their typed calls."""
        if not values:
            return
        if self._tick_pending:
            self._activate_clock(t)
        if any(n not in self.variables or self.variables[n].dimensions
               or TYPE_OF.get(self.variables[n].type) != "Float64" for n in values):
            return self._set_values(values, t)
        vrs = [self.variables[name].valueReference for name in values]
        set_values = lambda: self.real_calls()[1](vrs, [float(v) for v in values.values()])  # noqa: E731
        try:
            self._set_in_mode(set_values, values, t)
        except FMICallException as exc:
            shown = ", ".join(f"{n} = {float(v)!r}" for n, v in values.items())
            raise self._fail(f"setting inputs ({shown})", exc, t) from None

    def _set_values(self, values: Mapping[str, object], t: float) -> None:
        """:meth:`_set_typed`, a refusal of the FMU told with the values set."""
        try:
            self._set_in_mode(lambda: self._set_typed(values), values, t)
        except FMICallException as exc:
            shown = ", ".join(f"{n} = {v!r}" for n, v in values.items())
            raise self._fail(f"setting inputs ({shown})", exc, t) from None

    def _set_in_mode(self, setter, names, t: float) -> None:
        """``setter()`` (setting the inputs ``names``) in the mode the standard
        asks: a Model Exchange instance out of initialization sets a discrete
        input in Event Mode, followed by the event iteration (an input
        event), and a continuous one in Continuous-Time Mode, restarting
        its solver (FMI 2.0 §3.2.3, FMI 3.0 §3.2.1); any other instance at once."""
        if self.system is None or not self.system.running or self._initializing:
            return setter()
        if any(self._element(n)[0].variability != "continuous" for n in names):
            self.system.event(t, setter)
        else:
            setter()
            self.system.restart()
        self._u_set = None

    def real_calls(self):
        """``(get, set)``: the instance's calls for Real (FMI 2.0) or Float64
        (FMI 3.0) values by value references."""
        s = self._slave
        return (s.getReal, s.setReal) if self.fmi_version == 2 else (s.getFloat64, s.setFloat64)

    # ---- values by name, FMU states on the live instance -----------------------------------------

    def _references(self, names) -> list[int]:
        missing = [n for n in names if n not in self.variables]
        if missing:
            raise KeyError(f"{self.path.name} has no variable(s) {missing}")
        return [self.variables[n].valueReference for n in names]

    def get_reals(self, names: Sequence[str], t: float | None = None) -> dict[str, float]:
        """The Real/Float64 values of ``names`` (one get; a refusal is an
        :class:`~cosim.errors.FmuCallError` quoting the FMU)."""
        names = list(names)
        if not names:
            return {}
        refs = self._references(names)
        try:
            return dict(zip(names, map(float, self.real_calls()[0](refs))))
        except FMICallException as exc:
            raise self._fail(f"getting {', '.join(names)}", exc, t) from None

    def set_reals(self, values: Mapping[str, float], t: float | None = None, where: str = "",
                  restore: bytes | None = None) -> None:
        """Set Real/Float64 variables by name, one by one so that a refusal
        (an :class:`~cosim.errors.FmuCallError`) names the variable and the
        value and quotes the FMU's reason; ``where`` says when (e.g. "in a
        restored state").

        ``restore``: a serialized FMU state the instance is in before the
        call. The values are then set in one call (a linearizer's difference
        sets about 100 per evaluation: one call per value was half of its
        time); if the FMU refuses them, that state is set back (after an
        error FMI lets an importer restart from a stored state: FMI 2.0
        section 2.1.3, FMI 3.0 section 2.2.3) and they are set one by one as
        above, so the refusal is the same one line."""
        refs = self._references(list(values))
        set_real = self.real_calls()[1]
        if restore is not None:
            try:
                set_real(refs, [float(v) for v in values.values()])
                return
            except FMICallException:
                self.restore_state(restore)  # clears the log: the error below quotes the refusal one by one
        for ref, (name, value) in zip(refs, values.items()):
            try:
                set_real([ref], [float(value)])
            except FMICallException as exc:
                raise self._fail(f"setting {name} = {value!r}{' ' + where if where else ''}", exc, t, name,
                                 value) from None

    def in_state(self, fmu_state: bytes, work):
        """``work()`` with the serialized ``fmu_state`` restored into this live
        instance, whose own state is saved before and set back after
        (``fmiXGetFMUState`` / ``fmiXSetFMUState``, FMI 2.0 section 2.1.8,
        FMI 3.0 section 2.2.6): the instance goes on as if nothing happened, and
        no other instance is made."""
        if self._slave is None:
            raise RuntimeError(f"{self.name}: start the instance before reading or editing an FMU state with it")
        s = self._slave
        self.messages.clear()
        try:
            saved = s.getFMUState()
        except FMICallException as exc:
            raise self._fail("saving the FMU state", exc) from None
        tick = self._tick_pending
        try:
            self.restore_state(fmu_state)
            return work()
        finally:
            try:
                s.setFMUState(saved)
                s.freeFMUState(saved)
            except FMICallException as exc:
                raise self._fail("setting back the FMU state it had", exc) from None
            self._tick_pending = tick

    def state_values(self, fmu_state: bytes, names: Sequence[str], t: float | None = None) -> dict[str, float]:
        """The values of ``names`` in a serialized FMU state of this FMU (e.g.
        a :class:`~cosim.loop.master.Snapshot`'s), read on this live (started)
        instance, which keeps its own state."""
        return self.in_state(fmu_state, lambda: self.get_reals(names, t))

    def state_with(self, fmu_state: bytes, values: Mapping[str, float], t: float | None = None) -> bytes:
        """A serialized FMU state: ``fmu_state`` with ``values`` set (variables
        the FMU lets an importer set, e.g. this project's discrete states),
        serialized again, on this live instance, which keeps its own state. A
        value the FMU refuses is an :class:`~cosim.errors.FmuCallError` naming
        it."""
        def edit():
            self.set_reals(values, t, "in a restored state")
            return self.serialize_state()
        return self.in_state(fmu_state, edit)

    # ---- Model Exchange: what a linearizer evaluates -------------------------------------------------
    # (FMI 2.0 section 3.2.1, FMI 3.0 section 3.2: the Model Exchange calls on an instance made with
    # interface="ModelExchange", after start(), in Continuous-Time Mode; sizes from the ModelStructure)

    @property
    def typed_calls(self) -> bool:
        """Whether the variables :meth:`bind` bound take typed get and set
        calls (an array, an integer, a string...), not the one-call Float64
        fast path (which the Model Exchange system's C drives directly)."""
        return self._typed

    @property
    def state_names(self) -> list[str]:
        """The continuous states, in the order of the FMU's state vector."""
        return [d.variable.derivative.name for d in self.model_description.derivatives]

    @property
    def derivative_names(self) -> list[str]:
        return [d.variable.name for d in self.model_description.derivatives]

    @property
    def event_indicator_count(self) -> int:
        return int(self.model_description.numberOfEventIndicators or 0)

    def _vector(self, call, what: str, n: int | None = None) -> np.ndarray:
        n = len(self.state_names) if n is None else n
        out = np.zeros(n)
        if n:
            try:
                call(out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), n)
            except FMICallException as exc:
                raise self._fail(what, exc) from None
        return out

    def bare_call(self, name: str):
        """The instance's FMI function ``name`` without fmpy's wrapper (a
        caller that prepares its ctypes arguments once, e.g. the calibrator's
        right-hand side evaluations: :mod:`cosim.calibration.model`); its
        status goes to :meth:`check_status`."""
        return _bare(self._slave, name)

    @property
    def handle(self) -> ctypes.c_void_p:
        """The instance's FMI handle (``fmi2Component``, ``fmi3Instance``), the first argument of a bare call."""
        return ctypes.c_void_p(self._slave.component)

    def check_status(self, status: int, what: str) -> None:
        """A bare call's status: above warning, the :class:`~cosim.errors.FmuCallError`
        of this instance quoting its log (the one place status codes become exceptions)."""
        if status > 1:
            raise self._fail(what, FMICallException(function=what, status=status))

    def continuous_states(self) -> np.ndarray:
        return self._vector(self._slave.getContinuousStates, "getting the continuous states")

    def set_continuous_states(self, x: np.ndarray) -> None:
        """Set the continuous states (Continuous-Time Mode: FMI 2.0 §3.2.1, FMI
        3.0 §3.2.1); the master's solver, if it integrates this instance,
        restarts from them at the next step (the states changed outside it)."""
        x = np.ascontiguousarray(x, dtype=float)
        if x.size:
            try:
                self._slave.setContinuousStates(x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), x.size)
            except FMICallException as exc:
                raise self._fail("setting the continuous states", exc) from None
            if self.system is not None and self.system.running:
                self.system.restart()

    def derivatives(self) -> np.ndarray:
        """The state derivatives at the states and inputs set."""
        s = self._slave
        return self._vector(s.getDerivatives if self.fmi_version == 2 else s.getContinuousStateDerivatives,
                            "getting the state derivatives")

    def nominals(self) -> np.ndarray:
        """The nominal values of the continuous states (the FMU's, at this point)."""
        return self._vector(self._slave.getNominalsOfContinuousStates, "getting the states' nominal values")

    def event_indicators(self) -> np.ndarray:
        s = self._slave
        return self._vector(s.getEventIndicators, "getting the event indicators", self.event_indicator_count)

    def directional_derivatives(self, unknowns: Sequence[str], knowns: Sequence[str]) -> np.ndarray:
        """The Jacobian d unknowns / d knowns at the current point, one column
        per known (``fmiXGetDirectionalDerivative`` with seed 1 on it: FMI 2.0
        section 2.1.9, FMI 3.0 section 2.2.10), exact to round-off; requires
        :attr:`provides_directional_derivatives`."""
        out_refs, in_refs = self._references(unknowns), self._references(knowns)
        columns = []
        for ref, name in zip(in_refs, knowns):
            try:
                columns.append(self._slave.getDirectionalDerivative(out_refs, [ref], [1.0]))
            except FMICallException as exc:
                raise self._fail(f"the directional derivative along {name}", exc) from None
        return np.array(columns, dtype=float).reshape(len(in_refs), len(out_refs)).T

    def do_step(self, t: float, h: float) -> None:
        """Advance the FMU from ``t`` to ``t + h``; a clocked FMU computes the
        tick at ``t`` first, and must meet its next tick at ``t + h``."""
        if self.clock is not None:
            return self._clocked_step(t, h)
        if self.system is not None:
            self.system.step(self, t, h)
            self._t = t + h
            return
        try:
            self._api.do_step(t, h)
        except FMICallException as exc:
            if self._asked_to_terminate(exc.status):
                raise self._terminated(t, h) from None
            raise self._call_failure(Call.STEP, exc, t, h) from None
        if self.fmi_version == 3 and self._api.terminate.value:
            raise self._terminated(t, h)

    def _asked_to_terminate(self, status: int) -> bool:
        """A discarded FMI 2.0 doStep with ``fmi2Terminated`` set: the FMU
        asks to end the simulation (FMI 2.0 §4.2.3)."""
        if self.fmi_version != 2 or status != 2 or self.interface != "CoSimulation":
            return False
        from fmpy.fmi2 import fmi2Terminated

        try:
            return bool(self._slave.getBooleanStatus(fmi2Terminated))
        except FMICallException:  # an FMU that cannot tell did not ask
            return False

    def _terminated(self, t: float, h: float) -> SimulationTerminated:
        """The run's end at ``t`` that this FMU asked for in the step to ``t + h``."""
        log = "; ".join(self.messages)
        return SimulationTerminated(self.name, self.path, t, f"asked to terminate the simulation in the step from "
                                    f"t = {t!r} s to {t + h!r} s; the run ends at t = {t!r} s"
                                    + (f" (FMU log: {log})" if log else ""))

    def _clocked_step(self, t: float, h: float) -> None:
        """Event Mode at the tick t: compute it; to t + h (Co-Simulation: doStep;
        Model Exchange: the time set, no state to integrate); Event Mode at the
        next tick."""
        if self._tick_pending:  # no input set since the tick began: it samples the inputs held
            self._activate_clock(t)
        s = self._slave
        try:
            *_, next_defined, next_tick = s.updateDiscreteStates()
            if self.interface == "ModelExchange":
                s.enterContinuousTimeMode()
                s.setTime(t + h)  # within the FMU's tolerance of the tick, taken as the tick
                s.completedIntegratorStep()
                event = next_defined and abs(next_tick - (t + h)) <= 1e-9 * h
            else:
                s.enterStepMode()
                event, terminate, _, _ = s.doStep(t, h)
                if terminate:
                    raise self._terminated(t, h)
            s.enterEventMode()
        except FMICallException as exc:
            raise self._call_failure(Call.STEP, exc, t, h) from None
        if not event:
            raise self._fail(f"doStep from t = {t!r} by {h!r} s", RuntimeError("it ended before the next tick of "
                             "its clock"), t)
        self._tick_pending = True

    def read_outputs(self, t: float) -> None:
        """Get all bound outputs into :attr:`y` in one call; typed outputs
        (:meth:`bind`) one call per type, those held as objects into the
        master's object slots."""
        if self._typed:
            names, target = self._object_reads
            if self.system is not None and not self._initializing:
                self.system.refresh()
            try:
                values = self._get_typed(self.output_names + names)
            except FMICallException as exc:
                raise self._call_failure(Call.GET, exc, t) from None
            n = self._n_out
            if n:
                self.y[:n] = [float(v) for v in values[:n]]  # held exactly (cosim.component.FLOAT_HELD)
            if names:
                target[:] = [int(v) if isinstance(v, int) else v for v in values[n:]]
            return
        if self._n_out and self._me_member is not None and not self._initializing:  # Model Exchange, running
            return self.system.get_outputs(self, t)
        if self._n_out:
            try:
                self._api.get(self._out_vr, self._c_out, self._y_ptr)
            except FMICallException as exc:
                raise self._call_failure(Call.GET, exc, t) from None

