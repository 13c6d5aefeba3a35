"""Geometric velocity controller on SE(3) of section 3.2 (eqs. 13-18, after
Lee, Leok and McClamroch), followed by the inverse rotor model.

Conventions are the plant's (``fmu_models.models.quadrotor``): world and body z axes
point down, gravity is ``+g e3``, the rotors push along ``-z_B``, so
``m v_dot = -T R e3 + m g e3``. In this convention (which is Lee et al.'s),
the desired third body axis is

.. math:: z_B^* = \\frac{k_v e_v + m g e_3}{\\|k_v e_v + m g e_3\\|},
          \\qquad e_v = v - v^*,

the opposite of the printed eq. (13): with the printed sign, hovering at rest
(e_v = 0) would ask for ``z_B* = -e3``, i.e. upside down, while eq. (18),
``T = (k_v e_v + m g e3)^T R e3``, gives ``T = m g > 0`` at hover only with
the sign used here. Eq. (18) is used as printed.

Additions the paper leaves open (justified in ``docs/controller.md``):

* gains are normalized: the physical gains are ``m k_v`` (N s/m),
  ``diag(I) k_R`` (N m) and ``diag(I) k_omega`` (N m s), so the parameters
  are closed-loop rates independent of the vehicle;
* desired heading ``x_c = [cos psi*, sin psi*, 0]`` from a commanded yaw
  ``psi*`` (an input, default 0);
* tilt limit: the desired force ``F = m k_v e_v + m g e3`` has its vertical
  component floored at ``fz_min m g`` and its horizontal part scaled down
  so that ``z_B*`` is at most ``tilt_max`` from the vertical; this keeps
  ``x_c`` and ``z_B*`` from being parallel (the condition after eq. 14);
* ``R*_dot`` in eq. (17): zero (default) or the finite difference of R* over
  one controller step (``desired_rate="finite_difference"``), for which the
  previous R* is the controller's state;
* rotor speeds from the inverse of the plant's rotor model
  (``fmu_models.models.rotor.rotor_speeds_squared``, the vehicle's
  ``arm_angle``: plus or X), squared speeds clipped to
  ``[0, Omega_max^2]``.

The velocity-controller state ``vel_state`` (VEL_STATE_SIZE = 10) holds the
desired attitude R* of the previous step (9, column-major) and a flag that is
1 once a step has been taken since reset.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from fmu_models.lazy_casadi import ca
import numpy as np

from fmu_models.models.quadrotor import QUADROTOR, rotation_matrix
from fmu_models.models.rotor import rotor_speeds_squared

from .parameters import check_ranges, param

__all__ = [
    "VehicleParams", "GeometricParams", "DESIRED_RATE_RULES", "VEL_STATE_SIZE",
    "hat", "vee", "desired_force", "desired_attitude", "attitude_error",
    "angular_velocity_error", "thrust_and_torque", "rotor_speeds",
    "velocity_controller", "velocity_controller_function", "initial_velocity_state",
]

DESIRED_RATE_RULES = ("zero", "finite_difference")
VEL_STATE_SIZE = 10


def _plant_param(name: str):
    """A field of the nominal vehicle: the plant's parameter ``name`` (default,
    unit, description and range from the plant's variable table)."""
    v = QUADROTOR.variable(name)
    return param(v.start, v.unit, f"nominal {v.description}", min=v.min, max=v.max)


@dataclass(frozen=True)
class VehicleParams:
    """Nominal vehicle the controller assumes (plant defaults, Table 1)."""

    # Units, descriptions and ranges are the plant's (its variable table): one source.
    m: float = _plant_param("m")
    g: float = _plant_param("g")
    Ix: float = _plant_param("Ix")
    Iy: float = _plant_param("Iy")
    Iz: float = _plant_param("Iz")
    l: float = _plant_param("l")
    b: float = _plant_param("b")
    d: float = _plant_param("d")
    Omega_max: float = _plant_param("Omega_max")
    arm_angle: float = _plant_param("arm_angle")  # the airframe: the mixer's rotor positions, as the plant's

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class GeometricParams:
    """Gains and rules of the geometric velocity controller (not in the paper)."""

    k_v: float = param(5.0, "1/s", "velocity gain per unit mass (physical gain m k_v, N s/m)", min=0.0)
    k_R: tuple[float, float, float] = param((400.0, 400.0, 64.0), "1/s2",
                                            "attitude gain per unit inertia (physical I k_R, N m)", min=0.0)
    k_omega: tuple[float, float, float] = param((40.0, 40.0, 16.0), "1/s",
                                                "rate gain per unit inertia (physical I k_omega, N m s)", min=0.0)
    # (0, pi/2) as an inclusive range: 1e-6 rad up to 1e-6 rad short of the horizontal
    tilt_max: float = param(math.radians(35.0), "rad", "largest angle of z_B* from the vertical",
                            min=1e-6, max=math.pi / 2 - 1e-6)
    fz_min: float = param(0.2, "1", "floor of the vertical desired force, as a fraction of m g", min=1e-6, max=1.0)
    desired_rate: str = "zero"  # rule for R*_dot in eq. 17: "zero" or "finite_difference" (structural)
    dt: float = param(0.01, "s", "controller step (used by the finite-difference rule)", min=1e-4, max=1.0)
    vehicle: VehicleParams = field(default_factory=VehicleParams)  # nominal vehicle

    def __post_init__(self) -> None:
        if self.desired_rate not in DESIRED_RATE_RULES:
            raise ValueError(f"desired_rate {self.desired_rate!r} is not one of {DESIRED_RATE_RULES}")
        check_ranges(self)


_GEOMETRIC = GeometricParams()  # the defaults: one (frozen) instance for every signature


def hat(w):
    """Hat map R^3 -> so(3): ``hat(w) @ x = w x x``."""
    return ca.vertcat(
        ca.horzcat(0, -w[2], w[1]),
        ca.horzcat(w[2], 0, -w[0]),
        ca.horzcat(-w[1], w[0], 0),
    )


def vee(S):
    """Vee map so(3) -> R^3, the inverse of :func:`hat` (uses the
    antisymmetric part, so it is exact on skew matrices)."""
    return 0.5 * ca.vertcat(S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1])


def desired_force(v_ref, v, params: GeometricParams = _GEOMETRIC, a_ref=None):
    """Desired force along ``+z_B*`` (N), the numerator of eq. (13) with the
    sign fixed for z down, tilt-limited.

    .. math:: F = m k_v (v - v^*) + m g e_3 - m a^*

    ``a_ref`` (a*, m/s², world, z down; ``None``: no term, the paper's law
    bit for bit) is the acceleration feed-forward, an addition beyond the
    paper (Lee et al.'s tracking controller has it): with ``m v_dot = -T R e3
    + m g e3`` and ``T R e3 = F``, the closed velocity loop is then
    ``v_dot = a* - k_v (v - v*)``, so a curved reference no longer needs a
    velocity error to turn. Then ``F_z <- max(F_z, fz_min m g)`` and the horizontal part scaled by
    ``min(1, F_z tan(tilt_max) / |F_h|)``. Written without ``|F_h|`` itself
    so the function stays differentiable at hover (F_h = 0).
    """
    veh = params.vehicle
    e3 = ca.DM([0.0, 0.0, 1.0])
    force = veh.m * params.k_v * (v - v_ref) + veh.m * veh.g * e3
    if a_ref is not None:
        force = force - veh.m * a_ref
    fz = ca.fmax(force[2], params.fz_min * veh.m * veh.g)
    horizontal_sq = force[0] ** 2 + force[1] ** 2
    allowed_sq = (fz * ca.tan(params.tilt_max)) ** 2
    scale = ca.sqrt(allowed_sq / ca.fmax(horizontal_sq, allowed_sq))
    return ca.vertcat(scale * force[0], scale * force[1], fz)


def desired_attitude(force, psi_ref):
    """Desired attitude R*, eqs. (13)-(15).

    ``z_B* = F / |F|`` (eq. 13, sign fixed), heading ``x_c = [cos psi*,
    sin psi*, 0]``, ``y_B* = z_B* x x_c / |z_B* x x_c|`` (eq. 14),
    ``R* = [y_B* x z_B*, y_B*, z_B*]`` (eq. 15).
    """
    z_b = force / ca.norm_2(force)
    x_c = ca.vertcat(ca.cos(psi_ref), ca.sin(psi_ref), 0.0)
    y_raw = ca.cross(z_b, x_c)
    y_b = y_raw / ca.norm_2(y_raw)
    return ca.horzcat(ca.cross(y_b, z_b), y_b, z_b)


def attitude_error(R_ref, R):
    """Attitude error on SO(3), eq. (16): ``e_R = 1/2 (R*^T R - R^T R*)^vee``."""
    return 0.5 * vee(R_ref.T @ R - R.T @ R_ref)


def angular_velocity_error(omega_b, R, R_ref, omega_ref):
    """Angular-velocity error, eq. (17): ``e_omega = omega_B - R^T R* omega*``
    with ``omega* = (R*^T R*_dot)^vee`` (rad/s)."""
    return omega_b - R.T @ R_ref @ omega_ref


def thrust_and_torque(force, R, e_R, e_omega, omega_b, params: GeometricParams = _GEOMETRIC):
    """Control inputs (1) by eq. (18).

    .. math:: T = F^T R e_3, \\qquad
              \\tau = -I k_R e_R - I k_\\omega e_\\omega + \\omega_B \\times I \\omega_B

    Returns ``(T, tau)``: thrust (N), body torques (N m, 3-vector).
    """
    veh = params.vehicle
    inertia = ca.vertcat(veh.Ix, veh.Iy, veh.Iz)
    thrust = ca.dot(force, R[:, 2])
    tau = (-inertia * ca.vertcat(*params.k_R) * e_R - inertia * ca.vertcat(*params.k_omega) * e_omega
           + ca.cross(omega_b, inertia * omega_b))
    return thrust, tau


def rotor_speeds(thrust, tau, vehicle: VehicleParams = VehicleParams()):
    """Rotor speeds (rad/s) by the inverse rotor model, saturated.

    Squared speeds from ``fmu_models.models.rotor.rotor_speeds_squared`` (the
    vehicle's airframe, ``arm_angle``: 0 plus, pi/4 X), each clipped to ``[0, Omega_max^2]`` before the root.
    """
    squares = rotor_speeds_squared(thrust, tau[0], tau[1], tau[2], vehicle.b, vehicle.d, vehicle.l,
                                   vehicle.arm_angle)
    return ca.vertcat(*[ca.sqrt(ca.fmin(ca.fmax(s, 0.0), vehicle.Omega_max**2)) for s in squares])


def velocity_controller(v_ref, v, euler, omega_b, psi_ref, vel_state, params: GeometricParams = _GEOMETRIC,
                        a_ref=None):
    """The geometric velocity controller as CasADi expressions.

    Parameters
    ----------
    v_ref : 3-vector
        Desired velocity v* (m/s, world, z down).
    v : 3-vector
        Velocity (m/s, world).
    euler : 3-vector
        phi, theta, psi (rad, Z-Y-X, eq. 8).
    omega_b : 3-vector
        Body rates p, q, r (rad/s).
    psi_ref : scalar
        Commanded yaw psi* (rad), sets the heading x_c.
    vel_state : vector of length VEL_STATE_SIZE
        Previous R* (column-major) and the primed flag.
    params : GeometricParams
    a_ref : 3-vector or None
        Acceleration fed forward into the desired force (m/s², world, z
        down; :func:`desired_force`); ``None`` (default): none, the paper's law.

    Returns
    -------
    dict
        ``Omega`` (4, rad/s), ``wrench`` (4: T in N, tau in N m, before rotor
        saturation), ``e_R`` (3), ``e_omega`` (3, rad/s), ``R_ref`` (3x3),
        ``vel_state_next``.
    """
    R = rotation_matrix(euler[0], euler[1], euler[2])
    force = desired_force(v_ref, v, params, a_ref)
    R_ref = desired_attitude(force, psi_ref)
    e_R = attitude_error(R_ref, R)
    if params.desired_rate == "finite_difference":
        R_prev = ca.reshape(vel_state[0:9], 3, 3)
        omega_ref = vel_state[9] * vee(R_prev.T @ R_ref - R_ref.T @ R_prev) / (2.0 * params.dt)
    else:
        omega_ref = ca.DM.zeros(3)
    e_omega = angular_velocity_error(omega_b, R, R_ref, omega_ref)
    thrust, tau = thrust_and_torque(force, R, e_R, e_omega, omega_b, params)
    return {
        "Omega": rotor_speeds(thrust, tau, params.vehicle),
        "wrench": ca.vertcat(thrust, tau),
        "e_R": e_R,
        "e_omega": e_omega,
        "R_ref": R_ref,
        "vel_state_next": ca.vertcat(ca.reshape(R_ref, 9, 1), 1.0),
    }


def velocity_controller_function(params: GeometricParams = _GEOMETRIC) -> ca.Function:
    """The geometric velocity controller as one CasADi function.

    ``velocity_controller(v_ref[3], v[3], euler[3], omega_b[3], psi_ref,
    vel_state[10]) -> (Omega[4], vel_state_next[10], wrench[4], e_R[3],
    e_omega[3])``, units as in :func:`velocity_controller`.
    """
    v_ref = ca.SX.sym("v_ref", 3)
    v = ca.SX.sym("v", 3)
    euler = ca.SX.sym("euler", 3)
    omega_b = ca.SX.sym("omega_b", 3)
    psi_ref = ca.SX.sym("psi_ref")
    vel_state = ca.SX.sym("vel_state", VEL_STATE_SIZE)
    out = velocity_controller(v_ref, v, euler, omega_b, psi_ref, vel_state, params)
    return ca.Function(
        "velocity_controller",
        [v_ref, v, euler, omega_b, psi_ref, vel_state],
        [out["Omega"], out["vel_state_next"], out["wrench"], out["e_R"], out["e_omega"]],
        ["v_ref", "v", "euler", "omega_b", "psi_ref", "vel_state"],
        ["Omega", "vel_state_next", "wrench", "e_R", "e_omega"],
    )


def initial_velocity_state() -> np.ndarray:
    """Velocity-controller state after reset: R*_prev = identity, not primed."""
    return np.concatenate([np.eye(3).reshape(-1, order="F"), [0.0]])
