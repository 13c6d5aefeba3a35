"""The sampled closed loop from the FMUs themselves: the plant FMU and a
controller FMU of any variant, each linearized by the engine's linearizer
(:func:`cosim.linearize.linearization.linearize_fmu`), joined with ``control.interconnect``.

* plant: Model Exchange directional derivatives (all its states: the 12 of
  the rigid body and the 4 rotor speeds, inert at tau_m = 0), discretized
  with a zero-order hold at the controller's period ``dt`` -- what the
  master does: the rotor speeds are held over ``[t_n, t_n + dt)``
  (docs/stability.md);
* controller: the one-period map of its FMU's step, its discrete state
  (the learned FNN weights and the velocity controller's memory) part of the
  loop's state;
* signals joined by name: the plant's outputs (its 12 states) feed the
  controller's inputs of the same names, the controller's ``Omega_1..4``
  the plant's. The loop's inputs are the references and the wind.

Two operating points, one join (:func:`join_loop`):

* :func:`fmu_closed_loop`: a trimmed :class:`~.operating_points.OperatingPoint`,
  the controller at its initial state or a given FMU state;
* :func:`snapshot_loop`: a run frozen at time t (a :class:`cosim.loop.master.Snapshot`):
  plant and controller at their FMU states, inputs at their values then.

Discrete states the step neither changes nor reads (a PD's unused FNN
weights) are **inert**: each adds an eigenvalue 1 that no signal excites or
sees. :func:`inert_states` finds them from the closed loop's matrices and
the spectral radius is taken without them; the rest is the loop's.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from cosim.linearize.linearization import Linearization, linearize_fmu
from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import QUADROTOR
from fnn_controller.controller_fmu import ACCELERATION_INPUTS, REFERENCE_INPUTS, controller_model

from ..components import CONTROLLER_INSTANCE
from ..controller_component import DEFAULT_PLANT
from .linearize import INPUT_NAMES
from .operating_points import STATE_NAMES, OperatingPoint

__all__ = ["FmuLoop", "fmu_closed_loop", "snapshot_loop", "join_loop", "inert_states"]

_REFS = tuple(name for name, _, _ in REFERENCE_INPUTS)
_ACCS = tuple(name for name, _, _ in ACCELERATION_INPUTS)
_WIND = INPUT_NAMES[4:7]


@dataclass(frozen=True, eq=False)
class FmuLoop:
    """``system``: the closed loop (inputs the references and the wind,
    outputs the 12 plant states; its first states the plant's, then the
    controller's); ``plant``, ``controller``: the two FMUs' linearizations;
    ``inert``: indices of the inert states of ``system``."""

    system: ct.StateSpace
    controller: Linearization
    inert: tuple[int, ...]
    plant: Linearization | None = None

    @property
    def active(self) -> list[int]:
        return [i for i in range(self.system.nstates) if i not in set(self.inert)]

    @property
    def poles(self) -> np.ndarray:
        return self.poles_holding(())

    @property
    def spectral_radius(self) -> float:
        """max |eigenvalue| of the loop without its inert states: < 1 is locally stable."""
        return float(np.max(np.abs(self.poles)))

    def poles_holding(self, controller_states) -> np.ndarray:
        """The poles with the controller's ``controller_states`` (names) held at
        their values: their rows and columns removed, as the inert states' are."""
        labels = list(self.system.state_labels)
        held = {labels.index(f"controller_{n}") for n in controller_states}
        keep = [i for i in self.active if i not in held]
        return np.linalg.eigvals(np.asarray(self.system.A)[np.ix_(keep, keep)])

    def propagate(self, plant_deviation: Mapping[str, float], steps: int) -> np.ndarray:
        """The 12 plant states' deviation after ``steps`` periods of the linear
        loop from a deviation of the plant's states (by name), the
        controller's state undisturbed and the inputs held: ``C A^steps x0``."""
        labels = list(self.system.state_labels)
        x0 = np.zeros(self.system.nstates)
        for name, value in plant_deviation.items():
            x0[labels.index(f"plant_{name}")] = float(value)
        A = np.asarray(self.system.A)
        return np.asarray(self.system.C) @ np.linalg.matrix_power(A, int(steps)) @ x0


def inert_states(A: np.ndarray, atol: float = 1e-9) -> tuple[int, ...]:
    """States ``i`` with ``A[i] = e_i`` and ``A[j, i] = 0`` for ``j != i``: never
    changed by any other state and read by none (to ``atol``)."""
    A = np.asarray(A)
    n = A.shape[0]
    eye = np.eye(n)
    return tuple(i for i in range(n) if np.allclose(A[i], eye[i], rtol=0, atol=atol)
                 and np.allclose(np.delete(A[:, i], i), 0.0, rtol=0, atol=atol))


def join_loop(plant: Linearization, controller: Linearization) -> FmuLoop:
    """The plant's continuous linearization held (ZOH) over the controller's
    period and joined to the controller's one-period map by signal name."""
    import control as ct
    dt = controller.system.dt
    if not dt or plant.system.dt:
        raise ValueError(f"join_loop: expected a continuous plant (dt = {plant.system.dt}) and a sampled "
                         f"controller (dt = {dt})")

    def named(sys, system_name):  # the loop's states are then plant_<name> and controller_<name>
        return ct.ss(sys.A, sys.B, sys.C, sys.D, dt, name=system_name, states=list(sys.state_labels),
                     inputs=list(sys.input_labels), outputs=list(sys.output_labels))

    sampled = ct.c2d(plant.system, dt, method="zoh")
    loop = ct.interconnect([named(sampled, "plant"), named(controller.system, "controller")],
                           inplist=list(_REFS + _WIND), outlist=list(STATE_NAMES), check_unused=False,
                           name="fmu_closed_loop")
    loop = ct.ss(loop)
    return FmuLoop(loop, controller, inert_states(np.asarray(loop.A)), plant)


def fmu_closed_loop(op: OperatingPoint, variant: str = "pd", fmi_version: int = 2,
                    controller_state: bytes | None = None, controller_parameters=None) -> FmuLoop:
    """The sampled closed loop of ``variant`` at the trimmed point ``op`` from
    the FMUs (module docstring). ``controller_state``: a serialized FMU state
    of the controller (e.g. taken during a run); else its initial state.
    ``controller_parameters``: parameters of the controller FMU."""
    dt = op.position.dt
    start = dict(zip((v.name for v in QUADROTOR.states), np.concatenate([op.x, op.omega])))
    plant = linearize_fmu(cached_fmu(QUADROTOR, fmi_version), start=start, inputs=dict(zip(INPUT_NAMES, op.plant_u)),
                          parameters=dict(op.plant_parameters or {}), interface="me")
    inputs = (dict(zip(_REFS, np.concatenate([op.x[:3] + op.position_error, op.p_ref_dot])))
              | dict(zip(STATE_NAMES, op.x)) | dict.fromkeys(_ACCS, 0.0))
    parameters = {"psi_ref": op.psi_ref, **dict(controller_parameters or {})}
    controller = linearize_fmu(cached_fmu(controller_model(variant), fmi_version), inputs=inputs,
                               parameters=parameters, fmu_state=controller_state)
    if abs(controller.system.dt - dt) > 1e-12 * dt:
        raise ValueError(f"controller period {controller.system.dt} s differs from the operating point's dt = {dt} s")
    return join_loop(plant, controller)


def snapshot_loop(snapshot, plant_fmu: str | Path, controller_fmu: str | Path, plant: str = DEFAULT_PLANT,
                  controller: str = CONTROLLER_INSTANCE, instances: Mapping | None = None) -> FmuLoop:
    """The sampled closed loop of a run frozen at ``snapshot.time``
    (:class:`cosim.loop.master.Snapshot`, taken by ``Master.run(snapshots=...)``):
    the controller's one-period map from its FMU state with its inputs at
    that time (the learned weights as they were then), the plant linearized
    at its state then (read from its FMU state) with its inputs then (the
    wind as it blew, the rotor commands given at that time). ``plant_fmu``,
    ``controller_fmu``: the FMU files the run flew, instances ``plant`` and
    ``controller``; ``instances``: the run's live instances by name (the
    master's :class:`~cosim.fmi.fmu.FmuComponent`), on which the
    snapshot's FMU states are then read and stepped (each left in its own
    state) instead of new ones."""
    instances = instances or {}
    for name in (plant, controller):
        if name not in snapshot.states:
            raise ValueError(f"the snapshot at t = {snapshot.time:g} s has no FMU {name!r}; it has "
                             f"{', '.join(snapshot.states)}")
    ctrl = linearize_fmu(controller_fmu, inputs=snapshot.inputs_of(controller),
                         parameters=snapshot.parameters[controller], fmu_state=snapshot.states[controller],
                         t=snapshot.time, instance=instances.get(controller))
    plant_lin = linearize_fmu(plant_fmu, inputs=snapshot.inputs_of(plant),
                              parameters=snapshot.parameters[plant], fmu_state=snapshot.states[plant],
                              t=snapshot.time, interface="me", instance=instances.get(plant))
    return join_loop(plant_lin, ctrl)
