"""Rotor model of the paper's section 2.1: rotor speeds -> thrust and torques.

Plus configuration as in Mahony et al. (2012), which the paper follows for the
input vector u = [T, tau_phi, tau_theta, tau_psi] (eq. 1). Body frame x forward,
y right, z down (the paper's convention); rotor 1 on +x, 2 on +y, 3 on -x,
4 on -y; rotors 1 and 3 turn the other way from 2 and 4. Each rotor pushes
b * Omega_i**2 along -z_B and reacts with a drag torque d * Omega_i**2:

    T         = b (O1^2 + O2^2 + O3^2 + O4^2)
    tau_phi   = b l (O4^2 - O2^2)
    tau_theta = b l (O1^2 - O3^2)
    tau_psi   = d (-O1^2 + O2^2 - O3^2 + O4^2)

Written with plain arithmetic so the same functions serve CasADi symbols (the
plant FMU, the controller) and numpy arrays (tests).
"""
from __future__ import annotations

__all__ = ["thrust_and_torques", "rotor_speeds_squared"]


def thrust_and_torques(omega_squared, b, d, l):
    """[T, tau_phi, tau_theta, tau_psi] from the squared rotor speeds (rad^2/s^2)."""
    o1, o2, o3, o4 = (omega_squared[i] for i in range(4))
    return (
        b * (o1 + o2 + o3 + o4),
        b * l * (o4 - o2),
        b * l * (o1 - o3),
        d * (-o1 + o2 - o3 + o4),
    )


def rotor_speeds_squared(thrust, tau_phi, tau_theta, tau_psi, b, d, l):
    """Inverse of :func:`thrust_and_torques`: the squared rotor speeds that
    produce the wanted thrust (N) and torques (N m), before any saturation."""
    t = thrust / (4 * b)
    roll = tau_phi / (2 * b * l)
    pitch = tau_theta / (2 * b * l)
    yaw = tau_psi / (4 * d)
    return (
        t + pitch - yaw,
        t - roll + yaw,
        t - pitch - yaw,
        t + roll + yaw,
    )
