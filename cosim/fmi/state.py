"""The states of an FMU instance, a part of
:class:`cosim.fmi.fmu.FmuComponent` (:class:`StateAccess`): the FMU
state got, set and serialized (``fmiXGetFMUState``, ``fmiXSerializeFMUState``
and their inverses: FMI 2.0 section 2.1.8, FMI 3.0 section 2.2.6), a
serialized state read and edited on the live instance, which keeps its own
(a master's snapshots, the linearizer along a flight); and the Model
Exchange calls a linearizer evaluates (FMI 2.0 section 3.2.1, FMI 3.0
section 3.2): continuous states, derivatives, nominals, event indicators,
directional derivatives.
"""
from __future__ import annotations

import ctypes
from typing import Mapping, Sequence

import numpy as np
from fmpy.fmi1 import FMICallException

__all__ = ["StateAccess"]


class StateAccess:
    """The FMU state and the continuous states of
    :class:`cosim.fmi.fmu.FmuComponent`'s instance (a part of that
    class, not used alone)."""

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
