"""A state estimator as a sampled-data FMU: an extended Kalman filter written
in CasADi that predicts with the IMU and corrects with the drag-model
accelerometer and with GNSS or motion capture, each measurement gated and
fused at the time it was taken (docs/estimation.md, eqs. E5-E14 and E19-E28;
the numbers below are those equations').

State (18): position ``x y z`` and velocity ``u v w`` (world frame, z down,
eq. 6), attitude ``phi theta psi`` (Z-Y-X Euler, eq. 8), gyro bias
``b_g``, accelerometer bias ``b_a`` (body frame) and the wind ``w_W`` (world
frame). The discrete state is the posterior at ``t_filter``, the time of the
last IMU sample used (a delayed horizon, as PX4's EKF2). At the FMU's time t,
with the IMU's ``gyro, acc`` stamped ``t_imu`` and the fix ``y`` stamped
``t_fix`` (fresh or not) as inputs:

1. a new IMU sample (``t_imu > t_filter + dt/2``) predicts the posterior to
   ``t_imu`` (E7-E8, explicit Euler; covariance E13; E22) and is corrected
   with the accelerometer's two horizontal body axes, the drag model's
   measurement (E9): ``acc_xy = [R^T D(v - w_W) / m]_xy + b_a,xy``;
2. a fresh fix newer than the last is compared with the state retrodicted
   over its age ``tau = t_filter - t_fix`` (E10, E20);
3. both corrections are sequential scalar updates (E11-E12), the Jacobians
   from CasADi's AD, kept only when their NIS passes the chi-square gate of
   ``gate_level`` (E19); refusals are counted, and a run of them restarts
   that measurement's part of the state (E21);
4. the outputs are the posterior predicted from ``t_filter`` to t (the
   output predictor, E23), the body rates brought forward by the torques of
   the rotor command ``Omega_1..4`` received a step before, the one that
   acted over that span (E26; unconnected: the IMU's averages extrapolated
   along their trend): the state named like the plant's outputs
   (``x .. psi``), the body rates, the wind, the biases, the covariance (variances of all 18,
   covariances within the position, velocity, attitude and wind blocks),
   the NIS of both corrections, the time they describe (``t_estimate``) and
   the gate's counts.

``EstimatorGM`` is the same filter with the fix's position error correlated
in time as three more states (E27: a first-order Gauss-Markov process, the
receiver ``GNSS6GM``'s E25), in the fix's measurement and its restart.
``EstimatorMocap`` is the same filter also fed the motion capture's
attitude with the fix of the same frame (E29: gated, counted, restarted
after a run of refusals), with the attitude integrated to second order
(E30) and the extrapolated rate's noise in its output predictor (E31).

In our master's feedthrough ordering ``t_imu = t`` and the output is the
posterior: the controller reading the estimate at t_n flies on the
measurements of t_n. In a Jacobi importer the samples arrive a step old,
say so by their stamps, and the output is brought forward to t_n.
"""
from __future__ import annotations

from functools import partial

from fmu_models.lazy_casadi import ca

from ..export import staged
from ..export.model import FmuModel, Sampled
from ..export.variables import discrete, input_, output, parameter
from .estimator_outputs import (ATTITUDE_FIX_COUNTS, ATTITUDE_FIX_MODEL, COUNTS, COVARIANCE_BLOCKS, MAGNETOMETER_COUNTS,
                                MAGNETOMETER_MODEL, covariance_output)
from .imu import AXES, IMU_DEFAULTS
from .magnetometer import MAGNETOMETER_DEFAULTS, body_field, heading_from_field
from .quadrotor import (DEFAULTS, QUADROTOR, aerodynamic_drag, body_angular_acceleration, euler_rate_matrix,
                        rotation_matrix, rotor_clip)
from .rotor import thrust_and_torques
from .sensors import DT_DEFAULT

__all__ = ["ESTIMATOR", "ESTIMATOR_MAG", "ESTIMATOR_GM", "ESTIMATOR_MOCAP", "ESTIMATED_STATES", "ANGLES",
           "FIX_BIAS_STATES", "FIX_NAMES",
           "ESTIMATOR_DEFAULTS", "process_model", "drag_measurement",
           "chi2_quantile_even", "chi2_quantile_odd", "magnetometer_measurement", "attitude_fix_measurement",
           "body_drag_acceleration", "scalar_update", "covariance_names", "COVARIANCE_BLOCKS"]

# The filter's state, in order: the 9 plant states it estimates, then the biases and the wind.
ESTIMATED_STATES = ("x", "y", "z", "u", "v", "w", "phi", "theta", "psi",
                    "gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "accel_bias_x", "accel_bias_y", "accel_bias_z",
                    "wind_x", "wind_y", "wind_z")
_N = len(ESTIMATED_STATES)
_UNITS = ("m",) * 3 + ("m/s",) * 3 + ("rad",) * 3 + ("rad/s",) * 3 + ("m/s2",) * 3 + ("m/s",) * 3
# EstimatorGM's three more states (E27): the fix's position error correlated in time (first-order
# Gauss-Markov, the receiver's E25), appended so that the 18 above keep their indices
FIX_BIAS_STATES = ("fix_bias_x", "fix_bias_y", "fix_bias_z")
_ALL_STATES = ESTIMATED_STATES + FIX_BIAS_STATES
_WIND = (15, 16, 17)  # the wind's indices in the state
FIX_NAMES = ("x", "y", "z", "u", "v", "w")  # the fix: position and velocity (GNSS or motion capture)
# Tuning (docs/estimation.md, "Tuning"); the sensor values are the IMU's defaults.
ESTIMATOR_DEFAULTS = {
    "wind_walk": 1.0,             # m/s/sqrt(s): the horizontal wind's random walk between gusts (steps restart it, E21)
    "wind_walk_z": 0.01,          # m/s/sqrt(s): the vertical wind's, nearly constant (hardly observable, E9)
    "drag_noise_density": 0.005,  # m/s2/sqrt(Hz): error of the drag model in the prediction
    "sigma_drag": 0.005,          # m/s2: error of the drag model in the accelerometer measurement
    "P0_position": 1.0, "P0_velocity": 0.2, "P0_attitude": 0.05,
    "P0_gyro_bias": 0.005, "P0_accel_bias": 0.01, "P0_wind": 3.0, "P0_wind_z": 0.1,
    "gate_level": 0.9999,         # chi-square gate: one good measurement in 10^4 refused (E19)
    "reset_after_fix": 5.0,       # fixes refused in a row before position and velocity restart (E21)
    "reset_after_drag": 1.0,      # drag measurements refused in a row before the wind restarts (E21)
    "sigma_mag": 1.0e-6,          # T: the magnetometer's noise (BMM150, 0.6 uT) and its calibration's residual (E24)
    "sigma_attitude_fix": 1.0e-3,  # rad: the motion capture's angles (E29; the lab's, OptiTrack's: docs/sensors.md)
}
_IMU = tuple(f"gyro_{i}" for i in AXES) + tuple(f"acc_{i}" for i in AXES)
_ROTORS = (1, 2, 3, 4)
_P0 = {"x": "P0_position", "u": "P0_velocity", "phi": "P0_attitude", "gyro_bias_x": "P0_gyro_bias",
       "accel_bias_x": "P0_accel_bias", "wind_x": "P0_wind"}


def covariance_names(fix_bias: bool = False) -> list[tuple[str, int, int]]:
    """``(output name, i, j)`` of the covariance outputs: ``var_<s>`` for every
    state, ``cov_<a>_<b>`` (a before b) within each block of COVARIANCE_BLOCKS;
    with ``fix_bias`` (EstimatorGM, E27) then ``var_fix_bias_*`` and the
    covariances ``cov_<p>_fix_bias_<p>`` of each position axis with its fix error."""
    index = {s: k for k, s in enumerate(ESTIMATED_STATES)}
    names = [(f"var_{s}", k, k) for k, s in enumerate(ESTIMATED_STATES)]
    for block in COVARIANCE_BLOCKS.values():
        names += [(covariance_output(a, b, block), index[a], index[b]) for k, a in enumerate(block)
                  for b in block[k + 1:]]
    if fix_bias:
        names += [(f"var_{s}", _N + k, _N + k) for k, s in enumerate(FIX_BIAS_STATES)]
        names += [(f"cov_{a}_{s}", k, _N + k) for k, (a, s) in enumerate(zip("xyz", FIX_BIAS_STATES))]
    return names


def _upper(i, j):
    i, j = min(i, j), max(i, j)
    return f"P_{_ALL_STATES[i]}__{_ALL_STATES[j]}"


def _split(xs):
    return xs[0:3], xs[3:6], xs[6:9], xs[9:12], xs[12:15], xs[15:18]


def body_drag_acceleration(xs, m, k_drag_lin, k_drag_quad):
    """Drag acceleration in the body frame (m/s^2), eq. E6: ``R^T D(v - w_W) / m``."""
    _, velocity, attitude, _, _, wind = _split(xs)
    R = rotation_matrix(attitude[0], attitude[1], attitude[2])
    return R.T @ aerodynamic_drag(velocity - wind, k_drag_lin, k_drag_quad) / m


def process_model(xs, gyro, acc, noise, v):
    """Time derivative of the state, eqs. E7-E8: the IMU's rates less the gyro
    bias drive the attitude (eq. 3), the specific force (drag model on the
    horizontal body axes, accelerometer less its bias on z_B) drives the
    velocity (eqs. 9-11). ``noise`` (15): gyro, accel z, drag x y, the two
    bias walks and the wind walk, white with the densities of E13. With the
    fix's correlated error (21 states, 18 noises; EstimatorGM) also E27:
    ``b_p' = -b_p / gm_tau + n_b``."""
    _, velocity, attitude, b_g, b_a, _ = _split(xs)
    drag = body_drag_acceleration(xs, v["m"], v["k_drag_lin"], v["k_drag_quad"])
    rates = gyro - b_g - noise[0:3]
    force = ca.vertcat(drag[0] + noise[4], drag[1] + noise[5], acc[2] - b_a[2] - noise[3])
    R = rotation_matrix(attitude[0], attitude[1], attitude[2])
    derivative = [velocity, R @ force + ca.vertcat(0, 0, v["g"]),
                  euler_rate_matrix(attitude[0], attitude[1]) @ rates,
                  noise[6:9], noise[9:12], noise[12:15]]
    if xs.shape[0] > _N:  # E27: the fix's position error, a first-order Gauss-Markov process (the receiver's E25)
        derivative.append(-xs[_N:_N + 3] / v["gm_tau"] + noise[15:18])
    return ca.vertcat(*derivative)


def drag_measurement(xs, v):
    """The accelerometer's horizontal body axes predicted from the state, eq. E9."""
    drag = body_drag_acceleration(xs, v["m"], v["k_drag_lin"], v["k_drag_quad"])
    return ca.vertcat(drag[0] + xs[12], drag[1] + xs[13])


def scalar_update(xs, P, h, H, measured, variance):
    """One scalar EKF correction, eqs. E11-E12: innovation ``nu = y - h``,
    ``s = H P H^T + r``, gain ``K = P H^T / s``; returns the corrected state,
    covariance and the NIS term ``nu^2 / s``. ``P H^T`` and ``s`` where ``H``
    is (sparse, each channel its own), the rest one function every channel
    calls (:func:`_corrected`, :func:`_called`)."""
    PH = P @ H.T
    s = (H @ PH)[0, 0] + variance
    return _called(_corrected, "ekf_correct", (xs, P, PH, s, measured - h), covariance=1)


def _corrected(xs, P, PH, s, nu):
    """The scalar correction of :func:`scalar_update` from ``PH = P H^T``,
    ``s`` and the innovation ``nu`` (E11-E12): ``K = PH / s``, the state
    ``xs + K nu``, the covariance ``P - K PH^T`` made symmetric, the NIS term."""
    K = PH / s
    P_next = P - K @ PH.T
    return xs + K * nu, (P_next + P_next.T) / 2, nu * nu / s


def _sequential(xs, P, measure, measured, variances):
    """Scalar updates one channel after another; each channel's Jacobian at the
    state corrected by the channels before it (E11)."""
    xs_sym = ca.SX.sym("xs", xs.shape[0])
    predicted = measure(xs_sym)
    nis = 0
    for k in range(measured.shape[0]):
        h, H = ca.substitute([predicted[k], ca.jacobian(predicted[k], xs_sym)], [xs_sym], [xs])
        xs, P, term = scalar_update(xs, P, h, H, measured[k], variances[k])
        nis = nis + term
    return xs, P, nis


def _variables(magnetometer: bool, fix_bias: bool = False, attitude_fix: bool = False):
    variables = [
        *(input_(f"gyro_{i}", "rad/s", f"IMU angular rate about {i}_B", 0.0) for i in AXES),
        input_("acc_x", "m/s2", "IMU specific force along x_B", 0.0),
        input_("acc_y", "m/s2", "IMU specific force along y_B", 0.0),
        input_("acc_z", "m/s2", "IMU specific force along z_B (-g level at rest, z down)", -DEFAULTS["g"]),
        *(input_(f"{name}_m", unit, f"fix (GNSS or motion capture): {name}", 0.0)
          for name, unit in zip(FIX_NAMES, _UNITS)),
        input_("fresh", "1", "1 when the fix is new this step (then the filter corrects with it), 0 otherwise; "
                             "left at 1, every step's fix is used", 1.0),
        input_("t_imu", "s", "time the IMU's sample refers to (the IMU's t_sample): the filter predicts to it "
                             "(E22); negative (its start, unconnected): every sample is taken as current", -1.0),
        input_("t_fix", "s", "time the fix was taken (the receiver's t_sample): the filter fuses it at that "
                             "time (E20), and only when it is later than the last fix's; negative (its start, "
                             "unconnected): every fresh fix is taken as current", -1.0),
        *(output(name, unit, f"estimate of {name}") for name, unit in zip(ESTIMATED_STATES[:9], _UNITS)),
        *(output(name, "rad/s", f"body rate {name}: IMU rate less the estimated gyro bias")
          for name in ("p", "q", "r")),
        *(output(name, unit, f"estimate of {name}") for name, unit in zip(ESTIMATED_STATES[9:], _UNITS[9:])),
        *(output(name, "1", f"posterior covariance entry ({ESTIMATED_STATES[i]}, {ESTIMATED_STATES[j]}), "
                            "in the states' units squared")
          for name, i, j in covariance_names()),
        output("nis_fix", "1", "normalized innovation squared of this step's fix (6 degrees of freedom; "
                               "0 without a fresh fix)"),
        output("fix_used", "1", "1 when this step corrected with the fix (fresh), else 0"),
        output("nis_acc", "1", "normalized innovation squared of the accelerometer's drag measurement "
                               "(2 degrees of freedom; 0 without a new IMU sample)"),
        output("t_estimate", "s", "time the outputs describe: the FMU's time (E23)"),
        output("t_filter", "s", "time of the filter's posterior: the last IMU sample's (E22)"),
        output("fix_age", "s", "tau: how far before t_filter this step's fix was taken (E20; 0 without one)"),
        output("outliers_fix", "1", "fixes refused by the gate since the start (E19)"),
        output("outliers_acc", "1", "drag measurements refused by the gate since the start (E19)"),
        output("resets_fix", "1", "restarts of position and velocity from the fix after reset_after refusals "
                                  "in a row (E21)"),
        output("resets_acc", "1", "restarts of the wind's covariance after reset_after refused drag "
                                  "measurements in a row (E21)"),
        parameter("m", "kg", "vehicle mass of the drag model (the plant's)", DEFAULTS["m"], min=1e-3),
        parameter("g", "m/s2", "gravitational acceleration", DEFAULTS["g"], min=0.0),
        parameter("k_drag_lin", "N.s/m", "linear drag coefficient of the model (the plant's)",
                  DEFAULTS["k_drag_lin"], min=0.0),
        parameter("k_drag_quad", "N.s2/m2", "quadratic drag coefficient of the model (the plant's)",
                  DEFAULTS["k_drag_quad"], min=0.0),
        *(parameter(name, unit, f"IMU {name.replace('_', ' ')} the filter assumes (E13)", IMU_DEFAULTS[name],
                    min=0.0)
          for name, unit in (("gyro_noise_density", "rad/s"), ("accel_noise_density", "m/s2"),
                             ("gyro_bias_walk", "rad/s"), ("accel_bias_walk", "m/s2"))),
        parameter("wind_walk", "m/s", "random walk of the wind model (E13)",
                  ESTIMATOR_DEFAULTS["wind_walk"], min=0.0),
        parameter("wind_walk_z", "m/s", "random walk of the vertical wind (E13): the drag measurement sees "
                  "it only through the tilt", ESTIMATOR_DEFAULTS["wind_walk_z"], min=0.0),
        parameter("drag_noise_density", "m/s2", "white error density of the drag model in the "
                  "prediction (E13)", ESTIMATOR_DEFAULTS["drag_noise_density"], min=0.0),
        parameter("sigma_drag", "m/s2", "error of the drag model in the accelerometer measurement (E9)",
                  ESTIMATOR_DEFAULTS["sigma_drag"], min=0.0),
        *(parameter(f"sigma_{name}_m", unit, f"standard deviation of the fix's {name} (E10)", 1.0, min=1e-9)
          for name, unit in zip(FIX_NAMES, _UNITS)),
        parameter("gate_level", "1", "level of the chi-square innovation gate: a measurement whose NIS is above "
                  "the chi-square quantile of this level (its degrees of freedom) is refused (E19)",
                  ESTIMATOR_DEFAULTS["gate_level"], min=0.5, max=1.0 - 1e-12),
        parameter("reset_after_fix", "1", "fixes refused in a row after which position and velocity start "
                  "again from the fix (E21)", ESTIMATOR_DEFAULTS["reset_after_fix"], min=1.0, max=1.0e6,
                  integer=True),
        parameter("reset_after_drag", "1", "drag measurements refused in a row after which the wind starts "
                  "again from its initial uncertainty and the measurement is fused (E21): 1, a gust's step "
                  "is found by its first measurement", ESTIMATOR_DEFAULTS["reset_after_drag"], min=1.0,
                  max=1.0e6, integer=True),
        *(parameter(f"{name}_0", unit, f"initial estimate of {name}", 0.0)
          for name, unit in zip(ESTIMATED_STATES, _UNITS)),
        *(parameter(p0, unit, f"initial standard deviation of the {p0[3:].replace('_', ' ')} estimate (each axis)",
                    ESTIMATOR_DEFAULTS[p0], min=1e-9)
          for p0, unit in (("P0_position", "m"), ("P0_velocity", "m/s"), ("P0_attitude", "rad"),
                           ("P0_gyro_bias", "rad/s"), ("P0_accel_bias", "m/s2"), ("P0_wind", "m/s"))),
        # 0 with wind_walk_z = 0: no vertical wind state, the vertical wind held at wind_z_0 (its variance stays 0)
        parameter("P0_wind_z", "m/s", "initial standard deviation of the vertical wind estimate; 0 (with "
                  "wind_walk_z = 0): the filter has no vertical wind state, it holds wind_z_0",
                  ESTIMATOR_DEFAULTS["P0_wind_z"], min=0.0),
        parameter("dt", "s", "communication step = sample period of the filter (every doStep must be dt)",
                  DT_DEFAULT, min=1e-6, max=10.0),
        discrete("started", "1", "0 before the first step (the initial estimate is the first prior), 1 after"),
        discrete("t_posterior", "s", "time of the posterior below: the last IMU sample's"),
        discrete("t_last_fix", "s", "time of the last fix seen (used or refused)"),
        discrete("refusal_run_fix", "1", "fixes refused in a row"),
        discrete("refusal_run_acc", "1", "drag measurements refused in a row"),
        *(discrete(f"total_{c}", "1", f"{c.replace('_', ' of the ')} so far") for c in COUNTS),
        *(discrete(f"previous_{name}", unit, f"the IMU's {name} of the sample before the last")
          for name, unit in zip(_IMU, ("rad/s",) * 3 + ("m/s2",) * 3)),
        *(discrete(f"xhat_{name}", unit, f"posterior estimate of {name} at the previous step")
          for name, unit in zip(ESTIMATED_STATES, _UNITS)),
        *(discrete(_upper(i, j), "1", "posterior covariance entry at the previous step")
          for i in range(_N) for j in range(i, _N)),
    ]
    if magnetometer:  # the magnetometer (E24), appended so that the variables above keep their value references
        variables += [
        *(input_(f"mag_{i}", "T", f"magnetometer's field along {i}_B (sampled with the IMU)", 0.0) for i in AXES),
        input_("fresh_mag", "1", "1 when the magnetometer's sample is to be fused (with each new IMU sample); "
                                 "0 (its start, unconnected): no magnetometer", 0.0),
        *(parameter(f"field_{d}", "T", f"the site's Earth field the filter assumes, {d} component (NED, E24)",
                    MAGNETOMETER_DEFAULTS[f"field_{d}"]) for d in ("north", "east", "down")),
        parameter("sigma_mag", "T", "standard deviation of the magnetometer's error per axis the filter assumes: "
                  "noise and the calibration's residual offset (E24)", ESTIMATOR_DEFAULTS["sigma_mag"], min=1e-12),
        output("nis_mag", "1", "normalized innovation squared of the magnetometer (3 degrees of freedom; 0 without "
                               "a sample fused this step)"),
        output("outliers_mag", "1", "magnetometer samples refused by the gate since the start (E19)"),
        discrete("total_outliers_mag", "1", "outliers of the magnetometer so far"),
        ]
    # the rotor speeds commanded (E26), appended last so that the variables above keep their value references
    variables += [
        *(input_(f"Omega_{i}", "rad/s", f"rotor {i}'s speed commanded (the controller's output): the output "
                 "predictor brings the body rates forward by the torques it makes (E26); negative (its start, "
                 "unconnected): along the IMU's trend instead", -1.0) for i in _ROTORS),
        *(parameter(name, unit, f"{what} of the vehicle the output predictor's rotor model assumes (the plant's, "
                    "E26)", DEFAULTS[name], min=1e-12)
          for name, unit, what in (("l", "m", "arm length"), ("b", "N.s2", "rotor thrust coefficient"),
                                   ("d", "N.m.s2", "rotor drag-torque coefficient"),
                                   ("Ix", "kg.m2", "moment of inertia about x_B"),
                                   ("Iy", "kg.m2", "moment of inertia about y_B"),
                                   ("Iz", "kg.m2", "moment of inertia about z_B"),
                                   ("Omega_max", "rad/s", "maximum rotor speed"))),
        *(discrete(f"command_{i}", "rad/s", f"rotor {i}'s command received at the step before (E26)")
          for i in _ROTORS),
    ]
    if fix_bias:  # the fix's correlated error (E27), appended last so that the variables above keep their references
        variables += [
            *(output(name, "m", f"estimate of the fix's correlated position error along {a} (E27)")
              for a, name in zip("xyz", FIX_BIAS_STATES)),
            *(output(name, "1", f"posterior covariance entry ({_ALL_STATES[i]}, {_ALL_STATES[j]}), in the states' "
                                "units squared")
              for name, i, j in covariance_names(fix_bias=True)[len(covariance_names()):]),
            parameter("gm_tau", "s", "correlation time of the fix's position error the filter assumes (the "
                      "receiver's, E25, E27)", 60.0, min=1e-6),
            *(parameter(f"gm_sigma_{a}_m", "m", f"stationary standard deviation of the fix's correlated error "
                        f"along {a} the filter assumes (the receiver's gm_sigma_{a}, E27); its white part is "
                        f"sigma_{a}_m", 0.0, min=0.0) for a in "xyz"),
            *(discrete(f"xhat_{name}", "m", f"posterior estimate of {name} at the previous step")
              for name in FIX_BIAS_STATES),
            *(discrete(_upper(i, j), "1", "posterior covariance entry at the previous step")
              for j in range(_N, _N + 3) for i in range(j + 1)),
        ]
    if magnetometer:  # the offset and the first heading (E28), last so that the variables above keep their references
        variables += [
        *(parameter(f"mag_bias_{i}", "T", f"hard-iron offset along {i}_B the magnetometer's calibration found: "
                    "subtracted from each sample (its residual belongs in sigma_mag)", 0.0) for i in AXES),
        parameter("heading_from_mag", "1", "1: the heading starts from the first magnetometer sample the gate "
                  "accepts at that heading (E28, psi_0 then unused); 0: from psi_0", 1.0, min=0.0, max=1.0,
                  integer=True),
        discrete("heading_set", "1", "1 once a magnetometer sample has set the heading (E28)"),
        ]
    if attitude_fix:  # the motion capture's attitude (E29), last so that the variables above keep their references
        variables += [
            *(input_(f"{a}_m", "rad", f"the motion capture's {a} (its rigid body's attitude), taken with the fix: "
                     "fused when the fix is fresh, at its time t_fix (E29)", 0.0) for a in ANGLES),
            *(parameter(f"sigma_{a}_m", "rad", f"standard deviation of the motion capture's {a} (E29)",
                        ESTIMATOR_DEFAULTS["sigma_attitude_fix"], min=1e-9) for a in ANGLES),
            parameter("reset_after_attitude", "1", "motion-capture attitudes refused in a row after which the "
                      "attitude starts again from the frame (E21, E29)", ESTIMATOR_DEFAULTS["reset_after_fix"],
                      min=1.0, max=1.0e6, integer=True),
            output("nis_attitude", "1", "normalized innovation squared of the motion capture's attitude (3 degrees of "
                                        "freedom; 0 without a fresh frame)"),
            output("outliers_attitude", "1", "motion-capture attitudes refused by the gate since the start (E19)"),
            output("resets_attitude", "1", "restarts of the attitude from the motion capture after "
                                           "reset_after_attitude refusals in a row (E21)"),
            discrete("refusal_run_attitude", "1", "motion-capture attitudes refused in a row"),
            *(discrete(f"total_{c}", "1", f"{c.replace('_', ' of the ')} so far") for c in ATTITUDE_FIX_COUNTS),
        ]
    # the airframe of the output predictor's rotor model (E26), last so that the variables above keep their references
    arm = QUADROTOR.variable("arm_angle")
    variables.append(parameter("arm_angle", arm.unit, "angle of rotor 1's arm from x_B the output predictor's rotor "
                               "model assumes (the plant's: 0 plus, pi/4 X; E26)", arm.start, min=arm.min,
                               max=arm.max))
    return tuple(variables)


def _state(v, n: int = _N):
    """The posterior of the first ``n`` states of ``_ALL_STATES`` from the discrete variables."""
    xs = ca.vertcat(*(v[f"xhat_{name}"] for name in _ALL_STATES[:n]))
    P = ca.SX(n, n)
    for i in range(n):
        for j in range(n):
            P[i, j] = v[_upper(i, j)]
    return xs, P


def _discrete(xs, P):
    n = xs.shape[0]
    z = {f"xhat_{name}": xs[k] for k, name in enumerate(_ALL_STATES[:n])}
    z.update({_upper(i, j): P[i, j] for i in range(n) for j in range(i, n)})
    return z


def chi2_quantile_even(k: int, level, iterations: int = 40):
    """The ``level`` quantile of the chi-square distribution with an even
    number ``k`` of degrees of freedom (the gate of E19), by Newton's method
    on its log survival function, closed form for even k::

        S(x) = exp(-x/2) sum_{i < k/2} (x/2)^i / i!,   S(x_gate) = 1 - level

    ``log S`` is concave (the chi-square density is log-concave for k >= 2),
    so from any start Newton's iterates reach the root from above after the
    first step and decrease to it monotonically; 40 steps reach round-off
    for levels up to 1 - 1e-12. Numbers or CasADi expressions (the FMU's law)."""
    m = k // 2
    if m < 1 or 2 * m != k:
        raise ValueError(f"chi2_quantile_even: k = {k} is not an even positive integer")
    target = ca.log(1.0 - level)
    x = 0 * level + float(k)  # a number or an expression, as the level
    for _ in range(iterations):
        terms, term = 1.0, 1.0
        for i in range(1, m):
            term = term * (x / 2) / i
            terms = terms + term
        log_survival = -x / 2 + ca.log(terms)
        slope = -term / (2 * terms)  # d log S / dx = -density / S, the last term being (x/2)^(m-1) / (m-1)!
        x = ca.fmax(x - (log_survival - target) / slope, 1e-9)
    return x


def chi2_quantile_odd(k: int, level, iterations: int = 40):
    """The ``level`` quantile of the chi-square distribution with an odd number
    ``k >= 3`` of degrees of freedom (the magnetometer's gate, E19), by
    Newton's method on its log survival function, closed form for odd k::

        S(x) = erfc(sqrt(x/2)) + exp(-x/2) sum_{1 <= i <= (k-1)/2} (x/2)^(i-1/2) / Gamma(i+1/2)

    (k = 3: ``erfc(sqrt(x/2)) + sqrt(2x/pi) exp(-x/2)``). The density is
    log-concave for k >= 2, so, as in :func:`chi2_quantile_even`, the
    iterates reach the root from above after the first step; ``erfc`` is
    ``1 - erf`` (CasADi has no erfc), exact to 1e-12 relative for levels up
    to 1 - 1e-6. Numbers or CasADi expressions."""
    m = (k - 1) // 2
    if m < 1 or 2 * m + 1 != k:
        raise ValueError(f"chi2_quantile_odd: k = {k} is not an odd integer >= 3")
    target = ca.log(1.0 - level)
    x = 0 * level + float(k)
    for _ in range(iterations):
        term = ca.sqrt(x / 2) / ca.sqrt(ca.pi) * 2  # (x/2)^(1/2) / Gamma(3/2)
        terms = term
        for i in range(1, m):
            term = term * (x / 2) / (i + 0.5)
            terms = terms + term
        survival = 1.0 - ca.erf(ca.sqrt(x / 2)) + ca.exp(-x / 2) * terms
        slope = -ca.exp(-x / 2) * term / 2 / survival  # d log S / dx = -density / S, density = e^(-x/2) term_m / 2
        x = ca.fmax(x - (ca.log(survival) - target) / slope, 1e-9)
    return x


ANGLES = ESTIMATED_STATES[6:9]  # the attitude's states: phi, theta, psi (indices 6, 7, 8)


def attitude_fix_measurement(xs, gyro, tau):
    """The motion capture's Euler angles predicted from the state, eq. E29:
    the state's attitude retrodicted over the frame's age ``tau`` (its
    ``t_fix``, E20) with the IMU's rate less the gyro bias through eq. 3,
    ``o - tau T(o) (gyro - b_g)``."""
    return xs[6:9] - tau * euler_rate_matrix(xs[6], xs[7]) @ (gyro - xs[9:12])


def _attitude_fix(xs, P, v, gyro, tau, new_fix, level):
    """The motion capture's attitude fused (E29) by three sequential scalar
    updates (E11-E12), gated by its chi-square test with 3 degrees of
    freedom (E19) and restarted from it after ``reset_after_attitude``
    refusals in a row (E21). Returns the state and covariance, whether it was
    refused, whether it restarted, the run of refusals and the NIS."""
    def measure(s):
        return attitude_fix_measurement(s, gyro, tau)

    predicted = measure(xs)
    raw = ca.vertcat(*(v[f"{a}_m"] for a in ANGLES))
    # each measured angle taken within pi of its prediction: a heading near +-pi is one angle, not two
    measured = predicted + ca.atan2(ca.sin(raw - predicted), ca.cos(raw - predicted))
    variances = [v[f"sigma_{a}_m"] ** 2 for a in ANGLES]
    corrected = _sequential(xs, P, measure, measured, variances)
    nis = corrected[2]
    refused = ca.logic_and(new_fix, nis > chi2_quantile_odd(3, level))
    xs, P, refused = _gated(ca.logic_and(new_fix, ca.logic_not(refused)), corrected[:2], (xs, P), refused)
    run = ca.if_else(new_fix, ca.if_else(refused, v["refusal_run_attitude"] + 1, 0.0), v["refusal_run_attitude"])
    reset = run >= v["reset_after_attitude"]
    # the attitude starts again from the frame brought forward over tau, at its noise, uncorrelated with the rest
    restart = ca.vertcat(xs[0:6], measured + tau * euler_rate_matrix(xs[6], xs[7]) @ (gyro - xs[9:12]), xs[9:])
    xs = ca.if_else(reset, restart, xs)
    xs, P = _cut(xs, ca.if_else(reset, _reset(P, range(6, 9), variances), P))
    return (xs, P), refused, reset, ca.if_else(reset, 0.0, run), nis


def magnetometer_measurement(xs, v):
    """The magnetometer predicted from the state, eq. E24 less its noise: the
    site's field rotated into the body frame by the estimated attitude."""
    return body_field(xs[6:9], ca.vertcat(v["field_north"], v["field_east"], v["field_down"]))


class _Recorded(dict):
    """The variables a law reads by name, each a fresh symbol at its first read, in the order read."""

    def __missing__(self, name):
        self[name] = ca.SX.sym(name)
        return self[name]


_CALLED: dict[tuple, tuple] = {}  # (law, shapes, options) -> (its Function, the names it reads from v)


def _triangle(n: int) -> list[tuple[int, int]]:
    """The entries ``(i, j)``, ``i <= j``, of an n x n matrix's upper triangle, column by column."""
    return [(i, j) for j in range(n) for i in range(j + 1)]


def _packed(P):
    """A symmetric matrix as the column of its upper triangle (:func:`_triangle`),
    taken by linear (column-major) index in one call: element by element, the
    packing and unpacking of the EKFs' covariances took ~1 CPU-s of a first build."""
    n = P.shape[0]
    return P[[i + j * n for i, j in _triangle(n)]]


def _unpacked(packed, n: int):
    """The symmetric n x n matrix of :func:`_packed`: ``(i, j)`` and ``(j, i)`` one expression."""
    position = {entry: k for k, entry in enumerate(_triangle(n))}
    return ca.reshape(packed[[position[min(i, j), max(i, j)] for j in range(n) for i in range(n)]], n, n)


def _called(law, name: str, args: tuple, v=None, covariance: int | None = None, **options):
    """``law(*args, v, **options)`` as one CasADi function the step calls
    (:func:`fmu_models.export.staged.call`) rather than its expression graph
    inlined at every use: the generated C holds the law's code once, a
    function the step calls at each use, where the inlined step was one
    straight-line function of 30 000-40 000 lines that gcc compiled in
    8-14 CPU-s (docs/estimation.md, "The generated C"); inline while the
    step's structure is read (:func:`fmu_models.export.staged.inlined`). The law is built
    once per shape of its arguments and ``options``, on symbols; ``v`` (the
    model's variables by name) becomes the inputs it reads. ``covariance``:
    the position of the covariance among the arguments and among the
    results; it crosses the call as its upper triangle (:func:`_packed`:
    every covariance here is symmetric bit for bit, each entry made
    ``(A_ij + A_ji) / 2`` and IEEE addition commutes), half the values to
    copy, and the law's lower triangle, which only repeats the upper, is
    never computed. The numbers are those of the law inlined, bit for bit:
    the same operations in the same order."""
    if staged.inlining():  # the step's structure read (fmu_models.export.staged.inlined): the law inline
        return tuple(law(*args, **({} if v is None else {"v": v}), **options))
    args = [ca.densify(ca.SX(a)) for a in args]
    n = None
    if covariance is not None:
        n = args[covariance].shape[0]
        args[covariance] = _packed(args[covariance])
    key = (law, tuple(a.shape for a in args), covariance, tuple(sorted(options.items())))
    if key not in _CALLED:
        symbols = [ca.SX.sym(f"a{k}", *a.shape) for k, a in enumerate(args)]
        inputs = list(symbols)
        if covariance is not None:
            inputs[covariance] = _unpacked(symbols[covariance], n)
        read = _Recorded()
        results = list(law(*inputs, **({} if v is None else {"v": read}), **options))
        if covariance is not None:
            results[covariance] = _packed(results[covariance])
        _CALLED[key] = (ca.Function(name, symbols + list(read.values()), results, {"never_inline": True}),
                        tuple(read))
    function, names = _CALLED[key]
    results = staged.call(function, [*args, *(v[name] for name in names)])
    if covariance is not None:
        results[covariance] = _unpacked(results[covariance], n)
    return tuple(results)


def _predict(xs, P, gyro, acc, v, h, second_order: bool = False, rate_noise=None):
    """The state and covariance ``h`` seconds later (:func:`_predicted`),
    one function called by the filter's prediction and its output predictor
    (:func:`_called`); ``rate_noise``, when given, an argument of it."""
    if rate_noise is None:
        return _called(_predicted, "ekf_predict", (xs, P, gyro, acc, h), v, covariance=1, second_order=second_order)
    return _called(_predicted, "ekf_predict", (xs, P, gyro, acc, h, rate_noise), v, covariance=1,
                   second_order=second_order)


def _predicted(xs, P, gyro, acc, h, rate_noise=None, v=None, second_order: bool = False):
    """The state and covariance ``h`` seconds later with the IMU's averages
    held (E7-E8, E13): explicit Euler over h (the position with its
    ``h^2/2 dv/dt``), the covariance by F and G linearized at the estimate,
    noise-free. ``h = 0`` leaves both unchanged. ``second_order``: the
    attitude with its ``h^2/2`` term too (E30); ``rate_noise``: the gyro's
    white density times this factor (E31: a rate extrapolated from two
    samples). The filters without the motion capture's attitude use neither
    (their laws bit for bit as before)."""
    n = xs.shape[0]
    fix_bias = n > _N  # EstimatorGM (E27): three more states, three more noises
    xs_sym, noise = ca.SX.sym("xs", n), ca.SX.sym("n", 18 if fix_bias else 15)
    f = process_model(xs_sym, gyro, acc, noise, v)
    at_estimate = [xs_sym, noise], [xs, ca.DM.zeros(noise.shape[0])]  # linearized at the posterior, noise-free
    # the position also takes the velocity's change over the step, h^2/2 dv/dt (E8): with a 0.1 mm fix,
    # the first-order step's h^2/2 |a| (50 um at 1 m/s2) would be half the fix's noise
    second = ca.vertcat(h / 2 * f[3:6], ca.SX.zeros(n - 3))
    if second_order:  # E30: the attitude's too, h^2/2 (d/do of T(o) omega) T(o) omega (omega held over h)
        turn = f[6:9]
        second[6:9] = h / 2 * ca.jacobian(turn, xs_sym[6:9]) @ turn
    f = f + second
    F, G, f_hat = ca.substitute([ca.jacobian(f, xs_sym), ca.jacobian(f, noise), f], *at_estimate)
    F, G = ca.SX.eye(n) + h * F, h * G
    gyro_density = v["gyro_noise_density"] if rate_noise is None else v["gyro_noise_density"] * rate_noise
    density = [gyro_density] * 3 + [v["accel_noise_density"]] + [v["drag_noise_density"]] * 2 + \
        [v["gyro_bias_walk"]] * 3 + [v["accel_bias_walk"]] * 3 + [v["wind_walk"]] * 2 + [v["wind_walk_z"]]
    if fix_bias:  # E27: sqrt(2 sigma_gm^2 / tau_gm), the density whose stationary variance is sigma_gm^2
        density += [ca.sqrt(2 / v["gm_tau"]) * v[f"gm_sigma_{a}_m"] for a in "xyz"]
    # continuous density -> covariance of a dt-averaged sample (the IMU's), held over h (E13)
    Q = ca.diag(ca.vertcat(*density) ** 2 / v["dt"])
    P_next = F @ P @ F.T + G @ Q @ G.T
    return xs + h * f_hat, (P_next + P_next.T) / 2


def _reset(P, states, variances):
    """``P`` with the rows and columns of ``states`` (indices) cleared and
    their variances set (E21): those states start again, uncorrelated."""
    n = P.shape[0]
    keep = ca.DM.ones(n)
    for k in states:
        keep[k] = 0.0
    fresh = ca.SX.zeros(n)
    for k, variance in zip(states, variances):
        fresh[k] = variance
    return ca.diag(keep) @ P @ ca.diag(keep) + ca.diag(fresh)


def _gated(accept, corrected, before, *carried):
    """The corrected state and covariance when the gate accepts, else the prior (E19),
    computed once with ``carried`` (:func:`_cut`)."""
    return _cut(*(ca.if_else(accept, c, b) for c, b in zip(corrected, before)), *carried)


def _cut(xs, P, *values):
    """The state, the covariance and ``values`` computed once, where the step
    is cut into pieces (:func:`fmu_models.export.staged.value`): the gate's
    decisions (a chi-square quantile: 40 Newton steps) and what they select
    are read by the pieces after the cut, not computed again in each."""
    if staged.inlining():
        return (xs, P, *values)
    xs, packed, *values = staged.value([xs, _packed(P), *values])
    return (xs, _unpacked(packed, P.shape[0]), *values)


def _update(t, v, magnetometer: bool = False, fix_bias: bool = False, attitude_fix: bool = False):
    xs, P = _state(v, len(_ALL_STATES) if fix_bias else _N)
    gyro = ca.vertcat(*(v[f"gyro_{i}"] for i in AXES))
    acc = ca.vertcat(*(v[f"acc_{i}"] for i in AXES))
    started = v["started"] > 0
    level = v["gate_level"]

    # Timing (E22): the filter's state lives at the time of the last IMU sample it used, t_filter. A sample
    # is new when its time stamp is at least half a step later (each is used once, however often an
    # importer shows it); at the first step the initial estimate is the state at the IMU's time.
    t_imu = ca.if_else(v["t_imu"] < 0, t, v["t_imu"])  # no stamp: the sample is current
    new_imu = ca.logic_or(ca.logic_not(started), t_imu > v["t_posterior"] + v["dt"] / 2)
    h = ca.if_else(ca.logic_and(started, new_imu), t_imu - v["t_posterior"], 0.0)
    # (with the motion capture's attitude the rate's noise factor 1, an argument: the output predictor's function)
    xs, P = _predict(xs, P, gyro, acc, v, h, second_order=attitude_fix, rate_noise=1.0 if attitude_fix else None)
    t_filter = ca.if_else(new_imu, t_imu, v["t_posterior"])

    # E9: the drag model's measurement, once per IMU sample, gated (E19-E21): after reset_after refusals
    # in a row the wind starts again from its initial uncertainty (a gust's step is no random walk)
    r_acc = v["accel_noise_density"] ** 2 / v["dt"] + v["sigma_drag"] ** 2
    corrected = _sequential(xs, P, lambda s: drag_measurement(s, v), acc[0:2], [r_acc, r_acc])
    nis_acc = corrected[2]
    refused_acc = ca.logic_and(new_imu, nis_acc > chi2_quantile_even(2, level))
    xs, P, refused_acc = _gated(ca.logic_and(new_imu, ca.logic_not(refused_acc)), corrected[:2], (xs, P), refused_acc)
    run_acc = ca.if_else(new_imu, ca.if_else(refused_acc, v["refusal_run_acc"] + 1, 0.0), v["refusal_run_acc"])
    reset_acc = run_acc >= v["reset_after_drag"]
    # the wind starts again from its initial uncertainty, and the measurement that found the step is fused
    P_wind = _reset(P, _WIND, [v["P0_wind"] ** 2] * 2 + [v["P0_wind_z"] ** 2])
    restarted = _sequential(xs, P_wind, lambda s: drag_measurement(s, v), acc[0:2], [r_acc, r_acc])
    xs, P = _gated(reset_acc, restarted[:2], (xs, P))
    run_acc = ca.if_else(reset_acc, 0.0, run_acc)

    # E24: the magnetometer, sampled with the IMU (same board, same time stamp), once per new IMU sample,
    # gated; no restart after refusals: a refused field is a disturbed one (steel, currents), not a wrong
    # heading, and the heading coasts on the gyro until the field is clean again
    if magnetometer:
        # less the hard-iron offset the calibration found (a parameter; its residual is in sigma_mag)
        mag = ca.vertcat(*(v[f"mag_{i}"] - v[f"mag_bias_{i}"] for i in AXES))
        r_mag = v["sigma_mag"] ** 2
        new_mag = ca.logic_and(new_imu, v["fresh_mag"] > 0.5)
        # E28: until a sample has set it, the heading is taken from the sample (the tilt-compensated compass) and
        # the sample fused at that heading, through the same gate: its heading-free part (the field's size and
        # dip) is then all the NIS sees, and a sample failing it sets nothing and waits for the next
        first = ca.logic_and(new_mag, ca.logic_and(v["heading_from_mag"] > 0.5, v["heading_set"] < 0.5))
        heading = heading_from_field(xs[6], xs[7], mag, ca.vertcat(v["field_north"], v["field_east"], v["field_down"]))
        xs_mag = ca.if_else(first, ca.vertcat(xs[0:8], heading, xs[9:]), xs)
        corrected = _sequential(xs_mag, P, lambda s: magnetometer_measurement(s, v), mag, [r_mag] * 3)
        nis_mag = corrected[2]
        refused_mag = ca.logic_and(new_mag, nis_mag > chi2_quantile_odd(3, level))
        accepted_mag = ca.logic_and(new_mag, ca.logic_not(refused_mag))
        heading_set = ca.if_else(ca.logic_and(first, accepted_mag), 1.0, v["heading_set"])
        xs, P, refused_mag, heading_set = _gated(accepted_mag, corrected[:2], (xs, P), refused_mag, heading_set)

    # E10: the fix, when fresh and newer than the last one seen, fused at its own time t_fix: compared
    # with the state retrodicted over tau = t_filter - t_fix through the process model (E20), gated
    fix = ca.vertcat(*(v[f"{name}_m"] for name in FIX_NAMES))
    sigma2 = [v[f"sigma_{name}_m"] ** 2 for name in FIX_NAMES]
    t_fix = ca.if_else(v["t_fix"] < 0, t, v["t_fix"])
    new_fix = ca.logic_and(v["fresh"] > 0.5, t_fix > v["t_last_fix"])
    tau = ca.fmax(t_filter - t_fix, 0.0)

    def retrodicted(s):  # first order in tau: the velocity's change over tau (< 0.1 of its noise) left out
        position = s[0:3] - tau * s[3:6]
        if fix_bias:  # E27: the fix also carries its correlated error, a state; its covariance enters s (E11)
            position = position + s[_N:_N + 3]
        return ca.vertcat(position, s[3:6])

    corrected = _sequential(xs, P, retrodicted, fix, sigma2)
    nis_fix = corrected[2]
    refused_fix = ca.logic_and(new_fix, nis_fix > chi2_quantile_even(6, level))
    used = ca.logic_and(new_fix, ca.logic_not(refused_fix))
    xs, P, refused_fix = _gated(used, corrected[:2], (xs, P), refused_fix)
    used = ca.logic_and(new_fix, ca.logic_not(refused_fix))
    run_fix = ca.if_else(new_fix, ca.if_else(refused_fix, v["refusal_run_fix"] + 1, 0.0), v["refusal_run_fix"])
    reset_fix = run_fix >= v["reset_after_fix"]
    # position and velocity start again from the fix (brought forward over tau), at its noise (E21)
    restart = ca.vertcat(fix[0:3] + tau * fix[3:6], fix[3:6], xs[6:_N], ca.DM.zeros(xs.shape[0] - _N))
    xs = ca.if_else(reset_fix, restart, xs)
    variances = [sigma2[k] + (tau ** 2 * sigma2[k + 3] if k < 3 else 0.0) for k in range(6)]
    if fix_bias:
        # E27: the fix's correlated error starts again from its stationary prior N(0, sigma_gm^2), and the
        # position, taken as the fix less that error, carries it too: var p += sigma_gm^2, cov(p, b_p) = -sigma_gm^2
        gm2 = [v[f"gm_sigma_{a}_m"] ** 2 for a in "xyz"]
        P_restart = _reset(P, [*range(6), _N, _N + 1, _N + 2],
                           [variances[k] + (gm2[k] if k < 3 else 0.0) for k in range(6)] + gm2)
        for k in range(3):
            P_restart[k, _N + k] = -gm2[k]
            P_restart[_N + k, k] = -gm2[k]
    else:
        P_restart = _reset(P, range(6), variances)
    xs, P = _cut(xs, ca.if_else(reset_fix, P_restart, P))
    run_fix = ca.if_else(reset_fix, 0.0, run_fix)

    # E29: the motion capture's attitude (the rigid body's Euler angles), taken with the fix (the same frame: its
    # fresh flag and its stamp t_fix), compared with the state retrodicted over tau, gated on its own (a rigid body
    # the motion capture mislabels flips its attitude, not its position), restarted from the frame after
    # reset_after_attitude refusals in a row (E21's rule)
    if attitude_fix:
        (xs, P), refused_attitude, reset_attitude, run_attitude, nis_attitude = _attitude_fix(
            xs, P, v, gyro, tau, new_fix, level)

    # the output predictor (E23): the posterior at t_filter brought to the FMU's time t with the IMU's
    # averages extrapolated along their trend over the last two samples (rates change within a step)
    t_out = ca.fmax(t, t_filter)
    h_out = t_out - t_filter
    previous = ca.vertcat(*(v[f"previous_{name}"] for name in _IMU))
    change = ca.if_else(v["started"] > 0, ca.vertcat(gyro, acc) - previous, ca.DM.zeros(6))
    trend = change * h_out / v["dt"]
    # the body rates over [t_filter, t_out] (E26): the rate at t_filter (the IMU's average over the last step
    # describes its middle, half a step earlier), then the angular acceleration of the torques commanded. The
    # command received a step before is the one that acted over that span: an importer that adds a step per
    # hop (the lag h_out) delivers the command a step late too, and without that lag h_out = 0 and it is unused.
    # No output reads this step's command, so the estimator adds no direct feedthrough (no algebraic loop).
    rate_start = gyro + change[0:3] * 0.5 - xs[9:12]
    commands = [v[f"command_{i}"] for i in _ROTORS]
    modelled = commands[0] >= 0
    for c in commands[1:]:
        modelled = ca.logic_and(modelled, c >= 0)
    _, *torque = thrust_and_torques([rotor_clip(c, v["Omega_max"]) ** 2 for c in commands], v["b"], v["d"], v["l"],
                                   v["arm_angle"])
    alpha = body_angular_acceleration(rate_start, ca.vertcat(v["Ix"], v["Iy"], v["Iz"]), ca.vertcat(*torque))
    # the attitude predicted with the mean rate over the span; unconnected: the IMU's averages along their trend
    gyro_out = ca.if_else(modelled, rate_start + alpha * h_out / 2 + xs[9:12], gyro + trend[0:3])
    # E31 (with the motion capture's attitude): the rate held over the span is extrapolated from the last two gyro
    # samples, so its white noise is that of 1.5 g_n - 0.5 g_{n-1} (E26) or (1 + h/dt) g_n - (h/dt) g_{n-1} (E23)
    ratio = h_out / v["dt"]
    extrapolated = ca.if_else(modelled, ca.sqrt(1.5 ** 2 + 0.5 ** 2), ca.sqrt((1 + ratio) ** 2 + ratio ** 2))
    xs_out, P_out = _predict(xs, P, gyro_out, acc + trend[3:6], v, h_out, second_order=attitude_fix,
                             rate_noise=extrapolated if attitude_fix else None)

    counted = _counted(magnetometer, attitude_fix)
    events = {"outliers_fix": refused_fix, "outliers_acc": refused_acc, "resets_fix": reset_fix,
              "resets_acc": reset_acc}
    if magnetometer:
        events["outliers_mag"] = refused_mag
    if attitude_fix:
        events.update(outliers_attitude=refused_attitude, resets_attitude=reset_attitude)
    counts = {c: v[f"total_{c}"] + ca.if_else(events[c], 1.0, 0.0) for c in counted}
    out = {name: xs_out[k] for k, name in enumerate(_ALL_STATES[:xs_out.shape[0]])}
    # the body rate at t_out: from the commands (E26), or the IMU's trend (E23) when they are not connected
    rates = ca.if_else(modelled, rate_start + h_out * alpha, gyro + change[0:3] * (h_out / v["dt"] + 0.5) - xs_out[9:12])
    out.update({"p": rates[0], "q": rates[1], "r": rates[2],
                "nis_acc": ca.if_else(new_imu, nis_acc, 0.0), "nis_fix": ca.if_else(new_fix, nis_fix, 0.0),
                "fix_used": ca.if_else(used, 1.0, 0.0), "t_estimate": t_out, "t_filter": t_filter,
                "fix_age": ca.if_else(new_fix, tau, 0.0), **counts})
    out.update({name: P_out[i, j] for name, i, j in covariance_names(fix_bias)})
    if magnetometer:
        out["nis_mag"] = ca.if_else(new_mag, nis_mag, 0.0)
    discrete_next = {"heading_set": heading_set} if magnetometer else {}
    if attitude_fix:
        out["nis_attitude"] = ca.if_else(new_fix, nis_attitude, 0.0)
        discrete_next["refusal_run_attitude"] = run_attitude
    return out, {**discrete_next, "started": 1.0, "t_posterior": t_filter, "t_last_fix": ca.if_else(new_fix, t_fix, v["t_last_fix"]),
                 "refusal_run_fix": run_fix, "refusal_run_acc": run_acc,
                 **{f"previous_{name}": ca.if_else(new_imu, v[name], v[f"previous_{name}"]) for name in _IMU}, **{f"total_{c}": n for c, n in counts.items()},
                 **{f"command_{i}": v[f"Omega_{i}"] for i in _ROTORS},
                 **_discrete(xs, P)}


_NEVER = -1.0e300  # s: the time of the last fix before any: every fix's stamp is later


def _counted(magnetometer: bool, attitude_fix: bool) -> tuple[str, ...]:
    """The counts a filter outputs: the gate's (E19-E21), the magnetometer's refusals, the motion-capture attitude's."""
    return COUNTS + (MAGNETOMETER_COUNTS if magnetometer else ()) + (ATTITUDE_FIX_COUNTS if attitude_fix else ())


def _initial(v, r, magnetometer: bool = False, fix_bias: bool = False, attitude_fix: bool = False):
    xs = ca.vertcat(*(v[f"{name}_0"] for name in ESTIMATED_STATES))
    sigma = [v[_P0[ESTIMATED_STATES[3 * (k // 3)]]] for k in range(_N - 1)] + [v["P0_wind_z"]]
    if fix_bias:  # E27: the receiver's error is stationary from its start (E25): N(0, sigma_gm^2)
        xs = ca.vertcat(xs, ca.DM.zeros(3))
        sigma += [v[f"gm_sigma_{a}_m"] for a in "xyz"]
    return {"started": 0.0, "t_posterior": 0.0, "t_last_fix": _NEVER, "refusal_run_fix": 0.0,
            "refusal_run_acc": 0.0, **{f"previous_{name}": 0.0 for name in _IMU}, **{f"total_{c}": 0.0 for c in _counted(magnetometer, attitude_fix)},
            **({"refusal_run_attitude": 0.0} if attitude_fix else {}),
            **{f"command_{i}": -1.0 for i in _ROTORS}, **({"heading_set": 0.0} if magnetometer else {}),
            **_discrete(xs, ca.diag(ca.vertcat(*sigma) ** 2))}


ESTIMATOR = FmuModel(
    identifier="Estimator",
    description="extended Kalman filter (docs/estimation.md): predicts position, velocity, attitude, IMU biases "
                "and the wind with the IMU, corrects with the drag model's accelerometer every step and with a "
                "GNSS or motion-capture fix when it is fresh; outputs named like the plant's states, the "
                "covariance and the NIS; z axis down",
    variables=_variables(magnetometer=False),
    sampled=Sampled(update=_update, initial=_initial, n_random=0, seed=None, sample_period="dt"),
)

# The same filter with the magnetometer's correction (E24): a model of its own, so that the Estimator of a
# mission without a magnetometer keeps no input unconnected and flies bit for bit as before (docs/estimation.md)
ESTIMATOR_MAG = FmuModel(
    identifier=MAGNETOMETER_MODEL,
    description="the Estimator's extended Kalman filter (docs/estimation.md) also correcting its attitude with a "
                "three-axis magnetometer sampled with the IMU (E24), gated; z axis down",
    variables=_variables(magnetometer=True),
    sampled=Sampled(update=partial(_update, magnetometer=True), initial=partial(_initial, magnetometer=True),
                    n_random=0, seed=None, sample_period="dt"),
)

# The same filter with the fix's position error correlated in time as three more states (E27): a model of its own,
# so that a mission whose fix is white (motion capture, GNSS6) keeps its 18-state filter bit for bit
ESTIMATOR_GM = FmuModel(
    identifier="EstimatorGM",
    description="the Estimator's extended Kalman filter (docs/estimation.md) with the fix's position error "
                "correlated in time, a first-order Gauss-Markov process per axis estimated as three more states "
                "(E27; the receiver GNSS6GM's E25); z axis down",
    variables=_variables(magnetometer=False, fix_bias=True),
    sampled=Sampled(update=partial(_update, fix_bias=True), initial=partial(_initial, fix_bias=True),
                    n_random=0, seed=None, sample_period="dt"),
)


# The same filter fed by a motion capture's full pose (E29): position, velocity and attitude of the same frame, gated
# and fused at its time; with an attitude known to a tenth of a milliradian it also integrates the attitude to second
# order (E30) and counts the extrapolated rate's noise in its output predictor (E31), which the other filters leave
# out (their laws, and every number they gave, bit for bit as before; docs/estimation.md, "The lab's attitude")
ESTIMATOR_MOCAP = FmuModel(
    identifier=ATTITUDE_FIX_MODEL,
    description="the Estimator's extended Kalman filter (docs/estimation.md) also correcting its attitude with the "
                "motion capture's (the rigid body's Euler angles, taken with the fix), gated (E29); z axis down",
    variables=_variables(magnetometer=False, attitude_fix=True),
    sampled=Sampled(update=partial(_update, attitude_fix=True), initial=partial(_initial, attitude_fix=True),
                    n_random=0, seed=None, sample_period="dt"),
)
