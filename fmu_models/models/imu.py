"""An inertial measurement unit as an FMU: gyroscope and accelerometer in the
body frame, white noise and bias random walk, seeded (docs/sensors.md, "IMU";
the laws are eqs. E1-E4 of docs/estimation.md).

A real IMU delivers, at its output data rate, the average of the sensed rate
and specific force over the last sample period (delta-angle / delta-velocity
over dt). This one does the same over each communication step, from the
plant's states alone: velocity ``u, v, w`` (world frame, z down), attitude
``phi, theta, psi`` and body rates ``p, q, r``. Reading the plant's
acceleration instead would make the plant's output depend on its rotor
inputs, and plant -> IMU -> estimator -> controller -> plant an algebraic loop
(docs/estimation.md, "Timing"). Per communication step n (``t_n = n dt``)::

    f_B,n    = (R_{n-1} + R_n)^T / 2 ((v_n - v_{n-1}) / dt - g e3)    specific force over the step (E1)
    omega_n  = (omega_B,{n-1} + omega_B,n) / 2                        rate over the step
    gyro_n   = omega_n + b_g,n + (N_g / sqrt(dt)) w_n                 (E2)
    acc_n    = f_B,n + b_a,n + (N_a / sqrt(dt)) w'_n                  (E3)
    b_.,n+1  = b_.,n + K_. sqrt(dt) w''_n,   b_.,0 = bias_0           (E4)
    t_sample = t_n                                                    the time the sample refers to

with ``R`` of eq. 8, ``N`` the white-noise density, ``K`` the bias random walk
and ``w`` standard normal numbers drawn by Box-Muller from numpy's
``default_rng(seed)`` (24 uniform numbers a step: gyro noise x y z, accel
noise x y z, gyro bias walk x y z, accel bias walk x y z; r1 first, as in
``sensors.py``). At n = 0 there is no previous step: the values of t_0 stand
for those of t_{-1} (at rest: ``f_B = R_0^T (-g e3)``).

Averaging K internal samples at K/dt Hz of white noise with density N gives
a standard deviation N sqrt(K/dt)/sqrt(K) = N/sqrt(dt) whatever K: a 1 kHz
internal rate read out at 100 Hz and a 100 Hz sensor are the same law here,
so the FMU draws one number per axis and step (docs/sensors.md). The true
biases are outputs too: the study's NEES needs them.

Units: a density N in rad/s/sqrt(Hz) is, number for number, the standard
deviation in rad/s of the noise averaged over 1 s; a random walk K in
rad/s/sqrt(s) the bias' standard deviation after 1 s. FMI units have whole
exponents, so the parameters carry these 1-s units (rad/s, m/s2) and the
data sheets' numbers unchanged.
"""
from __future__ import annotations

from fmu_models.lazy_casadi import ca

from ..export.model import FmuModel, Sampled
from ..export.variables import discrete, input_, output, parameter, seed_parameter
from .quadrotor import DEFAULTS, rotation_matrix
from .sensors import DT_DEFAULT, gaussian

__all__ = ["IMU", "specific_force", "AXES", "IMU_DEFAULTS"]

AXES = ("x", "y", "z")
# Datasheet values (docs/sensors.md): Bosch BMI088 gyro 0.014 deg/s/sqrt(Hz),
# accel 175 ug/sqrt(Hz) (the noisier of the parts we cite, so the estimator is
# not tuned on a best case); bias random walks from its bias instability.
IMU_DEFAULTS = {
    "gyro_noise_density": 2.4e-4,    # rad/s/sqrt(Hz): 0.014 deg/s/sqrt(Hz)
    "accel_noise_density": 1.7e-3,   # m/s2/sqrt(Hz): 175 ug/sqrt(Hz)
    "gyro_bias_walk": 2.0e-5,        # rad/s/sqrt(s)
    "accel_bias_walk": 3.0e-4,       # m/s2/sqrt(s)
}


def specific_force(a, R, g):
    """Specific force in the body frame (m/s^2), eq. E1: ``R^T (a - g e3)``;
    ``a`` the acceleration in the world frame (z down, eqs. 10-11), ``R`` body
    to world. At rest level it is ``(0, 0, -g)``: the accelerometer feels the
    support push up."""
    return R.T @ (a - ca.vertcat(0, 0, g))


_VARIABLES = (
    input_("u", "m/s", "velocity north (world frame, eq. 6)", 0.0),
    input_("v", "m/s", "velocity east (world frame, eq. 6)", 0.0),
    input_("w", "m/s", "velocity down (world frame, eq. 6)", 0.0),
    input_("phi", "rad", "roll angle (Z-Y-X Euler, eq. 8)", 0.0),
    input_("theta", "rad", "pitch angle (Z-Y-X Euler, eq. 8)", 0.0),
    input_("psi", "rad", "yaw angle (Z-Y-X Euler, eq. 8)", 0.0),
    input_("p", "rad/s", "body roll rate (eq. 2)", 0.0),
    input_("q", "rad/s", "body pitch rate (eq. 2)", 0.0),
    input_("r", "rad/s", "body yaw rate (eq. 2)", 0.0),
    *(output(f"gyro_{i}", "rad/s", f"measured angular rate about {i}_B (noise and bias, eq. E2)") for i in AXES),
    *(output(f"acc_{i}", "m/s2", f"measured specific force along {i}_B (noise and bias, eq. E3)") for i in AXES),
    *(output(f"gyro_bias_{i}", "rad/s", f"true gyro bias about {i}_B in this step's output (eq. E4)")
      for i in AXES),
    *(output(f"accel_bias_{i}", "m/s2", f"true accelerometer bias along {i}_B in this step's output (eq. E4)")
      for i in AXES),
    parameter("gyro_noise_density", "rad/s",
              "gyro white-noise density N_g (rad/s/sqrt(Hz)); per-step std N_g/sqrt(dt)",
              IMU_DEFAULTS["gyro_noise_density"], min=0.0),
    parameter("accel_noise_density", "m/s2",
              "accelerometer white-noise density N_a (m/s2/sqrt(Hz)); per-step std N_a/sqrt(dt)",
              IMU_DEFAULTS["accel_noise_density"], min=0.0),
    parameter("gyro_bias_walk", "rad/s",
              "gyro bias random walk K_g: the bias' std grows as K_g sqrt(t)", IMU_DEFAULTS["gyro_bias_walk"],
              min=0.0),
    parameter("accel_bias_walk", "m/s2",
              "accelerometer bias random walk K_a: the bias' std grows as K_a sqrt(t)",
              IMU_DEFAULTS["accel_bias_walk"], min=0.0),
    *(parameter(f"gyro_bias_0_{i}", "rad/s", f"gyro bias about {i}_B at t = 0 (left after calibration)", 0.0)
      for i in AXES),
    *(parameter(f"accel_bias_0_{i}", "m/s2", f"accelerometer bias along {i}_B at t = 0 (left after calibration)",
                0.0) for i in AXES),
    parameter("g", "m/s2", "gravitational acceleration (as the plant's)", DEFAULTS["g"], min=0.0),
    seed_parameter("seed", "seed of numpy's default_rng that draws the noise and the bias walks "
                           "(24 numbers per step)"),
    parameter("dt", "s", "communication step = output period of the IMU (every doStep must be dt)",
              DT_DEFAULT, min=1e-6, max=10.0),
    discrete("started", "1", "0 before the first step, 1 after (the previous values below exist)"),
    *(discrete(f"previous_{name}", unit, f"{name} at the previous step")
      for name, unit in (("u", "m/s"), ("v", "m/s"), ("w", "m/s"), ("phi", "rad"), ("theta", "rad"),
                         ("psi", "rad"), ("p", "rad/s"), ("q", "rad/s"), ("r", "rad/s"))),
    *(discrete(f"b_g_{i}", "rad/s", f"gyro bias about {i}_B") for i in AXES),
    *(discrete(f"b_a_{i}", "m/s2", f"accelerometer bias along {i}_B") for i in AXES),
    output("t_sample", "s", "time the sample refers to: the end of the step it averages over, the FMU's time "
                            "when it read the plant (an estimator fuses it at that time, docs/estimation.md)"),
)


_PREVIOUS = ("u", "v", "w", "phi", "theta", "psi", "p", "q", "r")


def _update(t, v, rs):
    w = [gaussian(rs[2 * k], rs[2 * k + 1]) for k in range(12)]
    sqrt_dt = ca.sqrt(v["dt"])
    # t_0 stands for t_{-1}: no step before the first
    before = {name: ca.if_else(v["started"] > 0, v[f"previous_{name}"], v[name]) for name in _PREVIOUS}
    velocity = ca.vertcat(v["u"], v["v"], v["w"])
    velocity_before = ca.vertcat(before["u"], before["v"], before["w"])
    R_mean = (rotation_matrix(before["phi"], before["theta"], before["psi"])
              + rotation_matrix(v["phi"], v["theta"], v["psi"])) / 2
    f_body = specific_force((velocity - velocity_before) / v["dt"], R_mean, v["g"])
    out, nxt = {"t_sample": t}, {"started": 1.0, **{f"previous_{name}": v[name] for name in _PREVIOUS}}
    for k, i in enumerate(AXES):
        rate = (before["pqr"[k]] + v["pqr"[k]]) / 2
        b_g, b_a = v[f"b_g_{i}"], v[f"b_a_{i}"]
        out[f"gyro_{i}"] = rate + b_g + v["gyro_noise_density"] / sqrt_dt * w[k]
        out[f"acc_{i}"] = f_body[k] + b_a + v["accel_noise_density"] / sqrt_dt * w[3 + k]
        out[f"gyro_bias_{i}"] = b_g
        out[f"accel_bias_{i}"] = b_a
        nxt[f"b_g_{i}"] = b_g + v["gyro_bias_walk"] * sqrt_dt * w[6 + k]
        nxt[f"b_a_{i}"] = b_a + v["accel_bias_walk"] * sqrt_dt * w[9 + k]
    return out, nxt


def _initial(v, r):
    return {"started": 0.0, **{f"previous_{name}": 0.0 for name in _PREVIOUS},
            **{f"b_g_{i}": v[f"gyro_bias_0_{i}"] for i in AXES}, **{f"b_a_{i}": v[f"accel_bias_0_{i}"] for i in AXES}}


IMU = FmuModel(
    identifier="IMU",
    description="inertial measurement unit (body frame): gyroscope and accelerometer averaged over each "
                "communication step (specific force from the plant's velocity change and attitude) with white "
                "noise and bias random walk; seeded; z axis down",
    variables=_VARIABLES,
    sampled=Sampled(update=_update, initial=_initial, n_random=0, seed="seed", sample_period="dt",
                    n_random_step=24),
)
