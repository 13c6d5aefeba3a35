"""Model Exchange FMUs integrated together: one solver over their stacked
continuous states, the solver's calls in C (``me_system.c``).

A Model Exchange FMU gives its state derivatives and event indicators; the
importer integrates it (FMI 2.0 §3.1, FMI 3.0 §3.1). The Model Exchange
FMUs of a run that are connected to each other form one
:class:`ModelExchangeSystem` (``coupling = "tight"``, the default): one
solver integrates all their states, and its right-hand side sets every
member's time and states, evaluates the connections between members in
dependency order (an output is read after the inputs it depends on are set:
the ModelStructure's ``Outputs`` dependencies), then reads every member's
derivatives; the members' event indicators, stacked, are its roots. So
connected Model Exchange FMUs behave like one model, as OMSimulator
integrates them. With ``coupling = "loose"`` every Model Exchange FMU is a
system of its own, its inputs held over each communication step (the
coupling error of Co-Simulation at that step). A lone FMU is a system of
one either way. docs/cosim.md, "Model Exchange".

The solver is:

* **CVODE** (BDF with root finding, SUNDIALS 7 as fmpy ships it), stopped
  exactly at every communication point and time event (``CVodeSetStopTime``);
  relative tolerance the tightest of the members' (:class:`SolverSettings`),
  each state's absolute tolerance the relative one times its nominal, as fmpy
  sets them; the Jacobian by CVODE's difference quotients; or
* **forward Euler** at a fixed step, the integrator the Reference FMUs' own
  Co-Simulation uses, so their published results are reproduced to rounding.

Events, as fmpy's ``simulateME`` handles them: a time event at the earliest
member's ``nextEventTime``, a state event where any member's indicator
changes sign, a step event when any member's ``completedIntegratorStep``
asks for one. Each stops the shared integration; every member enters Event
Mode, their event iterations run with the connections evaluated between
rounds until no member needs new discrete states, every member enters
Continuous-Time Mode, the solver restarts. An input from outside the system
(a Co-Simulation FMU, a Python component) is set at a communication point
and held over the step: a changed continuous input restarts the solver, a
changed discrete one is an input event.

The right-hand side, the event indicators, the solver and the events are
called from C (``me_system.c``); Python builds the system at the start of a
run and tells its errors. The compiled master loop (:mod:`cosim.loop.kernel`)
calls a member's ``me_member_set`` / ``me_member_get`` / ``me_member_step``
as it calls an FMU's set, get and doStep, so a run of Model Exchange FMUs
leaves C only at its blocks of rows.
"""
from __future__ import annotations

import ctypes
import enum
from dataclasses import replace
from functools import lru_cache
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import ConnectionCheckError, CosimError
from ..native import F64, F64P, I32P, I64, I64P, PTR, U32, c_header, compiled_library
from .model_exchange import COUPLINGS, IntegrationError, SolverSettings

__all__ = ["ModelExchangeSystem", "systems", "COUPLINGS", "library"]

_SOURCE = Path(__file__).with_name("me_system.c")
_HEADER = "me_system_abi.h"


class MeError(enum.IntEnum):
    """Why a call of ``me_system.c`` failed (``MeSystem.error_kind``)."""

    OK = 0
    FMI = 1  # an FMI call's status above fmiWarning (error_member, error_code: the status)
    SOLVER = 2  # CVODE's failure (error_code: its flag; message: its own words)
    TERMINATE = 3  # a member asked to terminate the simulation
    NO_SETTLE = 4  # the event iteration did not settle
    CHATTER = 5  # more events in one communication step than allowed
    PAST_EVENT = 6  # a next time event before the current time


_FMI_CALLS = ("set_time", "set_states", "get_states", "get_derivatives", "get_indicators", "get_nominals",
              "completed_step", "enter_event_mode", "update_discrete", "enter_ct_mode", "get_real", "set_real")
_FMI_NAMES = {
    2: ("fmi2SetTime", "fmi2SetContinuousStates", "fmi2GetContinuousStates", "fmi2GetDerivatives",
        "fmi2GetEventIndicators", "fmi2GetNominalsOfContinuousStates", "fmi2CompletedIntegratorStep",
        "fmi2EnterEventMode", "fmi2NewDiscreteStates", "fmi2EnterContinuousTimeMode", "fmi2GetReal", "fmi2SetReal"),
    3: ("fmi3SetTime", "fmi3SetContinuousStates", "fmi3GetContinuousStates", "fmi3GetContinuousStateDerivatives",
        "fmi3GetEventIndicators", "fmi3GetNominalsOfContinuousStates", "fmi3CompletedIntegratorStep",
        "fmi3EnterEventMode", "fmi3UpdateDiscreteStates", "fmi3EnterContinuousTimeMode", "fmi3GetFloat64",
        "fmi3SetFloat64")}

_MEMBER_FIELDS = (
    ("version", I64, "FMI 2 or 3"),
    ("component", PTR, "the fmi2Component / fmi3Instance"),
    *((name, PTR, text) for name, text in zip(_FMI_CALLS, _FMI_NAMES[2])),
    ("nx", I64, "continuous states"),
    ("nz", I64, "event indicators"),
    ("x_offset", I64, "its first state in the stacked states"),
    ("z_offset", I64, "its first indicator in the stacked indicators"),
    ("needs_completed_step", I64, "completedIntegratorStep after every solver step"),
    ("leader", I64, "its step advances the system (one member per system)"),
    ("index", I64, "its place among the members"),
    ("system", PTR, "the MeSystem it belongs to"),
    ("u_set", F64P, "its inputs from outside the system as last set"),
    ("u_known", I64, "u_set holds values (else the next set is a change)"),
    ("discrete_in", I64P, "per input from outside: 1 if discrete (set in Event Mode)"),
    ("directional", PTR, "fmi2GetDirectionalDerivative / fmi3GetDirectionalDerivative (jacobian = directional)"),
    ("state_vr", ctypes.POINTER(U32), "its states' value references"),
    ("unknown_vr", ctypes.POINTER(U32), "its derivatives', then its outputs' that feed other members"),
    ("n_unknowns", I64, ""),
    ("n_linked", I64, "its continuous inputs fed by other members"),
    ("linked_vr", ctypes.POINTER(U32), "their value references"),
    ("linked_connection", I64P, "the connection feeding each"),
    ("jac_columns", F64P, "d(unknowns)/d(state j, then linked input q), column by column"),
)

_CONNECTION_FIELDS = (
    ("source", I64, "member whose output is read"),
    ("source_vr", U32, "its value reference"),
    ("destination", I64, "member whose input is set"),
    ("destination_vr", U32, ""),
    ("factor", F64, "converted: destination = factor * source + offset"),
    ("offset", F64, ""),
    ("converted", I64, "the connection carries a unit conversion"),
    ("discrete", I64, "a discrete input: set in Event Mode only"),
    ("source_slot", I64, "the source output's place among its member's unknowns after the derivatives"),
)

_SUNDIALS = ("SUNContext_Create", "SUNContext_Free", "SUNContext_ClearErrHandlers", "SUNContext_PushErrHandler", "N_VNew_Serial", "N_VDestroy",
             "N_VGetArrayPointer", "SUNDenseMatrix", "SUNMatDestroy", "SUNLinSol_Dense", "SUNLinSolFree",
             "CVodeCreate", "CVodeInit", "CVodeReInit", "CVodeSVtolerances", "CVodeRootInit", "CVodeSetLinearSolver",
             "CVodeSetMaxStep", "CVodeSetMinStep", "CVodeSetMaxNumSteps", "CVodeSetNoInactiveRootWarn", "CVodeSetUserData",
             "CVodeSetStopTime", "CVode", "CVodeGetRootInfo", "CVodeFree", "CVodeGetReturnFlagName",
             "CVodeSetJacFn", "SUNDenseMatrix_Column")
_SUNDIALS_FIELDS = tuple((name, PTR, "") for name in _SUNDIALS)


class MeMember(ctypes.Structure):
    """One member FMU of a system: its FMI calls and its place in the stacked vectors."""

    _fields_ = [(name, kind) for name, kind, _ in _MEMBER_FIELDS]


class MeConnection(ctypes.Structure):
    """A connection between two members, evaluated inside the right-hand side."""

    _fields_ = [(name, kind) for name, kind, _ in _CONNECTION_FIELDS]


class MeSundials(ctypes.Structure):
    """The SUNDIALS entry points, from the libraries fmpy loads (no header is installed)."""

    _fields_ = [(name, kind) for name, kind, _ in _SUNDIALS_FIELDS]


_SYSTEM_FIELDS = (
    ("members", ctypes.POINTER(MeMember), "the member FMUs"),
    ("n_members", I64, ""),
    ("connections", ctypes.POINTER(MeConnection), "the connections between them, in dependency order"),
    ("n_connections", I64, ""),
    ("sundials", ctypes.POINTER(MeSundials), ""),
    ("euler", I64, "1: forward Euler; 0: CVODE"),
    ("relative_tolerance", F64, "CVODE's"),
    ("max_step", F64, "CVODE's largest step (0: unbounded)"),
    ("euler_step", F64, "Euler's step (0: the communication step)"),
    ("max_events", I64, "events allowed in one communication step"),
    ("nx", I64, "stacked states"),
    ("nz", I64, "stacked event indicators"),
    ("x", F64P, "Euler's states, derivatives, indicators now and before"),
    ("dx", F64P, ""),
    ("z", F64P, ""),
    ("z_before", F64P, ""),
    ("root_info", I32P, "CVODE's roots found"),
    ("t", F64, "the system's time (its last communication point or event)"),
    ("next_event_time", F64, "the earliest member's next time event"),
    ("has_next_event", I64, ""),
    ("events", I64, "events handled since the start"),
    ("restart", I64, "the solver restarts before its next step"),
    ("dirty", I64, "an input changed: the connections are evaluated before the next get"),
    ("event_mode", I64, "the members are in Event Mode"),
    ("cvode", PTR, "CVODE's memory, context, vectors, matrix and linear solver"),
    ("context", PTR, ""),
    ("y", PTR, ""),
    ("abstol", PTR, ""),
    ("matrix", PTR, ""),
    ("linear_solver", PTR, ""),
    ("error_kind", I64, "MeError"),
    ("error_member", I64, "the member at fault (-1: the system)"),
    ("error_code", I64, "the FMI status, CVODE's flag or the limit passed"),
    ("error_time", F64, ""),
    ("message", ctypes.c_char * 512, "CVODE's error message"),
    ("flag_name", ctypes.c_char * 64, "me_flag_name's answer"),
    ("directional", I64, "CVODE's Jacobian from the members' directional derivatives"),
    ("jac_dense", F64P, "nx * nx, column-major"),
    ("jac_du", F64P, "n_connections * nx: d(input)/d(states) of each connection"),
)


class MeSystem(ctypes.Structure):
    """A system of Model Exchange FMUs integrated by one solver."""

    _fields_ = [(name, kind) for name, kind, _ in _SYSTEM_FIELDS]


_SYS = ctypes.POINTER(MeSystem)
_ENTRY_POINTS = (("me_advance", (("s", _SYS), ("t", F64), ("t_end", F64))),
                 ("me_event", (("s", _SYS), ("t", F64))),
                 ("me_enter_event_mode", (("s", _SYS), ("t", F64))),
                 ("me_finish_event", (("s", _SYS), ("t", F64))),
                 ("me_free", (("s", _SYS),)),
                 ("me_flag_name", (("s", _SYS), ("flag", I64))),
                 ("me_jacobian", (("s", _SYS), ("t", F64), ("out", F64P))),
                 ("me_member_set", (("member", PTR), ("vr", ctypes.POINTER(U32)), ("n", ctypes.c_size_t),
                                    ("u", F64P))),
                 ("me_member_get", (("member", PTR), ("vr", ctypes.POINTER(U32)), ("n", ctypes.c_size_t),
                                    ("y", F64P))),
                 ("me_member_step", (("member", PTR), ("t", F64), ("h", F64), ("flag", ctypes.c_int))),
                 ("me_member_rows", (("member", PTR), ("t", F64P), ("steps", I64), ("in_vr", ctypes.POINTER(U32)),
                                     ("n_in", ctypes.c_size_t), ("u", F64P), ("out_vr", ctypes.POINTER(U32)),
                                     ("n_out", ctypes.c_size_t), ("y", F64P), ("row", I64P))),
                 ("me_member_evaluate_rows", (("member", PTR), ("n", I64), ("t", F64P), ("x", F64P),
                                              ("in_vr", ctypes.POINTER(U32)), ("n_in", ctypes.c_size_t),
                                              ("u", F64P), ("out_vr", ctypes.POINTER(U32)),
                                              ("n_out", ctypes.c_size_t), ("f", F64P), ("dd", PTR),
                                              ("unknown_vr", ctypes.POINTER(U32)), ("known_vr", ctypes.POINTER(U32)),
                                              ("n_known", ctypes.c_size_t), ("jac", F64P), ("row", I64P))))


def header() -> str:
    """The C header ``me_system.c`` includes, written from the definitions above."""
    return c_header("COSIM_ME_SYSTEM_ABI_H", "cosim/fmi/me_system.py", (("ME", MeError),),
                    ((MeMember, _MEMBER_FIELDS), (MeConnection, _CONNECTION_FIELDS), (MeSundials, _SUNDIALS_FIELDS),
                     (MeSystem, _SYSTEM_FIELDS)),
                    _ENTRY_POINTS)


@lru_cache(maxsize=None)
def library():
    """``me_system.c`` compiled (once per machine, :func:`cosim.native.compiled_library`)
    with its entry points typed; a one-line :class:`CosimError` without a C compiler."""
    # -ffp-contract=off: Euler's x + dt * dx rounds twice, as numpy does
    target = compiled_library(_SOURCE.read_bytes(), "cosim_me_system",
                              ("-O2", "-std=c99", "-ffp-contract=off", "-Wall", "-Werror"),
                              {_HEADER: header().encode()})
    if target is None:
        raise CosimError("Model Exchange needs a C compiler (cc or $CC) to build its solver's calls "
                         "(cosim/fmi/me_system.c); none was found")
    lib = ctypes.CDLL(str(target))
    for name, args in _ENTRY_POINTS:
        function = getattr(lib, name)
        function.argtypes, function.restype = [kind for _, kind in args], ctypes.c_int
    return lib


@lru_cache(maxsize=None)
def _sundials() -> MeSundials:
    """The SUNDIALS entry points fmpy's libraries export (SUNDIALS 7: fmpy checks the version on import)."""
    import fmpy.sundials  # noqa: F401  (checks the SUNDIALS version)
    from fmpy.sundials import libraries as lib

    owners = (lib.sundials_core, lib.sundials_nvecserial, lib.sundials_sunmatrixdense, lib.sundials_sunlinsoldense,
              lib.sundials_cvode)
    table = MeSundials()
    for name in _SUNDIALS:
        for owner in owners:
            function = getattr(owner, name, None)
            if function is not None:
                setattr(table, name, ctypes.cast(function, ctypes.c_void_p).value)
                break
        else:
            raise CosimError(f"fmpy's SUNDIALS has no {name}")
    return table


# ---- which FMUs form a system ---------------------------------------------------------------------------

def _scalar_real(fmu, variable: str) -> bool:
    from .description import TYPE_OF

    var = fmu.variables.get(variable)
    return var is not None and not var.dimensions and TYPE_OF.get(var.type, var.type) == "Float64"


def systems(fmus: Sequence, connections: Sequence, coupling: str = "tight") -> list["ModelExchangeSystem"]:
    """The :class:`ModelExchangeSystem` of every group of Model Exchange FMUs
    among ``fmus``: tight coupling, those joined by connections between them
    (of Float64 scalars: another type is exchanged at the communication points);
    loose, one each. Each member is told its system (``fmu.system``). An
    algebraic loop among members is refused in one line naming its path."""
    if coupling not in COUPLINGS:
        raise ValueError(f"coupling = {coupling!r}: expected one of {', '.join(COUPLINGS)}")
    members = [f for f in fmus if f.model_exchange]
    by_name = {f.name: f for f in members}
    internal = []
    if coupling == "tight":
        internal = [c for c in connections if c.source.component in by_name and c.destination.component in by_name
                    and c.source.component != c.destination.component
                    and _scalar_real(by_name[c.source.component], c.source.variable)
                    and _scalar_real(by_name[c.destination.component], c.destination.variable)]
    group = {f.name: f.name for f in members}  # union-find over the internal connections

    def root(name: str) -> str:
        while group[name] != name:
            name = group[name]
        return name

    for c in internal:
        group[root(c.source.component)] = root(c.destination.component)
    out = []
    for head in dict.fromkeys(root(f.name) for f in members):
        mine = [f for f in members if root(f.name) == head]
        names = {f.name for f in mine}
        out.append(ModelExchangeSystem(mine, [c for c in internal if c.destination.component in names]))
    return out


def _ordered(members: Sequence, connections: Sequence) -> list:
    """``connections`` between ``members`` in dependency order: one whose
    source output depends directly on an input (ModelStructure) comes after
    the connections into that input. A cycle is an algebraic loop: refused,
    the path named (``a.y -> b.u -> b.y -> a.u``)."""
    fmus = {f.name: f for f in members}
    into = {str(c.destination): c for c in connections}
    by_key = {str(c): c for c in connections}

    def needs(c) -> list:
        depends = fmus[c.source.component].feedthrough.get(c.source.variable, frozenset())
        return [into[f"{c.source.component}.{u}"] for u in sorted(depends) if f"{c.source.component}.{u}" in into]

    order, state = [], {}

    def visit(c, path: list) -> None:
        key = str(c)
        if state.get(key) == 2:
            return
        if state.get(key) == 1:
            cycle = path[path.index(key):]
            links = [by_key[k] for k in cycle][::-1]  # in the direction the values flow
            first = len(links) - 1  # the link the search met first leads
            steps = []
            for link in links[first:] + links[:first]:
                steps += [str(link.source), str(link.destination)]
            raise ConnectionCheckError(
                f"algebraic loop between Model Exchange FMUs: {' -> '.join(steps)}; each output needs the input "
                f"before it at the same instant (direct feedthrough): break it with a state, or delay it a step "
                f"(coupling = \"loose\" and ordering = \"exchange\" in [simulation])")
        state[key] = 1
        for d in needs(c):
            visit(d, path + [key])
        state[key] = 2
        order.append(c)

    for c in connections:
        visit(c, [])
    return order


class ModelExchangeSystem:
    """Model Exchange FMUs (:class:`~cosim.fmi.fmu.FmuComponent`) one
    solver integrates; ``connections`` (:class:`~cosim.loop.connection.Connection`)
    between them are evaluated inside its right-hand side. Built in C when
    every member has left Initialization Mode (:meth:`initialized`); its first
    member steps it (:meth:`step`, or the compiled loop's ``me_member_step``)."""

    def __init__(self, members: Sequence, connections: Sequence = ()):
        self.members = list(members)
        self.connections = _ordered(self.members, connections)
        self.internal = frozenset(str(c.destination) for c in self.connections)
        self._ready: set[str] = set()
        self._c = None  # the MeSystem and the arrays it points into
        self._entries = None  # the members' MeMember structures (in self._c's arrays)
        self.settings = self._settings()
        if self.settings.jacobian == "directional":
            lacking = [m.name for m in self.members if (m.model_description.numberOfContinuousStates
                       or any(c.destination.component == m.name for c in self.connections))
                       and not m.provides_directional_derivatives]
            if lacking:
                raise ConnectionCheckError(f"jacobian = \"directional\": {', '.join(lacking)} provide(s) no "
                                           f"directional derivatives (providesDirectionalDerivative); use the "
                                           f"default, \"difference\"")
        for m in self.members:
            m.system = self

    def _settings(self) -> SolverSettings:
        """One solver for all members: their method (the same for all), the
        tightest relative tolerance, the smallest step and event limit given."""
        given = [m.solver for m in self.members]
        methods = {s.method for s in given}
        jacobians = {s.jacobian for s in given}
        if len(jacobians) > 1:
            told = ", ".join(f"{m.name}: {s.jacobian}" for m, s in zip(self.members, given))
            raise ConnectionCheckError(f"Model Exchange FMUs solved together take one Jacobian ({told}): give "
                                       f"them the same, or set coupling = \"loose\" in [simulation]")
        if len(methods) > 1:
            told = ", ".join(f"{m.name}: {s.method}" for m, s in zip(self.members, given))
            raise ConnectionCheckError(f"Model Exchange FMUs solved together take one solver method ({told}): give "
                                       f"them the same, or set coupling = \"loose\" in [simulation]")
        steps = [s.step for s in given if s.step is not None]
        return replace(given[0], relative_tolerance=min(s.relative_tolerance for s in given),
                       step=min(steps) if steps else None, max_events=min(s.max_events for s in given))

    # ---- the lifecycle (called by the members) ----------------------------------------------------------

    def entering(self, member) -> None:
        """``member`` (re)enters Initialization Mode: the system waits for it
        (its solver of the last run freed, no member calls into it)."""
        self._ready.discard(member.name)
        self.close()

    def initialized(self, member, t0: float) -> None:
        """``member`` left Initialization Mode (it is in Event Mode); when
        every member has, the system is built and the initial event
        iteration runs (all members), then Continuous-Time Mode."""
        self._ready.add(member.name)
        if len(self._ready) < len(self.members):
            return
        self._build(t0)
        self._call(library().me_finish_event, t0)
        self._c[0].contents.events = 0

    def _build(self, t0: float) -> None:
        self.close()
        lib, settings = library(), self.settings
        members = (MeMember * len(self.members))()
        kept = []
        nx = nz = 0
        system = MeSystem()
        for i, (fmu, entry) in enumerate(zip(self.members, members)):
            dll, md = fmu._slave.dll, fmu.model_description
            entry.version, entry.component = fmu.fmi_version, fmu._slave.component
            for field, name in zip(_FMI_CALLS, _FMI_NAMES[fmu.fmi_version]):
                setattr(entry, field, ctypes.cast(getattr(dll, name), ctypes.c_void_p).value)
            entry.nx, entry.nz = md.numberOfContinuousStates, md.numberOfEventIndicators or 0
            entry.x_offset, entry.z_offset = nx, nz
            nx, nz = nx + entry.nx, nz + entry.nz
            entry.needs_completed_step = bool(fmu.kind.needsCompletedIntegratorStep)
            entry.leader, entry.index = int(i == 0), i
            u_set = np.zeros(max(fmu._n_in, 1))
            discrete = np.array([fmu.variables[n].variability != "continuous" for n in fmu.input_names] or [0],
                                dtype=np.int64)
            entry.u_set, entry.discrete_in = u_set.ctypes.data_as(F64P), discrete.ctypes.data_as(I64P)
            kept += [u_set, discrete]
            if settings.jacobian == "directional":
                kept += self._jacobian_tables(i, fmu, entry)
        index = {f.name: i for i, f in enumerate(self.members)}
        sources = {c: self._sources(self.members[index[c.source.component]]) for c in self.connections}
        links = (MeConnection * max(len(self.connections), 1))()
        for c, link in zip(self.connections, links):
            src, dst = self.members[index[c.source.component]], self.members[index[c.destination.component]]
            link.source, link.destination = index[src.name], index[dst.name]
            link.source_vr = src.variables[c.source.variable].valueReference
            variable = dst.variables[c.destination.variable]
            link.destination_vr, link.discrete = variable.valueReference, variable.variability != "continuous"
            if c.conversion is not None:
                link.converted, (link.factor, link.offset) = 1, c.conversion
            link.source_slot = sources[c].index(c.source.variable)
        buffers = [np.zeros(max(n, 1)) for n in (nx, nx, nz, nz)]
        roots = np.zeros(max(nz, 1), dtype=np.int32)
        kept += buffers + [roots, members, links]
        system.members, system.n_members = members, len(self.members)
        system.connections, system.n_connections = links, len(self.connections)
        system.sundials = ctypes.pointer(_sundials()) if settings.method == "cvode" else None
        system.euler = int(settings.method == "euler")
        system.relative_tolerance = settings.relative_tolerance
        system.max_step = settings.step if settings.method == "cvode" and settings.step is not None else 0.0
        system.euler_step = settings.step if settings.method == "euler" and settings.step is not None else 0.0
        system.max_events = settings.max_events
        system.nx, system.nz = nx, nz
        system.x, system.dx, system.z, system.z_before = (b.ctypes.data_as(F64P) for b in buffers)
        system.root_info = roots.ctypes.data_as(I32P)
        if settings.jacobian == "directional" and settings.method == "cvode":
            dense, du = np.zeros(max(nx * nx, 1)), np.zeros(max(len(self.connections) * nx, 1))
            system.directional, system.jac_dense, system.jac_du = 1, dense.ctypes.data_as(F64P), du.ctypes.data_as(F64P)
            kept += [dense, du]
        system.t, system.restart, system.event_mode = t0, 1, 1
        pointer = ctypes.pointer(system)
        address = ctypes.addressof(system)
        for entry in members:
            entry.system = address
        self._c, self._entries = (pointer, kept), members
        self._member_address = {f.name: ctypes.addressof(members[i]) for i, f in enumerate(self.members)}
        for fmu in self.members:
            fmu._me_member = ctypes.c_void_p(self._member_address[fmu.name])

    def _sources(self, fmu) -> list[str]:
        """``fmu``'s outputs that feed other members through continuous connections, in order."""
        return list(dict.fromkeys(c.source.variable for c in self.connections
                                  if c.source.component == fmu.name and not self._discrete(c)))

    def _discrete(self, c) -> bool:
        return next(m for m in self.members if m.name == c.destination.component).variables[
            c.destination.variable].variability != "continuous"

    def _jacobian_tables(self, i: int, fmu, entry) -> list:
        """The value references and the work array of member ``i``'s directional derivatives."""
        md = fmu.model_description
        vrs = lambda names: np.array([fmu.variables[n].valueReference for n in names] or [0], dtype=np.uint32)  # noqa: E731
        linked = [(k, c) for k, c in enumerate(self.connections)
                  if c.destination.component == fmu.name and not self._discrete(c)]
        unknowns = [d.variable.name for d in md.derivatives] + self._sources(fmu)
        state_vr, unknown_vr = vrs(fmu.state_names), vrs(unknowns)
        linked_vr = vrs([c.destination.variable for _, c in linked])
        linked_connection = np.array([k for k, _ in linked] or [0], dtype=np.int64)
        columns = np.zeros(max(len(unknowns) * (entry.nx + len(linked)), 1))
        if entry.nx or linked:
            entry.directional = ctypes.cast(getattr(fmu._slave.dll, f"fmi{fmu.fmi_version}GetDirectionalDerivative"),
                                            ctypes.c_void_p).value
        u32p = ctypes.POINTER(U32)
        entry.state_vr, entry.unknown_vr = state_vr.ctypes.data_as(u32p), unknown_vr.ctypes.data_as(u32p)
        entry.n_unknowns, entry.n_linked = len(unknowns), len(linked)
        entry.linked_vr, entry.linked_connection = linked_vr.ctypes.data_as(u32p), linked_connection.ctypes.data_as(I64P)
        entry.jac_columns = columns.ctypes.data_as(F64P)
        return [state_vr, unknown_vr, linked_vr, linked_connection, columns]

    def close(self) -> None:
        """Free the solver (a member closes, or a new run builds it again)."""
        if self._c is not None:
            if self._c[0].contents.sundials:
                library().me_free(self._c[0])
            self._c = self._entries = None
            for m in self.members:  # their MeMember is gone with it
                m._me_member = None

    # ---- calls in a run ----------------------------------------------------------------------------------

    def _call(self, function, *args) -> None:
        system = self._c[0]
        system.contents.error_kind = 0
        if function(system, *args):
            raise self.failure()

    @property
    def running(self) -> bool:
        """Built in C: every member has left Initialization Mode (:meth:`initialized`)."""
        return self._c is not None

    def _started(self) -> None:
        if not self.running:
            waiting = ", ".join(m.name for m in self.members if m.name not in self._ready)
            raise RuntimeError(f"the Model Exchange system of {', '.join(m.name for m in self.members)} has not "
                               f"started: {waiting} still to leave Initialization Mode")

    def step(self, member, t: float, h: float) -> None:
        """``member``'s share of the step from ``t`` to ``t + h``: the first
        member advances the whole system (C: ``me_member_step``)."""
        self._started()
        if library().me_member_step(member._me_member, t, h, 1) > 1:
            raise self.failure()

    def rows(self, member, times: np.ndarray, u: np.ndarray, y: np.ndarray) -> None:
        """``member`` (alone in its system, its inputs and outputs bound
        untyped) over the rows ``times``: at row ``i`` its bound inputs set
        to ``u[i]``, its bound outputs read into ``y[i]``, then the step to
        row ``i + 1``; the calls :meth:`set_inputs`, :meth:`get_outputs` and
        :meth:`step` make row by row, in C (``me_member_rows``: a
        calibration's trajectories). ``times``, ``u``, ``y``: C-contiguous
        float64, ``u`` rows x bound inputs, ``y`` rows x bound outputs."""
        self._started()
        row = I64(0)
        u32p = ctypes.POINTER(U32)
        status = library().me_member_rows(member._me_member, times.ctypes.data_as(F64P), times.size - 1,
                                           ctypes.cast(member._in_vr, u32p), member._n_in, u.ctypes.data_as(F64P),
                                           ctypes.cast(member._out_vr, u32p), member._n_out,
                                           y.ctypes.data_as(F64P), ctypes.byref(row))
        if status > 1:
            raise self.failure()
        member._t = float(times[-1])

    def evaluate_rows(self, member, times: np.ndarray, x: np.ndarray, u: np.ndarray, in_vr, out_vr, f: np.ndarray,
                      dd=None, unknown_vr=None, known_vr=None, jac: np.ndarray | None = None) -> None:
        """``member``'s right-hand side at the points ``(times[i], x[i], u[i])``
        (C: ``me_member_evaluate_rows``; the member alone in its system, in
        Continuous-Time Mode): ``f[i] = [der(x); outputs out_vr]``, and with
        ``dd`` (its bare ``fmiXGetDirectionalDerivative``) ``jac[i, k]`` the
        directional derivative of the ``unknown_vr`` along ``known_vr[k]``
        (FMI 2.0 section 3.2.2, FMI 3.0 section 3.2.2). Arrays C-contiguous
        float64; value references ctypes ``uint32`` arrays. A status above
        warning is the member's :class:`~cosim.errors.FmuCallError`."""
        self._started()
        row, u32p = I64(0), ctypes.POINTER(U32)
        cast = lambda vr: ctypes.cast(vr, u32p) if vr is not None else None  # noqa: E731
        status = library().me_member_evaluate_rows(
            member._me_member, times.size, times.ctypes.data_as(F64P), x.ctypes.data_as(F64P), cast(in_vr),
            u.shape[1] if u.ndim == 2 else 0, u.ctypes.data_as(F64P), cast(out_vr), f.shape[1] - x.shape[1],
            f.ctypes.data_as(F64P), ctypes.cast(dd, ctypes.c_void_p) if dd is not None else None, cast(unknown_vr),
            cast(known_vr), jac.shape[1] if jac is not None else 0,
            jac.ctypes.data_as(F64P) if jac is not None else None, ctypes.byref(row))
        if status > 1:
            member.check_status(status, f"the right-hand side at t = {float(times[row.value])!r} s")

    def set_inputs(self, member, t: float) -> None:
        """``member``'s bound inputs from outside the system (:attr:`u`), held
        over the step (C: ``me_member_set``)."""
        self._started()
        if library().me_member_set(member._me_member, member._in_vr, member._c_in, member._u_ptr) > 1:
            raise self.failure()

    def get_outputs(self, member, t: float) -> None:
        if library().me_member_get(member._me_member, member._out_vr, member._c_out, member._y_ptr) > 1:
            raise self.failure()

    def refresh(self) -> None:
        """The connections evaluated if an input changed (before a typed get)."""
        if self.running and self._c[0].contents.dirty:
            library().me_member_get(self.members[0]._me_member, None, 0, None)

    def restart(self) -> None:
        """An input changed outside the solver: it restarts at its next step."""
        system = self._c[0].contents
        system.restart, system.dirty = 1, 1

    def event(self, t: float, in_event_mode=None) -> None:
        """An event at ``t`` from outside (a discrete input set, an FMU state
        restored): every member in Event Mode (``in_event_mode()`` then, e.g.
        to set the input), the event iteration, Continuous-Time Mode."""
        self._call(library().me_enter_event_mode, t)
        if in_event_mode is not None:
            in_event_mode()
        self._call(library().me_finish_event, t)
        self._c[0].contents.events += 1

    def state_changed(self, member, t: float) -> None:
        """``member``'s FMU state was set: an event at ``t`` gives the next
        time event and restarts the solver (once the system runs); its
        inputs count as unknown."""
        if not self.running:
            return
        self._entries[self.members.index(member)].u_known = 0
        self.event(t)

    def jacobian(self, t: float) -> np.ndarray:
        """The Jacobian d(der)/dx of the stacked states at the members' states
        now, as CVODE is given it (``jacobian = "directional"``)."""
        self._started()
        nx = int(self._c[0].contents.nx)
        out = np.zeros((nx, nx), order="F")
        self._call(library().me_jacobian, t, out.ctypes.data_as(F64P))
        return out

    def failure(self) -> Exception:
        """The error of the last failed call, raised for the member at fault
        (:meth:`FmuComponent.integration_failure`)."""
        system = self._c[0].contents
        kind, code, t = MeError(system.error_kind), int(system.error_code), float(system.error_time)
        member = self.members[system.error_member] if 0 <= system.error_member < len(self.members) else None
        if kind == MeError.FMI:
            return (member or self.members[0]).integration_failure(code, t)
        if kind == MeError.SOLVER:
            library().me_flag_name(self._c[0], code)
            said = system.message.decode("utf-8", "replace")
            reason = f"CVODE failed ({system.flag_name.decode()}, flag {code})" + (f": {said}" if said else "")
        elif kind == MeError.TERMINATE:
            return member.integration_failure(IntegrationError(t, "the FMU asked to terminate the simulation",
                                                               terminate=True), t)
        elif kind == MeError.NO_SETTLE:
            reason = f"the event iteration did not settle in {code} updates of the discrete states"
        elif kind == MeError.CHATTER:
            reason = (f"more than {code} events in one communication step: the model chatters (a discontinuity "
                      f"the solver cannot pass)")
        else:
            reason = f"the next time event {float(system.next_event_time)!r} s lies in the past"
        culprit = member or self.members[0]
        return culprit.integration_failure(IntegrationError(t, reason + self._who(member)), t)

    def _who(self, member) -> str:
        if len(self.members) == 1:
            return ""
        return f" (Model Exchange system of {', '.join(m.name for m in self.members)})"
