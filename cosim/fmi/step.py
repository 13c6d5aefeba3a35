"""The step of an FMU instance, a part of
:class:`cosim.fmi.fmu.FmuComponent` (:class:`Stepping`): the inputs
set, the step taken and the outputs read, in the master's Python loop, and
the FMU as the compiled loop (:mod:`cosim.loop.kernel`) sees it.

* a per-step fast path: the value references of the connected inputs and of
  the wanted outputs are bound once (:meth:`Stepping.bind`) into ctypes
  arrays, and each step is one ``set`` of all inputs, one ``doStep`` and one
  ``get`` of all outputs (:class:`_Api`: the FMI functions without fmpy's
  wrapper), the values passing through preallocated numpy buffers with no
  per-step allocation; signals of other types than Float64 scalars take the
  typed calls (:mod:`cosim.fmi.variables`);
* the compiled loop's entry (:meth:`Stepping.kernel_entry`): the function
  pointers and buffers of the fast path, a Model Exchange member's calls of
  its system (:mod:`cosim.fmi.me_system`), or this component's own calls behind
  C callbacks for an FMU the compiled loop cannot drive
  (:meth:`Stepping.python_loop_reason`); a failed call there told as in the
  Python loop (:meth:`Stepping.kernel_failure`);
* an FMU asking to end the simulation (FMI 2.0 ``fmi2Terminated``, FMI 3.0
  ``terminateSimulation``) ends the run (:class:`~cosim.errors.SimulationTerminated`);
* a clocked FMI 3.0 FMU (a periodic input clock, this project's sampled-data
  FMUs: docs/fmi-export.md, "Clocks") runs in Co-Simulation with Event Mode:
  at each communication point, a tick, the clock is activated before the
  inputs are set, and :meth:`Stepping.do_step` computes the tick
  (``fmi3UpdateDiscreteStates``), steps to the next tick and enters Event Mode
  again. The values are those of the FMI 2.0 FMU, bit for bit; the master runs
  such an FMU in its Python loop (the compiled loop makes set, get and doStep
  calls only).
"""
from __future__ import annotations

import ctypes
from typing import Sequence

import numpy as np
from fmpy.fmi1 import FMICallException

from .description import TYPE_OF
from ..errors import FmuCallError, SimulationTerminated
from .variables import takes_typed_calls
from .c_calls import Call, KernelFmu

__all__ = ["Stepping"]


def _bare(slave, name: str):
    """The FMI function ``name`` of ``slave``'s library without fmpy's Python
    wrapper and without ctypes argument types: called with ctypes objects
    prepared once, it costs about half as much per call (measured 1.0 against
    2.1 us); the status is checked by the caller. Found in the library
    (``slave.dll``, fmpy's ctypes library, by the FMI name), not in fmpy's
    private table of its wrappers."""
    address = ctypes.cast(getattr(slave.dll, name), ctypes.c_void_p).value
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


class Stepping:
    """The step of :class:`cosim.fmi.fmu.FmuComponent`'s instance (a
    part of that class, not used alone): :meth:`bind`, :meth:`write_inputs`,
    :meth:`do_step`, :meth:`read_outputs`, :meth:`kernel_entry`."""

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
        self._typed = takes_typed_calls(self.variables, names)
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

    @property
    def typed_calls(self) -> bool:
        """Whether the variables :meth:`bind` bound take typed get and set
        calls (an array, an integer, a string...), not the one-call Float64
        fast path (which the Model Exchange system's C drives directly)."""
        return self._typed

    def kernel_parts(self) -> tuple:
        """What :meth:`kernel_entry` points into: the instance's calls, its
        buffers and value references, its Model Exchange system and member.
        While these are the same objects, an entry made before still holds
        (a master keeps its compiled loop's structure from run to run)."""
        return (self._api, self.system, self._me_member, self._u_ptr, self._y_ptr, self._in_vr, self._out_vr)

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

    def bare_call(self, name: str):
        """The instance's FMI function ``name`` without fmpy's wrapper (a
        caller that prepares its ctypes arguments once, e.g. the calibrator's
        right-hand side evaluations: :mod:`cosim.calibration.model`); its
        status goes to :meth:`check_status`."""
        return _bare(self._slave, name)

    def check_status(self, status: int, what: str) -> None:
        """A bare call's status: above warning, the :class:`~cosim.errors.FmuCallError`
        of this instance quoting its log (the one place status codes become exceptions)."""
        if status > 1:
            raise self._fail(what, FMICallException(function=what, status=status))

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
