"""The sampled closed loop from the FMUs themselves: the plant FMU and a
controller FMU of any variant, each linearized by the engine's linearizer
(:func:`cosim.linearize.linearize_fmu`), joined with ``control.interconnect``.

* plant: Model Exchange directional derivatives at ``op`` (its 12 rigid-body
  states; the rotor lag states are inert at tau_m = 0), discretized with a
  zero-order hold at the controller's period ``dt`` -- what the master does:
  the rotor speeds are held over ``[t_n, t_n + dt)`` (docs/stability.md);
* controller: the one-period map of its FMU's step, its discrete state
  (the learned FNN weights and the velocity controller's memory) part of the
  loop's state, at its initial state or at a saved FMU state of a run;
* signals joined by name: the plant's states feed the controller's inputs of
  the same names, the controller's ``Omega_1..4`` the plant's.

Discrete states the step neither changes nor reads (a PD's unused FNN
weights) are **inert**: each adds an eigenvalue 1 that no signal excites or
sees. :func:`inert_states` finds them from the closed loop's matrices and
the spectral radius is taken without them; the rest is the loop's.
"""
from __future__ import annotations

from dataclasses import dataclass

import control as ct
import numpy as np

from cosim.linearize import Linearization, linearize_fmu
from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import QUADROTOR
from fnn_controller.controller_fmu import ACCELERATION_INPUTS, REFERENCE_INPUTS, controller_model

from .linearize import INPUT_NAMES, linearize_plant_fmu
from .operating_points import STATE_NAMES, OperatingPoint

__all__ = ["FmuLoop", "fmu_closed_loop", "inert_states"]

_REFS = tuple(name for name, _, _ in REFERENCE_INPUTS)
_ACCS = tuple(name for name, _, _ in ACCELERATION_INPUTS)
_WIND = INPUT_NAMES[4:7]


@dataclass(frozen=True, eq=False)
class FmuLoop:
    """``system``: the closed loop (inputs the references and the wind,
    outputs the 12 plant states); ``controller``: the controller FMU's
    linearization; ``inert``: indices of the inert states of ``system``."""

    system: ct.StateSpace
    controller: Linearization
    inert: tuple[int, ...]

    @property
    def active(self) -> list[int]:
        return [i for i in range(self.system.nstates) if i not in set(self.inert)]

    @property
    def poles(self) -> np.ndarray:
        keep = self.active
        return np.linalg.eigvals(np.asarray(self.system.A)[np.ix_(keep, keep)])

    @property
    def spectral_radius(self) -> float:
        """max |eigenvalue| of the loop without its inert states: < 1 is locally stable."""
        return float(np.max(np.abs(self.poles)))


def inert_states(A: np.ndarray, atol: float = 1e-9) -> tuple[int, ...]:
    """States ``i`` with ``A[i] = e_i`` and ``A[j, i] = 0`` for ``j != i``: never
    changed by any other state and read by none (to ``atol``)."""
    A = np.asarray(A)
    n = A.shape[0]
    eye = np.eye(n)
    return tuple(i for i in range(n) if np.allclose(A[i], eye[i], rtol=0, atol=atol)
                 and np.allclose(np.delete(A[:, i], i), 0.0, rtol=0, atol=atol))


def fmu_closed_loop(op: OperatingPoint, variant: str = "pd", fmi_version: int = 2,
                    controller_state: bytes | None = None, controller_parameters=None) -> FmuLoop:
    """The sampled closed loop of ``variant`` at ``op`` from the FMUs (module
    docstring). ``controller_state``: a serialized FMU state of the
    controller (e.g. taken during a run); else its initial state.
    ``controller_parameters``: parameters of the controller FMU."""
    dt = op.position.dt
    plant_lin = linearize_plant_fmu(cached_fmu(QUADROTOR, fmi_version), op)
    names = dict(states=list(STATE_NAMES), inputs=list(INPUT_NAMES), outputs=list(STATE_NAMES))
    sampled = ct.c2d(ct.ss(plant_lin.A, plant_lin.B, np.eye(len(STATE_NAMES)), 0.0, **names), dt, method="zoh")
    plant = ct.ss(sampled.A, sampled.B, sampled.C, sampled.D, dt, name="plant", **names)
    inputs = (dict(zip(_REFS, np.concatenate([op.x[:3] + op.position_error, op.p_ref_dot])))
              | dict(zip(STATE_NAMES, op.x)) | dict.fromkeys(_ACCS, 0.0))
    parameters = {"psi_ref": op.psi_ref, **dict(controller_parameters or {})}
    lin = linearize_fmu(cached_fmu(controller_model(variant), fmi_version), inputs=inputs, parameters=parameters,
                        fmu_state=controller_state)
    if abs(lin.system.dt - dt) > 1e-12 * dt:
        raise ValueError(f"controller period {lin.system.dt} s differs from the operating point's dt = {dt} s")
    controller = ct.ss(lin.A, lin.B, lin.C, lin.D, dt, name="controller",
                       states=[f"z_{n}" for n in lin.system.state_labels], inputs=list(lin.system.input_labels),
                       outputs=list(lin.system.output_labels))
    loop = ct.interconnect([plant, controller], inplist=list(_REFS + _WIND), outlist=list(STATE_NAMES),
                           check_unused=False, name="fmu_closed_loop")
    loop = ct.ss(loop)
    return FmuLoop(loop, lin, inert_states(np.asarray(loop.A)))
