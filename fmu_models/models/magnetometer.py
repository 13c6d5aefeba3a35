"""A three-axis magnetometer as an FMU: the local Earth field seen in the body
frame, with white noise and a hard-iron offset, seeded (docs/sensors.md,
"Magnetometer"; the law is eq. E24 of docs/estimation.md).

Per communication step n (``t_n = n dt``)::

    mag_n    = R(phi_n, theta_n, psi_n)^T m_W + b_m + sigma_m w_n           (E24)
    t_sample = t_n                                                          the time the sample refers to

with ``R`` of eq. 8 (body to world, z down), ``m_W = (m_N, m_E, m_D)`` the
site's field in the world frame (NED, tesla), ``b_m`` the constant hard-iron
offset left after calibration (body frame) and ``w`` standard normal numbers
drawn by Box-Muller from numpy's ``default_rng(seed)`` (6 uniform numbers a
step: x, y, z; r1 first, as in ``sensors.py``). The field is the rotated
world field only: the field of the vehicle's own currents (motors) is left
out, and the filter's noise takes the offset's residual (docs/estimation.md,
"Heading").

Defaults: Bosch BMM150 (docs/sensors.md): RMS noise 0.6 uT per axis (regular
preset); the site field a mid-latitude one of the World Magnetic Model (about
48 uT, inclination 64 deg).
"""
from __future__ import annotations

from fmu_models.lazy_casadi import ca

from ..export.model import FmuModel, Sampled
from ..export.variables import discrete, input_, output, parameter, seed_parameter
from .imu import AXES
from .quadrotor import rotation_matrix
from .sensors import DT_DEFAULT, gaussian

__all__ = ["MAGNETOMETER", "MAGNETOMETER_DEFAULTS", "body_field", "heading_from_field"]

# docs/sensors.md, "Magnetometer": BMM150 noise (regular preset); a WMM mid-latitude field (NED, tesla)
MAGNETOMETER_DEFAULTS = {
    "sigma_mag": 0.6e-6,       # T: RMS noise per axis
    "field_north": 21.0e-6,    # T
    "field_east": 1.5e-6,      # T
    "field_down": 43.5e-6,     # T
}


def body_field(attitude, field_world):
    """The world field seen in the body frame, eq. E24 without noise and offset:
    ``R(phi, theta, psi)^T m_W``; numbers or CasADi expressions (the FMU's and
    the estimator's law)."""
    return rotation_matrix(attitude[0], attitude[1], attitude[2]).T @ field_world


def heading_from_field(roll, pitch, mag, field_world):
    """The heading ``psi`` (rad, in [-pi, pi]) at which the body-frame field
    ``mag`` is the world field ``field_world`` seen at ``roll`` and ``pitch``
    (E28, docs/estimation.md "Heading"): E24 solved for the yaw. With
    ``R = R_z(psi) R_y(theta) R_x(phi)`` (eq. 8), ``R_y R_x mag = R_z(psi)^T m_W``
    is the field in the vehicle's level frame, whose horizontal direction is
    the site's (``atan2(m_E, m_N)``, the declination) turned by ``-psi``::

        h   = R(phi, theta, 0) mag
        psi = atan2(m_E, m_N) - atan2(h_y, h_x)                         (E28)

    The tilt-compensated compass of every flight controller's start; numbers
    or CasADi expressions (the estimator's law)."""
    h = rotation_matrix(roll, pitch, 0.0) @ mag
    psi = ca.atan2(field_world[1], field_world[0]) - ca.atan2(h[1], h[0])
    return ca.atan2(ca.sin(psi), ca.cos(psi))


_VARIABLES = (
    input_("phi", "rad", "roll angle (Z-Y-X Euler, eq. 8)", 0.0),
    input_("theta", "rad", "pitch angle (Z-Y-X Euler, eq. 8)", 0.0),
    input_("psi", "rad", "yaw angle (Z-Y-X Euler, eq. 8)", 0.0),
    *(output(f"mag_{i}", "T", f"measured magnetic field along {i}_B (noise and offset, eq. E24)") for i in AXES),
    output("t_sample", "s", "time the sample refers to: the FMU's time when it read the plant (an estimator "
                            "fuses it at that time, docs/estimation.md)"),
    output("fresh", "1", "1: a new sample every step (the estimator's fresh_mag)"),
    parameter("sigma_mag", "T", "standard deviation of the white noise on each axis",
              MAGNETOMETER_DEFAULTS["sigma_mag"], min=0.0),
    *(parameter(f"field_{d}", "T", f"the site's Earth field, {d} component (world frame NED)",
                MAGNETOMETER_DEFAULTS[f"field_{d}"]) for d in ("north", "east", "down")),
    *(parameter(f"bias_{i}", "T", f"hard-iron offset along {i}_B left after calibration (constant)", 0.0)
      for i in AXES),
    seed_parameter("seed", "seed of numpy's default_rng that draws the noise (6 numbers per step)"),
    parameter("dt", "s", "communication step = output period of the magnetometer (every doStep must be dt)",
              DT_DEFAULT, min=1e-6, max=10.0),
    discrete("started", "1", "0 before the first step, 1 after (the law keeps no memory: a discrete state for "
                             "the sampled-data export)"),
)


def _update(t, v, rs):
    field = body_field([v["phi"], v["theta"], v["psi"]],
                       ca.vertcat(v["field_north"], v["field_east"], v["field_down"]))
    out = {"t_sample": t, "fresh": 1.0}
    for k, i in enumerate(AXES):
        out[f"mag_{i}"] = field[k] + v[f"bias_{i}"] + v["sigma_mag"] * gaussian(rs[2 * k], rs[2 * k + 1])
    return out, {"started": 1.0}


MAGNETOMETER = FmuModel(
    identifier="Magnetometer3",
    description="three-axis magnetometer (body frame): the site's Earth field rotated into the body frame, "
                "with white noise and a constant hard-iron offset; seeded; z axis down",
    variables=_VARIABLES,
    sampled=Sampled(update=_update, initial=lambda v, r: {"started": 0.0}, n_random=0, seed="seed", sample_period="dt",
                    n_random_step=6),
)
