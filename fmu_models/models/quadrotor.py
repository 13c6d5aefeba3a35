"""The quadrotor plant of the paper's section 2, written once in CasADi.

Conventions (paper eqs. 10-11): world frame x north, y east, z **down**;
body frame x forward, y right, z down; gravity is +g along z_W and the rotor
thrust pushes along -z_B. Altitude h is therefore -z.

States  p = (x, y, z) [m], v = (u, v, w) [m/s] (world frame, eq. 6),
        o = (phi, theta, psi) [rad] (Z-Y-X Euler angles, eq. 8),
        omega_B = (p, q, r) [rad/s] (body rates, eq. 2).
Inputs  Omega_1..4 [rad/s] rotor speeds, saturated to [0, Omega_max] (section
        5.2 saturates the control inputs); wind_x, wind_y, wind_z [m/s] wind
        velocity in the world frame.
Outputs the 12 states and the thrust and torques actually applied.

Motor dynamics (not in the paper): with tau_m > 0 each rotor speed Omega_r_i
follows its saturated command through a first-order lag,
d Omega_r_i/dt = (clip(Omega_i, 0, Omega_max) - Omega_r_i) / tau_m, and the
thrust and torques come from Omega_r; tau_m = 0 (the default) is the
instantaneous rotor of the paper, bit for bit: the rotor states are then
frozen and unused. The rotor states follow the 12 rigid-body states in the
state vector; STATE_NAMES stays the 12 rigid-body states (the plant state the
controller and the stability analysis use), ROTOR_STATE_NAMES names the four
others. See docs/plant-model.md, "Motor dynamics".

Aerodynamic drag (not in the paper, which adds wind in Gazebo) acts on the
air-relative velocity v_rel = v - v_wind through a linear (rotor drag) and a
quadratic (body drag) term, see ``docs/plant-model.md``.

Airframe and rotor aerodynamics (not in the paper; each 0 by default, the
plant above bit for bit): ``arm_angle`` turns the rotors about z_B (0 plus,
pi/4 X; :mod:`fmu_models.models.rotor`), and :func:`rotor_aerodynamics` adds
the rotor drag (H-force), axial inflow and translational lift at each hub, from
the hub's airspeed in body axes (docs/plant-model.md, "Rotor aerodynamics").
"""
from __future__ import annotations

import math

from fmu_models.lazy_casadi import ca

from ..export.model import FmuModel
from .rotor import rotor_positions, thrust_and_torques
from ..export.variables import input_, output, parameter, state

__all__ = ["QUADROTOR", "STATE_NAMES", "ROTOR_STATE_NAMES", "rotation_matrix", "euler_rate_matrix",
           "aerodynamic_drag", "rotor_aerodynamics", "body_angular_acceleration", "rotor_clip",
           "hover_rotor_speed", "DEFAULTS"]

# Keeps d|v_rel|/dv_rel finite at v_rel = 0 (the Jacobian at hover would be
# NaN otherwise); changes the drag force by k_drag_quad * 1e-6 * |v_rel|.
_SPEED_SMOOTHING = 1e-6  # m/s

_M = 1.07  # kg, Table 1
_G = 9.81  # m/s^2
_B = 6.55e-6  # N s^2, Table 1
# Rotor inputs start at the hover speed of the default parameters, so the FMU
# dropped into any importer hovers until something commands it.
_HOVER_SPEED = math.sqrt(_M * _G / (4 * _B))  # rad/s
# Inclusive lower bounds (FMI min is inclusive) of the parameters that must be
# positive: orders of magnitude below any real quadrotor, they keep out zero
# and the tiny values next to it, where dividing by m or I overflows. Reasons
# in docs/plant-model.md, "Parameter bounds".
_FLOOR = {
    "m": 1e-3,  # kg: 1 g
    "l": 1e-3,  # m: 1 mm
    "b": 1e-12,  # N s^2: a propeller of about 4 mm diameter
    "I": 1e-9,  # kg m^2: 1 g at 1 mm, the floors of m and l together
    "Omega_max": 1.0,  # rad/s: about 10 rpm
}
# Inclusive upper bound of the motor time constant tau_m: small quadrotor
# motors are 10-50 ms, heavy-lift multirotor motors with large propellers
# about 0.1-0.2 s; beyond 1 s the rotors are slower than any attitude loop
# can tolerate. Reasons in docs/plant-model.md, "Motor dynamics".
_TAU_M_MAX = 1.0  # s

_STATES = (
    state("x", "m", "position north (world frame)"),
    state("y", "m", "position east (world frame)"),
    state("z", "m", "position down (world frame; altitude is -z)"),
    state("u", "m/s", "velocity north (world frame, eq. 6)"),
    state("v", "m/s", "velocity east (world frame, eq. 6)"),
    state("w", "m/s", "velocity down (world frame, eq. 6)"),
    state("phi", "rad", "roll angle (Z-Y-X Euler, eq. 8)"),
    state("theta", "rad", "pitch angle (Z-Y-X Euler, eq. 8)"),
    state("psi", "rad", "yaw angle (Z-Y-X Euler, eq. 8)"),
    state("p", "rad/s", "body roll rate (eq. 2)"),
    state("q", "rad/s", "body pitch rate (eq. 2)"),
    state("r", "rad/s", "body yaw rate (eq. 2)"),
)
# The 12 rigid-body states in table order: the one list of the plant state's
# names (what the controller reads and the stability analysis linearizes).
STATE_NAMES: tuple[str, ...] = tuple(v.name for v in _STATES)
# Motor dynamics: the four rotor speeds, states of the FMU after the 12 above.
_ROTOR_STATES = tuple(
    state(f"Omega_r_{i}", "rad/s",
          f"speed of rotor {i}: first-order lag (tau_m) of the saturated command Omega_{i}; "
          f"frozen at its initial value and unused when tau_m = 0")
    for i in range(1, 5)
)
ROTOR_STATE_NAMES: tuple[str, ...] = tuple(v.name for v in _ROTOR_STATES)
# Euler kinematics (eq. 3) are singular at theta = +-pi/2.
_INITIAL_BOUNDS = {"theta": {"min": -1.55, "max": 1.55}}

_VARIABLES = (
    *_STATES,
    *(input_(f"Omega_{i}", "rad/s",
             f"commanded speed of rotor {i} (saturated to [0, Omega_max]); starts at hover",
             start=_HOVER_SPEED)
      for i in range(1, 5)),
    input_("wind_x", "m/s", "wind velocity north (world frame)"),
    input_("wind_y", "m/s", "wind velocity east (world frame)"),
    input_("wind_z", "m/s", "wind velocity down (world frame)"),
    output("T", "N", "total thrust applied, after rotor saturation (eq. 1)"),
    output("tau_phi", "N.m", "roll torque applied, after rotor saturation (eq. 1)"),
    output("tau_theta", "N.m", "pitch torque applied, after rotor saturation (eq. 1)"),
    output("tau_psi", "N.m", "yaw torque applied, after rotor saturation (eq. 1)"),
    parameter("m", "kg", "vehicle mass (Table 1)", _M, min=_FLOOR["m"]),
    parameter("l", "m", "arm length, centre to rotor axis (Table 1)", 0.17, min=_FLOOR["l"]),
    parameter("b", "N.s2", "rotor thrust coefficient, f_i = b Omega_i^2 (Table 1)", _B, min=_FLOOR["b"]),
    parameter("d", "N.m.s2",
              "rotor drag-torque coefficient, tau_i = d Omega_i^2 (Table 1's 2.66e-2 read as d/b in m; "
              "docs/plant-model.md)", 2.66e-2 * _B, min=0.0),
    parameter("Ix", "kg.m2", "moment of inertia about x_B (Table 1)", 3.0e-2, min=_FLOOR["I"]),
    parameter("Iy", "kg.m2", "moment of inertia about y_B (Table 1)", 4.0e-2, min=_FLOOR["I"]),
    parameter("Iz", "kg.m2", "moment of inertia about z_B (Table 1)", 2.1e-2, min=_FLOOR["I"]),
    parameter("g", "m/s2", "gravitational acceleration", _G, min=0.0),
    parameter("k_drag_lin", "N.s/m", "linear (rotor) drag coefficient on the air-relative velocity",
              0.20, min=0.0),
    parameter("k_drag_quad", "N.s2/m2", "quadratic (body) drag coefficient, 0.5 rho C_D A",
              0.04, min=0.0),
    parameter("Omega_max", "rad/s", "maximum rotor speed (thrust-to-weight about 2)", 900.0,
              min=_FLOOR["Omega_max"]),
    *(parameter(f"{v.name}_0", v.unit, f"initial value of {v.name}", 0.0, **_INITIAL_BOUNDS.get(v.name, {}))
      for v in _STATES),
    # Motor dynamics, last: the parameter vector keeps the order of the
    # instantaneous-rotor plant's parameters and appends these (before
    # internal_step); the rotor states come after the 12 rigid-body states.
    parameter("tau_m", "s",
              "motor time constant: first-order lag of each rotor speed behind its saturated command; "
              "0 = instantaneous rotors (the paper's model)", 0.0, min=0.0, max=_TAU_M_MAX),
    *(parameter(f"{v.name}_0", "rad/s",
                f"initial speed of rotor {i} (clipped to [0, Omega_max]; used only when tau_m > 0); "
                f"starts at hover, as the command Omega_{i}", _HOVER_SPEED, min=0.0)
      for i, v in enumerate(_ROTOR_STATES, start=1)),
    # Airframe and rotor aerodynamics, after the motor's (the same rule: earlier parameters keep their
    # value references); each 0 by default, which is the plant above bit for bit (docs/plant-model.md).
    parameter("arm_angle", "rad",
              "angle of rotor 1's arm from x_B towards y_B; rotor i at arm_angle + (i-1) pi/2: 0 = plus frame "
              "(rotor 1 on +x_B), pi/4 = X frame", 0.0, min=-math.pi, max=math.pi),
    parameter("k_rotor_drag", "N.s2/m",
              "rotor drag (H-force) coefficient: in-plane force -k_rotor_drag Omega_i v_perp_i at each hub "
              "(N per rad/s per m/s)", 0.0, min=0.0),
    parameter("k_inflow", "N.s2/m",
              "axial inflow coefficient: thrust of rotor i reduced by k_inflow Omega_i v_axial_i "
              "(v_axial_i: the hub's airspeed up along -z_B)", 0.0, min=0.0),
    parameter("k_translational_lift", "N.s2/m2",
              "translational lift coefficient: thrust of rotor i raised by k_translational_lift |v_perp_i|^2",
              0.0, min=0.0),
    *_ROTOR_STATES,
)


def rotation_matrix(phi, theta, psi):
    """R in SO(3), body to world, eq. (8)."""
    cph, sph = ca.cos(phi), ca.sin(phi)
    cth, sth = ca.cos(theta), ca.sin(theta)
    cps, sps = ca.cos(psi), ca.sin(psi)
    return ca.vertcat(
        ca.horzcat(cps * cth, cps * sph * sth - cph * sps, sph * sps + cph * cps * sth),
        ca.horzcat(cth * sps, cph * cps + sph * sps * sth, cph * sps * sth - cps * sph),
        ca.horzcat(-sth, cth * sph, cph * cth),
    )


def euler_rate_matrix(phi, theta):
    """T of eq. (3): Euler-angle rates = T @ omega_B (eq. 2)."""
    return ca.vertcat(
        ca.horzcat(1, ca.sin(phi) * ca.tan(theta), ca.cos(phi) * ca.tan(theta)),
        ca.horzcat(0, ca.cos(phi), -ca.sin(phi)),
        ca.horzcat(0, ca.sin(phi) / ca.cos(theta), ca.cos(phi) / ca.cos(theta)),
    )


def aerodynamic_drag(v_rel, k_drag_lin, k_drag_quad):
    """Drag force (N, world frame) on the air-relative velocity ``v_rel = v - v_wind``
    (m/s): ``-(k_drag_lin + k_drag_quad |v_rel|) v_rel`` (docs/plant-model.md); the
    plant's law, which the estimator (docs/estimation.md, eq. E6) inverts for the wind."""
    speed = ca.sqrt(ca.sumsqr(v_rel) + _SPEED_SMOOTHING**2)
    return -(k_drag_lin + k_drag_quad * speed) * v_rel


def rotor_aerodynamics(v_air, rates, speeds, l, arm_angle, k_rotor_drag, k_inflow, k_translational_lift):
    """The rotors' aerodynamic wrench in body axes (docs/plant-model.md, "Rotor aerodynamics").

    At hub i (position ``r_i``, :func:`~fmu_models.models.rotor.rotor_positions`) the air-relative velocity
    is ``v_i = v_air + omega_B x r_i`` with ``v_air = R^T (v - v_wind)`` (m/s, body axes, z down); its
    in-plane part ``v_perp_i = (v_ix, v_iy)`` and its axial part ``v_axial_i = -v_iz`` (positive when the
    hub moves up along the thrust, into the air the rotor draws in: a climb). With the applied rotor
    speeds ``Omega_i`` (rad/s):

    * rotor drag (H-force; Martin & Salaun 2010, Mahony, Kumar & Corke 2012):
      ``H_i = -k_rotor_drag Omega_i v_perp_i`` in the rotor plane;
    * axial inflow (Bangura & Mahony, momentum theory; RotorPy's ``k_z``): thrust change
      ``-k_inflow Omega_i v_axial_i``;
    * translational lift (RotorPy's ``k_h``; Leishman): thrust change ``+k_translational_lift |v_perp_i|^2``.

    Returns ``(lift, in_plane, moment)``: the thrust change summed over the rotors (N, along -z_B), the
    in-plane force ``(sum H_ix, sum H_iy, 0)`` (N) and the moment ``sum r_i x F_i`` of the forces at the
    hubs (N m). The plant adds them with :func:`_added`, which leaves every value as it was to the last
    bit when the three coefficients are 0.
    """
    lift, hx, hy = 0.0, 0.0, 0.0
    mx, my, mz = 0.0, 0.0, 0.0
    for (x, y), omega in zip(rotor_positions(l, arm_angle), speeds):
        hub = v_air + ca.cross(rates, ca.vertcat(x, y, 0.0))
        vx, vy, v_axial = hub[0], hub[1], -hub[2]
        dT = -k_inflow * omega * v_axial + k_translational_lift * (vx**2 + vy**2)
        fx, fy = -k_rotor_drag * omega * vx, -k_rotor_drag * omega * vy
        lift, hx, hy = lift + dT, hx + fx, hy + fy
        # r_i x (fx, fy, -dT) with r_i = (x, y, 0)
        mx, my, mz = mx - y * dT, my + x * dT, mz + x * fy - y * fx
    return lift, ca.vertcat(hx, hy, 0.0), (mx, my, mz)


def _added(value, term, off):
    """``value + term``, and ``value`` to the last bit where ``off``: ``value - (+0)``
    is ``value`` for every double, -0 and inf included, where ``value + 0`` turns
    -0 into +0; ``casadi.if_else`` gives an exact +0 even where ``term`` is NaN
    (``0 * inf`` at an airspeed that overflows)."""
    return value - ca.if_else(off, 0.0, -term)


def body_angular_acceleration(rates, inertia, torque):
    """d omega_B / dt (rad/s^2), eq. (4): ``(-omega x (I omega) + tau) / I``
    with ``I`` the diagonal of the inertia (kg m^2) and ``tau`` the torques (N m)."""
    return (-ca.cross(rates, inertia * rates) + torque) / inertia


def rotor_clip(omega, omega_max):
    """The rotor speeds the rotors can turn (rad/s): a command saturated to ``[0, Omega_max]``."""
    return ca.fmin(ca.fmax(omega, 0), omega_max)


def _equations(t, s):
    commanded = [rotor_clip(s[f"Omega_{i}"], s["Omega_max"]) for i in range(1, 5)]
    # Motor dynamics. casadi.if_else on SX evaluates both branches and keeps
    # one by multiplication-free selection (a + 0 or 0 + b), so tau_m = 0
    # gives exactly the instantaneous rotor of before, and the lag divides by
    # 1 instead of 0 there, which keeps the derivative and its Jacobian finite.
    instant = s["tau_m"] == 0
    tau_m = ca.if_else(instant, 1.0, s["tau_m"])
    rotor_rates = [ca.if_else(instant, 0.0, (cmd - s[name]) / tau_m)
                   for cmd, name in zip(commanded, ROTOR_STATE_NAMES)]
    applied = [ca.if_else(instant, cmd, rotor_clip(s[name], s["Omega_max"]))
               for cmd, name in zip(commanded, ROTOR_STATE_NAMES)]
    omega_sq = [omega**2 for omega in applied]
    thrust, tau_phi, tau_theta, tau_psi = thrust_and_torques(omega_sq, s["b"], s["d"], s["l"], s["arm_angle"])

    R = rotation_matrix(s["phi"], s["theta"], s["psi"])
    velocity = ca.vertcat(s["u"], s["v"], s["w"])
    v_rel = velocity - ca.vertcat(s["wind_x"], s["wind_y"], s["wind_z"])
    drag = aerodynamic_drag(v_rel, s["k_drag_lin"], s["k_drag_quad"])
    rates = ca.vertcat(s["p"], s["q"], s["r"])
    # The rotors' aerodynamic wrench, added to the thrust, the torques and the force (nothing changes at 0).
    lift, in_plane, moment = rotor_aerodynamics(R.T @ v_rel, rates, applied, s["l"], s["arm_angle"],
                                                s["k_rotor_drag"], s["k_inflow"], s["k_translational_lift"])
    off = ca.logic_and(ca.logic_and(s["k_rotor_drag"] == 0, s["k_inflow"] == 0), s["k_translational_lift"] == 0)
    thrust = _added(thrust, lift, off)
    tau_phi, tau_theta, tau_psi = (_added(tau, m, off) for tau, m in zip((tau_phi, tau_theta, tau_psi), moment))
    e3 = ca.DM([0, 0, 1])
    # eqs. (9)-(11) with the drag force and the rotors' in-plane (H) force added to F
    acceleration = (_added(-R @ e3 * thrust + drag, R @ in_plane, off)) / s["m"] + s["g"] * e3

    euler_rates = euler_rate_matrix(s["phi"], s["theta"]) @ rates  # eq. (2)
    inertia = ca.vertcat(s["Ix"], s["Iy"], s["Iz"])  # diagonal of I
    torque = ca.vertcat(tau_phi, tau_theta, tau_psi)
    angular_acceleration = body_angular_acceleration(rates, inertia, torque)  # eq. (4)

    derivatives = dict(zip(STATE_NAMES, ca.vertsplit(ca.vertcat(velocity, acceleration, euler_rates,
                                                                  angular_acceleration))))
    derivatives.update(zip(ROTOR_STATE_NAMES, rotor_rates))
    outputs = {"T": thrust, "tau_phi": tau_phi, "tau_theta": tau_theta, "tau_psi": tau_psi}
    return derivatives, outputs


QUADROTOR = FmuModel(
    identifier="Quadrotor",
    description="Quadrotor UAV (Sarabakha/Kayacan LM-FNN paper, section 2) with rotor saturation, "
                "optional first-order motor dynamics and aerodynamic drag in wind; z axis down",
    variables=_VARIABLES,
    equations=_equations,
    initial_state=lambda s: {**{name: s[f"{name}_0"] for name in STATE_NAMES},
                             **{name: rotor_clip(s[f"{name}_0"], s["Omega_max"]) for name in ROTOR_STATE_NAMES}},
)

DEFAULTS: dict[str, float] = {v.name: v.start for v in QUADROTOR.parameters}


def hover_rotor_speed(m=DEFAULTS["m"], g=DEFAULTS["g"], b=DEFAULTS["b"]) -> float:
    """Rotor speed (rad/s) at which the four rotors together carry the weight."""
    return math.sqrt(m * g / (4 * b))
