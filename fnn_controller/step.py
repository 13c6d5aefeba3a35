"""The whole controller step of Fig. 2: its inputs, outputs and state.

The step composes the position controller of :mod:`fnn_controller.position`
(outer loop, 3 axes, PD + FNN with learning) and the geometric velocity
controller of :mod:`fnn_controller.geometric` (inner loop, rotor-speed
inversion) into one controller step (dt = 0.01 s; outer and inner loop run
at the same rate): :func:`fnn_controller.parametric.parametric_step_function`,
the one composition, which the co-simulation master, the controller FMUs and
:class:`~fnn_controller.fast.QuadrotorController` evaluate (fixed gains are
its parameter vector ``p`` bound to values,
:func:`~fnn_controller.parametric.bound_step_function`). This module says
what goes in and out:

``controller_step_<variant>_parametric(p_ref[3], p_ref_dot[3], x[12], psi_ref, state[85], p[m], p_ref_ddot[3])
-> (y[17], state_next[85], check)``

========== ====== ==========================================================
input      unit   meaning
========== ====== ==========================================================
p_ref      m      desired position p* (world, z down)
p_ref_dot  m/s    its time derivative (from the trajectory, not differenced)
x          SI     plant state x y z u v w phi theta psi p q r
psi_ref    rad    commanded yaw (desired heading)
state      --     controller state: FNN (75, :mod:`~fnn_controller.position`)
                  then velocity controller (10, :mod:`~fnn_controller.geometric`)
p          --     the parameters (:func:`~fnn_controller.parametric.parameter_table`)
p_ref_ddot m/s2   d²p*/dt² (from the trajectory), read only with the option
                  ``PositionParams.accel_feedforward`` > 0; last, so every
                  earlier input keeps its index
========== ====== ==========================================================

========== ====== ==========================================================
output     unit   meaning
========== ====== ==========================================================
y          --     the 17 outputs of :data:`OUTPUTS`, parts :data:`Y_SLICES`:
Omega      rad/s  rotor speeds, in [0, Omega_max]
v_ref      m/s    desired velocity v* = tau_c - tau_n (eq. 26)
tau_c      m/s    PD part (eq. 19)
tau_n      m/s    FNN part (eq. 24)
wrench     N, Nm  T, tau_phi, tau_theta, tau_psi of eq. 18, before saturation
state_next --     controller state for the next step
check      --     sum of every input and output: finite iff all of them are
========== ====== ==========================================================

The functions here take the :class:`~fnn_controller.variants.Variant`
itself (a name is resolved where it enters).
"""
from __future__ import annotations

from fmu_models.lazy_casadi import ca
import numpy as np

from fmu_models.models.quadrotor import STATE_NAMES

from .geometric import VEL_STATE_SIZE, initial_velocity_state
from .position import FNN_STATE_SIZE, fnn_state_size, initial_fnn_state
from .position_parameters import PositionParams

_POSITION = PositionParams()  # the defaults: one (frozen) instance for every signature
from .variants.registry import Variant

__all__ = [
    "STATE_SIZE", "PLANT_STATE_NAMES", "OUTPUTS", "Y_PARTS", "Y_SLICES", "STEP_INPUT_NAMES",
    "state_size", "state_ports", "check_state", "step_symbols", "initial_state", "raise_non_finite",
]

STATE_SIZE = FNN_STATE_SIZE + VEL_STATE_SIZE  # the paper's variants


def state_ports(variant: Variant) -> tuple[tuple[str, str, str], ...]:
    """Name, unit and meaning of every element of ``variant``'s controller
    state, in state order: the learned state of each axis (``f_12_x``, the
    variant's axis state ports per axis), then the velocity controller's
    previous R* and its flag. The one naming of the state: the controller
    FMU's locals, the component's published signals, learned-state files."""
    learned = tuple((f"{name}_{axis}", unit, f"learned state of axis {axis} ({variant.label})")
                    for axis in "xyz" for name, unit in variant.axis_state_ports)
    previous = tuple((f"R_ref_prev_{i}", "1", "previous desired attitude R*, column-major") for i in range(1, 10))
    ports = learned + previous + (("R_ref_primed", "1", "1 once R* has been computed since reset"),)
    assert len(ports) == state_size(variant)
    return ports


ROTATION_TOLERANCE = 1e-6  # |R^T R - I| and |det R - 1| of a saved R*: a float rotation is within 1e-15


def check_state(variant: Variant, state) -> None:
    """Refuse a controller state of ``variant`` (:func:`state_ports` order)
    that no flight can reach, naming the element and its allowed range: a
    membership function's width ``sigma`` (eqs. 21-22, a Gaussian's) must be
    positive, (0, inf): at 0 the firing strengths are 0/0, below it the FNN
    is no longer one; the previous desired attitude R* (eq. 14) must be a
    rotation, R^T R = I and det R = +1 (to :data:`ROTATION_TOLERANCE`):
    the attitude error of eq. 16 is defined on SO(3) only.

    Raises
    ------
    ValueError
        ``sigma1_1_x = -1.0 m: a membership function's width must be in (0, inf)``.
    """
    ports = state_ports(variant)
    state = np.asarray(state, dtype=float)
    for (name, unit, _), value in zip(ports, state):
        if name.startswith("sigma") and not value > 0:
            raise ValueError(f"{name} = {float(value)!r} {unit}: a membership function's width must be in (0, inf)")
    names = [name for name, _, _ in ports]
    first = names.index("R_ref_prev_1")
    R = state[first:first + 9].reshape(3, 3, order="F")  # column-major, as the state holds it
    with np.errstate(over="ignore", invalid="ignore"):  # huge entries: an infinite deviation, refused below
        deviation = max(float(np.abs(R.T @ R - np.eye(3)).max()), abs(float(np.linalg.det(R)) - 1.0))
    if not deviation <= ROTATION_TOLERANCE:
        raise ValueError(f"R_ref_prev_1..9 = {np.round(R.reshape(-1, order='F'), 6).tolist()}: the previous desired "
                         f"attitude R* must be a rotation (R^T R = I, det R = +1, to {ROTATION_TOLERANCE:g}; "
                         f"off by {deviation:.3g})")


def state_size(variant: Variant) -> int:
    """Size of the whole controller state of ``variant``: position part, then velocity part."""
    return fnn_state_size(variant) + VEL_STATE_SIZE


PLANT_STATE_NAMES = STATE_NAMES  # x y z u v w phi theta psi p q r, the plant's table

# The step's outputs as one vector ``y``, part by part (name, unit, meaning):
# the one layout the co-simulation component and the controller FMU publish.
_Y = (
    ("Omega", tuple((f"Omega_{i}", "rad/s", f"rotor {i} speed command") for i in range(1, 5))),
    ("v_ref", tuple((f"v_ref_{a}", "m/s", f"desired velocity {a}, v* = tau_c - tau_n (eq. 26)") for a in "xyz")),
    ("tau_c", tuple((f"tau_c_{a}", "m/s", f"PD output {a} (eq. 19)") for a in "xyz")),
    ("tau_n", tuple((f"tau_n_{a}", "m/s", f"FNN output {a} (eq. 24)") for a in "xyz")),
    ("wrench", (("T", "N", "thrust demand (eq. 18), before saturation"),
                ("tau_phi", "N.m", "roll torque demand (eq. 18)"),
                ("tau_theta", "N.m", "pitch torque demand (eq. 18)"),
                ("tau_psi", "N.m", "yaw torque demand (eq. 18)"))),
)
OUTPUTS: tuple[tuple[str, str, str], ...] = tuple(o for _, part in _Y for o in part)
Y_PARTS = tuple(name for name, _ in _Y)  # in the order of OUTPUTS
_ENDS = np.cumsum([len(part) for _, part in _Y]).tolist()
Y_SLICES: dict[str, slice] = {name: slice(end - len(part), end) for (name, part), end in zip(_Y, _ENDS)}

_INPUTS = ("p_ref", "p_ref_dot", "x", "psi_ref", "p_ref_ddot")  # the checked inputs; state is the function's own


def step_symbols(variant: Variant) -> list[ca.SX]:
    """The input symbols ``p_ref, p_ref_dot, x, psi_ref, state, p_ref_ddot`` of ``variant``'s step."""
    return [ca.SX.sym("p_ref", 3), ca.SX.sym("p_ref_dot", 3), ca.SX.sym("x", 12), ca.SX.sym("psi_ref"),
            ca.SX.sym("state", state_size(variant)), ca.SX.sym("p_ref_ddot", 3)]


STEP_INPUT_NAMES = ("p_ref", "p_ref_dot", "x", "psi_ref", "state", "p_ref_ddot")  # in the order of step_symbols


def raise_non_finite(inputs: dict[str, np.ndarray]) -> None:
    """Raise ``ValueError`` naming the first non-finite controller input and
    its value, else ``FloatingPointError`` (finite inputs, non-finite result)."""
    for name in _INPUTS:
        values = inputs[name]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            where = f"x[{bad[0]}] ({PLANT_STATE_NAMES[bad[0]]})" if name == "x" else f"{name}[{bad[0]}]"
            raise ValueError(f"controller input {where} = {float(values[bad[0]])!r} is not finite")
    raise FloatingPointError(
        "the controller produced a non-finite value from finite inputs; its state is left unchanged")


def initial_state(variant: Variant, seed: int | np.random.Generator,
                  position: PositionParams = _POSITION) -> np.ndarray:
    """Controller state after reset: the variant's initial values of section 5.1
    (f_ij(0) from ``seed``) followed by the velocity-controller state."""
    return np.concatenate([initial_fnn_state(variant, seed, position), initial_velocity_state()])
