"""An FMU as a component of the master: a thin, fast wrapper over fmpy's
instances, Co-Simulation (``FMU2Slave``, ``FMU3Slave``) or Model Exchange
(``FMU2Model``, ``FMU3Model``, integrated by :mod:`cosim.fmi.me_system`).

fmpy's classes do the loading, instantiation and status checking (every
failed call raises fmpy's ``FMICallException`` in one place).
:class:`FmuComponent` is the one class a user sees; its jobs are in the
modules beside this one, each a part the class is made of (their methods
share the instance's state), the jobs without state plain functions there:

* :mod:`cosim.fmi.lifecycle`: the instance's lifecycle (its library loaded,
  instantiated with its log, set up by the standard's initialization, reset
  between runs, freed) and the one place an FMI status becomes this tool's
  exception (:meth:`FmuComponent._fail`);
* :mod:`cosim.fmi.variables`: values by name and by type, FMI 2.0 and 3.0
  (typed get and set, array elements, start values, inputs set outside the
  step loop in the mode the standard asks);
* :mod:`cosim.fmi.state`: the FMU state (get, set, serialized, edited on the
  live instance) and the continuous states and derivatives a linearizer
  evaluates;
* :mod:`cosim.fmi.step`: the step outside the compiled loop (bound inputs
  and outputs, ``doStep``, clock ticks) and the FMU as the compiled loop
  sees it (:meth:`FmuComponent.kernel_entry`).

This module reads the FMU file, before any instance exists:

* ports read from the modelDescription (:mod:`cosim.fmi.description`: name,
  causality, type, shape, unit and its ``UnitDefinitions`` meaning), so the
  master can check connections before the first step;
* the one reader of the modelDescription's extras fmpy does not read
  (annotations, the FMI 3.0 directional-derivative flag):
  :meth:`FmuComponent._extras`;
* a file that is no usable FMU (not a zip archive, a broken
  modelDescription.xml, no binary for this platform, an instantiation the FMU
  refuses) is an :class:`~cosim.errors.FmuLoadError` that names the file and
  the cause in one line, raised when the component is made;
* a sampled-data FMU's declaration of its period parameter (an annotation of
  its modelDescription, :data:`PERIOD_ANNOTATION`) is read into
  :attr:`FmuComponent.sample_period`, so a master can refuse a communication
  step the FMU cannot take before anything runs; a clocked FMI 3.0 FMU's
  input clock into :attr:`FmuComponent.clock`.
"""
from __future__ import annotations

import os
from collections import deque
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from fmpy import platform, platform_tuple, read_model_description, sharedLibraryExtension

from .description import PERIOD_ANNOTATION, fmu_ports
from ..cache import FileMemo
from ..errors import FmuLoadError, ScenarioError
from .lifecycle import _UNCONFIGURED_LEVEL, Lifecycle
from .state import StateAccess
from .step import Stepping
from .variables import VariableAccess

__all__ = ["FmuComponent", "read_description"]


_PARSED = FileMemo(64)  # fmpy's parses, by FMU file and validation (docs/cosim.md, "Caches")


def _parsed_model_description(path: str, info: os.stat_result, validate: bool):
    """fmpy's parse of the FMU at ``path`` as it is now (``info``: its size
    and time of change, so a rewritten file is read again). A study's worker
    builds a master per case over the same FMU files: each was parsed again
    (lxml, about 3.5 ms each, a fifth of a master's build). Nothing changes
    the parsed description; a failure is not kept."""
    key = f"{path}\0{validate}"  # the checked parse and the unchecked one are two values
    parsed = _PARSED.get(key, info)
    if parsed is None:
        parsed = read_model_description(path, validate=validate)
        _PARSED.put(key, info, parsed)
    return parsed


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
        return _parsed_model_description(str(path), where.stat(), validate), xml
    except zipfile.BadZipFile as exc:
        reason = f"not an FMU: not a zip archive ({exc})"
    except KeyError:
        reason = "not an FMU: the archive holds no modelDescription.xml"
    except OSError as exc:
        reason = f"cannot read modelDescription.xml: {exc.strerror or exc}"
    except Exception as exc:  # lxml's syntax errors, fmpy's validation and attribute errors
        reason = f"broken modelDescription.xml: {type(exc).__name__}: {exc}"
    raise FmuLoadError(name, path, reason) from None


class FmuComponent(Lifecycle, VariableAccess, StateAccess, Stepping):
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
        self._start_rules: dict[str, tuple[str | None, bool]] = {}  # lifecycle's, by variable: its model's facts
        self._float_refs: dict[tuple[str, ...], list[int] | None] = {}  # variables', by a set of names
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
