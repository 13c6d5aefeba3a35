"""A state estimator as a sampled-data FMU: an extended Kalman filter written
in CasADi that predicts with the IMU and corrects with the drag-model
accelerometer and with GNSS or motion capture (docs/estimation.md, eqs.
E5-E14; the numbers below are those equations').

State (18): position ``x y z`` and velocity ``u v w`` (world frame, z down,
eq. 6), attitude ``phi theta psi`` (Z-Y-X Euler, eq. 8), gyro bias
``b_g``, accelerometer bias ``b_a`` (body frame) and the wind ``w_W`` (world
frame). Per communication step n, with the IMU's ``gyro_n, acc_n`` and the
position/velocity fix ``y_n`` (fresh or not) as inputs:

1. the prior ``x^-_n, P^-_n`` is corrected with the
   accelerometer's two horizontal body axes, the drag model's measurement
   (E9): ``acc_xy = [R^T D(v - w_W) / m]_xy + b_a,xy``, every step;
2. then, when ``fresh = 1``, with the six position/velocity channels (E10);
   both as sequential scalar updates (E11-E12), the Jacobians from CasADi's AD;
3. the outputs are the posterior: the state named like the plant's outputs
   (``x .. psi``), the body rates ``p q r = gyro - b_g``, the wind, the biases,
   the covariance (variances of all 18, covariances within the position,
   velocity, attitude and wind blocks) and the normalized innovations squared
   (NIS) of both corrections;
0. before the corrections, the posterior of t_{n-1} is propagated to the
   prior of t_n with the IMU's averages over the step (E7-E8, explicit Euler
   over dt; covariance E13).

The discrete state is the posterior of t_{n-1}; step n first predicts it
to t_n with the IMU's averages over [t_{n-1}, t_n] (``fmu_models/models/imu.py``),
then corrects. Outputs have direct feedthrough from the fix and the IMU: the
controller reading the estimate at t_n flies on the measurements of t_n.
"""
from __future__ import annotations

from fmu_models.lazy_casadi import ca

from ..export.model import FmuModel, Sampled
from ..export.variables import discrete, input_, output, parameter
from .imu import AXES, IMU_DEFAULTS
from .quadrotor import DEFAULTS, aerodynamic_drag, euler_rate_matrix, rotation_matrix
from .sensors import DT_DEFAULT

__all__ = ["ESTIMATOR", "ESTIMATED_STATES", "FIX_NAMES", "ESTIMATOR_DEFAULTS", "process_model", "drag_measurement",
           "body_drag_acceleration", "scalar_update", "covariance_names", "COVARIANCE_BLOCKS"]

# The filter's state, in order: the 9 plant states it estimates, then the biases and the wind.
ESTIMATED_STATES = ("x", "y", "z", "u", "v", "w", "phi", "theta", "psi",
                    "gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "accel_bias_x", "accel_bias_y", "accel_bias_z",
                    "wind_x", "wind_y", "wind_z")
_N = len(ESTIMATED_STATES)
_UNITS = ("m",) * 3 + ("m/s",) * 3 + ("rad",) * 3 + ("rad/s",) * 3 + ("m/s2",) * 3 + ("m/s",) * 3
FIX_NAMES = ("x", "y", "z", "u", "v", "w")  # the fix: position and velocity (GNSS or motion capture)
# 3-state blocks whose full covariance is an output (the study's NEES per block)
COVARIANCE_BLOCKS = {"position": ("x", "y", "z"), "velocity": ("u", "v", "w"), "attitude": ("phi", "theta", "psi"),
                     "wind": ("wind_x", "wind_y", "wind_z")}
# Tuning (docs/estimation.md, "Tuning"); the sensor values are the IMU's defaults.
ESTIMATOR_DEFAULTS = {
    "wind_walk": 4.0,             # m/s/sqrt(s): the horizontal wind's random walk, fast enough for a reversal
    "wind_walk_z": 0.01,          # m/s/sqrt(s): the vertical wind's, nearly constant (hardly observable, E9)
    "drag_noise_density": 0.005,  # m/s2/sqrt(Hz): error of the drag model in the prediction
    "sigma_drag": 0.005,          # m/s2: error of the drag model in the accelerometer measurement
    "P0_position": 1.0, "P0_velocity": 0.2, "P0_attitude": 0.05,
    "P0_gyro_bias": 0.005, "P0_accel_bias": 0.01, "P0_wind": 3.0, "P0_wind_z": 0.1,
}
_P0 = {"x": "P0_position", "u": "P0_velocity", "phi": "P0_attitude", "gyro_bias_x": "P0_gyro_bias",
       "accel_bias_x": "P0_accel_bias", "wind_x": "P0_wind"}


def covariance_names() -> list[tuple[str, int, int]]:
    """``(output name, i, j)`` of the covariance outputs: ``var_<s>`` for every
    state, ``cov_<a>_<b>`` (a before b) within each block of COVARIANCE_BLOCKS."""
    index = {s: k for k, s in enumerate(ESTIMATED_STATES)}
    names = [(f"var_{s}", k, k) for k, s in enumerate(ESTIMATED_STATES)]
    for block in COVARIANCE_BLOCKS.values():
        names += [(f"cov_{a}_{b}", index[a], index[b]) for k, a in enumerate(block) for b in block[k + 1:]]
    return names


def _upper(i, j):
    i, j = min(i, j), max(i, j)
    return f"P_{ESTIMATED_STATES[i]}__{ESTIMATED_STATES[j]}"


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
    bias walks and the wind walk, white with the densities of E13."""
    _, velocity, attitude, b_g, b_a, _ = _split(xs)
    drag = body_drag_acceleration(xs, v["m"], v["k_drag_lin"], v["k_drag_quad"])
    rates = gyro - b_g - noise[0:3]
    force = ca.vertcat(drag[0] + noise[4], drag[1] + noise[5], acc[2] - b_a[2] - noise[3])
    R = rotation_matrix(attitude[0], attitude[1], attitude[2])
    return ca.vertcat(velocity, R @ force + ca.vertcat(0, 0, v["g"]),
                      euler_rate_matrix(attitude[0], attitude[1]) @ rates,
                      noise[6:9], noise[9:12], noise[12:15])


def drag_measurement(xs, v):
    """The accelerometer's horizontal body axes predicted from the state, eq. E9."""
    drag = body_drag_acceleration(xs, v["m"], v["k_drag_lin"], v["k_drag_quad"])
    return ca.vertcat(drag[0] + xs[12], drag[1] + xs[13])


def scalar_update(xs, P, h, H, measured, variance):
    """One scalar EKF correction, eqs. E11-E12: innovation ``nu = y - h``,
    ``s = H P H^T + r``, gain ``K = P H^T / s``; returns the corrected state,
    covariance and the NIS term ``nu^2 / s``."""
    PH = P @ H.T
    s = (H @ PH)[0, 0] + variance
    K = PH / s
    nu = measured - h
    P_next = P - K @ PH.T
    return xs + K * nu, (P_next + P_next.T) / 2, nu * nu / s


def _sequential(xs, P, measure, measured, variances):
    """Scalar updates one channel after another; each channel's Jacobian at the
    state corrected by the channels before it (E11)."""
    xs_sym = ca.SX.sym("xs", _N)
    predicted = measure(xs_sym)
    nis = 0
    for k in range(measured.shape[0]):
        h, H = ca.substitute([predicted[k], ca.jacobian(predicted[k], xs_sym)], [xs_sym], [xs])
        xs, P, term = scalar_update(xs, P, h, H, measured[k], variances[k])
        nis = nis + term
    return xs, P, nis


def _variables():
    variables = [
        *(input_(f"gyro_{i}", "rad/s", f"IMU angular rate about {i}_B", 0.0) for i in AXES),
        input_("acc_x", "m/s2", "IMU specific force along x_B", 0.0),
        input_("acc_y", "m/s2", "IMU specific force along y_B", 0.0),
        input_("acc_z", "m/s2", "IMU specific force along z_B (-g level at rest, z down)", -DEFAULTS["g"]),
        *(input_(f"{name}_m", unit, f"fix (GNSS or motion capture): {name}", 0.0)
          for name, unit in zip(FIX_NAMES, _UNITS)),
        input_("fresh", "1", "1 when the fix is new this step (then the filter corrects with it), 0 otherwise; "
                             "left at 1, every step's fix is used", 1.0),
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
                               "(2 degrees of freedom)"),
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
        parameter("fix_latency", "s", "age of the fix when it arrives (GNSS latency); the filter compares it "
                  "with the position extrapolated back by it (E10)", 0.0, min=0.0, max=1.0),
        *(parameter(f"{name}_0", unit, f"initial estimate of {name}", 0.0)
          for name, unit in zip(ESTIMATED_STATES, _UNITS)),
        *(parameter(p0, unit, f"initial standard deviation of the {p0[3:].replace('_', ' ')} estimate (each axis)",
                    ESTIMATOR_DEFAULTS[p0], min=1e-9)
          for p0, unit in (("P0_position", "m"), ("P0_velocity", "m/s"), ("P0_attitude", "rad"),
                           ("P0_gyro_bias", "rad/s"), ("P0_accel_bias", "m/s2"), ("P0_wind", "m/s"),
                           ("P0_wind_z", "m/s"))),
        parameter("dt", "s", "communication step = sample period of the filter (every doStep must be dt)",
                  DT_DEFAULT, min=1e-6, max=10.0),
        discrete("started", "1", "0 before the first step (the initial estimate is the first prior), 1 after"),
        *(discrete(f"xhat_{name}", unit, f"posterior estimate of {name} at the previous step")
          for name, unit in zip(ESTIMATED_STATES, _UNITS)),
        *(discrete(_upper(i, j), "1", "posterior covariance entry at the previous step")
          for i in range(_N) for j in range(i, _N)),
    ]
    return tuple(variables)


def _state(v):
    xs = ca.vertcat(*(v[f"xhat_{name}"] for name in ESTIMATED_STATES))
    P = ca.SX(_N, _N)
    for i in range(_N):
        for j in range(_N):
            P[i, j] = v[_upper(i, j)]
    return xs, P


def _discrete(xs, P):
    z = {f"xhat_{name}": xs[k] for k, name in enumerate(ESTIMATED_STATES)}
    z.update({_upper(i, j): P[i, j] for i in range(_N) for j in range(i, _N)})
    return z


def _predict(xs, P, gyro, acc, v):
    """The prior at t_n from the posterior at t_{n-1} and the IMU's averages
    over [t_{n-1}, t_n]: explicit Euler over dt (E7-E8), covariance E13."""
    dt = v["dt"]
    xs_sym, noise = ca.SX.sym("xs", _N), ca.SX.sym("n", 15)
    f = process_model(xs_sym, gyro, acc, noise, v)
    at_estimate = [xs_sym, noise], [xs, ca.DM.zeros(15)]  # linearized at the posterior, noise-free
    # the position also takes the velocity's change over the step, dt^2/2 dv/dt (E8): with a 0.1 mm fix,
    # the first-order step's dt^2/2 |a| (50 um at 1 m/s2) would be half the fix's noise
    second = ca.vertcat(dt / 2 * f[3:6], ca.SX.zeros(_N - 3))
    f = f + second
    F, G, f_hat = ca.substitute([ca.jacobian(f, xs_sym), ca.jacobian(f, noise), f], *at_estimate)
    F, G = ca.DM.eye(_N) + dt * F, dt * G
    density = [v["gyro_noise_density"]] * 3 + [v["accel_noise_density"]] + [v["drag_noise_density"]] * 2 + \
        [v["gyro_bias_walk"]] * 3 + [v["accel_bias_walk"]] * 3 + [v["wind_walk"]] * 2 + [v["wind_walk_z"]]
    Q = ca.diag(ca.vertcat(*density) ** 2 / dt)  # continuous density -> covariance of a dt-averaged sample
    P_next = F @ P @ F.T + G @ Q @ G.T
    return xs + dt * f_hat, (P_next + P_next.T) / 2


def _update(t, v):
    xs, P = _state(v)
    gyro = ca.vertcat(*(v[f"gyro_{i}"] for i in AXES))
    acc = ca.vertcat(*(v[f"acc_{i}"] for i in AXES))

    # the prior of t_n; at n = 0 the initial estimate is the prior
    xs_prior, P_prior = _predict(xs, P, gyro, acc, v)
    started = v["started"] > 0
    xs, P = ca.if_else(started, xs_prior, xs), ca.if_else(started, P_prior, P)
    # E9: the drag model's measurement, every step
    r_acc = v["accel_noise_density"] ** 2 / v["dt"] + v["sigma_drag"] ** 2
    xs, P, nis_acc = _sequential(xs, P, lambda s: drag_measurement(s, v), acc[0:2], [r_acc, r_acc])
    # E10: the fix, when fresh
    fix = ca.vertcat(*(v[f"{name}_m"] for name in FIX_NAMES))
    latency = v["fix_latency"]  # the fix describes t_n - latency: p(t_n - tau) = p - tau v (E10)
    xs_fix, P_fix, nis_fix = _sequential(xs, P, lambda s: ca.vertcat(s[0:3] - latency * s[3:6], s[3:6]), fix,
                                         [v[f"sigma_{name}_m"] ** 2 for name in FIX_NAMES])
    fresh = v["fresh"] > 0.5
    xs, P = ca.if_else(fresh, xs_fix, xs), ca.if_else(fresh, P_fix, P)

    out = {name: xs[k] for k, name in enumerate(ESTIMATED_STATES)}
    rates = gyro - xs[9:12]
    out.update({"p": rates[0], "q": rates[1], "r": rates[2], "nis_acc": nis_acc,
                "nis_fix": ca.if_else(fresh, nis_fix, 0.0), "fix_used": ca.if_else(fresh, 1.0, 0.0)})
    out.update({name: P[i, j] for name, i, j in covariance_names()})
    return out, {"started": 1.0, **_discrete(xs, P)}


def _initial(v, r):
    xs = ca.vertcat(*(v[f"{name}_0"] for name in ESTIMATED_STATES))
    sigma = [v[_P0[ESTIMATED_STATES[3 * (k // 3)]]] for k in range(_N - 1)] + [v["P0_wind_z"]]
    return {"started": 0.0, **_discrete(xs, ca.diag(ca.vertcat(*sigma) ** 2))}


ESTIMATOR = FmuModel(
    identifier="Estimator",
    description="extended Kalman filter (docs/estimation.md): predicts position, velocity, attitude, IMU biases "
                "and the wind with the IMU, corrects with the drag model's accelerometer every step and with a "
                "GNSS or motion-capture fix when it is fresh; outputs named like the plant's states, the "
                "covariance and the NIS; z axis down",
    variables=_variables(),
    sampled=Sampled(update=_update, initial=_initial, n_random=0, seed=None, sample_period="dt"),
)
