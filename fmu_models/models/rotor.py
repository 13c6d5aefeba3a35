"""Rotor model of the paper's section 2.1: rotor speeds -> thrust and torques.

Body frame x forward, y right, z down (the paper's convention). Rotor i sits
at the hub ``r_i = l (cos a_i, sin a_i, 0)`` with ``a_i = arm_angle + (i - 1) pi/2``
measured from x_B towards y_B (docs/plant-model.md, "Airframes").
``arm_angle = 0`` is the plus configuration of Mahony et al. (2012), which the
paper follows for the input vector u = [T, tau_phi, tau_theta, tau_psi]
(eq. 1): rotor 1 on +x, 2 on +y, 3 on -x, 4 on -y; ``arm_angle = pi/4`` is the
X. Rotors 1 and 3 turn the other way from 2 and 4 (:data:`SPIN`). Each rotor
pushes b * Omega_i**2 along -z_B and reacts with a drag torque d * Omega_i**2.
The roll and pitch torques are the moments ``sum r_i x f_i`` of the thrusts; for
the plus frame

    T         = b (O1^2 + O2^2 + O3^2 + O4^2)
    tau_phi   = b l (O4^2 - O2^2)
    tau_theta = b l (O1^2 - O3^2)
    tau_psi   = d (-O1^2 + O2^2 - O3^2 + O4^2)

and for any arm angle, the rotors being the plus frame's turned by
``arm_angle`` about z_B (and the thrusts along z_B unchanged by that turn),
the plus frame's roll and pitch torques turned by the same angle:

    [tau_phi, tau_theta] = Rz(arm_angle) [tau_phi+, tau_theta+]

With ``arm_angle = 0`` (cos = 1, sin = 0 exactly) this is the plus formula to
the last bit: ``1 x = x`` and adding ``0 y`` changes no nonzero number.

Written with plain arithmetic (and ``casadi.cos``/``sin``, which take floats
too) so the same functions serve CasADi symbols (the plant FMU, the
controller) and Python numbers.
"""
from __future__ import annotations

from fmu_models.lazy_casadi import ca

__all__ = ["SPIN", "rotor_positions", "thrust_and_torques", "rotor_speeds_squared"]

# Spin of rotor i as the sign of its reaction torque about z_B (z down): tau_psi = d sum SPIN_i Omega_i^2.
SPIN = (-1.0, 1.0, -1.0, 1.0)


def rotor_positions(l, arm_angle):
    """Hub positions ``(x_i, y_i)`` (m, body frame; z_i = 0) of rotors 1..4:
    ``l (cos a_i, sin a_i)``, ``a_i = arm_angle + (i - 1) pi/2``, written as
    quarter turns of rotor 1's arm so that they are exact at ``arm_angle = 0``."""
    c, s = l * ca.cos(arm_angle), l * ca.sin(arm_angle)
    return [(c, s), (-s, c), (-c, -s), (s, -c)]


def thrust_and_torques(omega_squared, b, d, l, arm_angle=0.0):
    """[T, tau_phi, tau_theta, tau_psi] (N, N m) from the squared rotor speeds
    (rad^2/s^2): the moments ``r_i x f_i`` of the thrusts ``f_i = -b O_i^2 e3``
    at the hubs of :func:`rotor_positions`."""
    o1, o2, o3, o4 = (omega_squared[i] for i in range(4))
    roll, pitch = b * l * (o4 - o2), b * l * (o1 - o3)  # the plus frame's
    c, s = ca.cos(arm_angle), ca.sin(arm_angle)
    return (
        b * (o1 + o2 + o3 + o4),
        c * roll - s * pitch,
        s * roll + c * pitch,
        d * (-o1 + o2 - o3 + o4),
    )


def rotor_speeds_squared(thrust, tau_phi, tau_theta, tau_psi, b, d, l, arm_angle=0.0):
    """Inverse of :func:`thrust_and_torques`: the squared rotor speeds that
    produce the wanted thrust (N) and torques (N m), before any saturation:
    the torques turned back by ``-arm_angle`` into the plus frame's, then the
    plus frame's inverse."""
    c, s = ca.cos(arm_angle), ca.sin(arm_angle)
    t = thrust / (4 * b)
    roll = (c * tau_phi + s * tau_theta) / (2 * b * l)
    pitch = (c * tau_theta - s * tau_phi) / (2 * b * l)
    yaw = tau_psi / (4 * d)
    return (
        t + pitch - yaw,
        t - roll + yaw,
        t - pitch - yaw,
        t + roll + yaw,
    )
