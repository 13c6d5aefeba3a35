"""The IMU, GNSS6 and Estimator FMUs (issue 20, docs/sensors.md and
docs/estimation.md): the sensors' statistics from long runs against their
parameters, the specific force's known answers, GNSS's fresh flag through
its latency, the EKF on a straight line with a known answer, and the
Estimator FMU step for step against its CasADi function evaluated in Python."""
from __future__ import annotations

import math

import numpy as np
import pytest
from tests.fmu_validation import validate_fmu

from tests.catalog_fmus import catalog_fmu
from fmu_models.models.estimator import ESTIMATOR, ESTIMATOR_GM, ESTIMATOR_MAG, ESTIMATED_STATES
from fmu_models.models.imu import IMU
from fmu_models.models.sensors import GNSS_6

from tests.fmus.sensor_harness import DT, Sensor

G = 9.81


def _imu(parameters, inputs):
    """Outputs (rows) of an IMU FMU fed ``inputs`` (rows of u v w phi theta psi p q r)."""
    return Sensor(IMU, parameters=parameters).run(inputs, read_before=False)


def _outputs(model, rows, names):
    index = [v.name for v in model.outputs]
    return rows[:, [index.index(n) for n in names]]


@pytest.mark.parametrize("model", [IMU, GNSS_6, ESTIMATOR, ESTIMATOR_MAG, ESTIMATOR_GM], ids=lambda m: m.identifier)
def test_builds_and_validates(model):
    assert validate_fmu(str(catalog_fmu(model, 2))) == []


def test_imu_white_noise_has_the_density_over_root_dt():
    """Gyro and accelerometer noise at rest: std N / sqrt(dt) per axis, mean
    the true value (0 rad/s; (0, 0, -g) m/s^2), independent from step to step."""
    n, n_g, n_a = 20000, 2.4e-4, 1.7e-3
    rows = _imu({"gyro_noise_density": n_g, "accel_noise_density": n_a, "gyro_bias_walk": 0.0,
                 "accel_bias_walk": 0.0, "seed": 4}, np.zeros((n, 9)))
    gyro = _outputs(IMU, rows, ["gyro_x", "gyro_y", "gyro_z"])
    acc = _outputs(IMU, rows, ["acc_x", "acc_y", "acc_z"]) - [0.0, 0.0, -G]
    for noise, density in ((gyro, n_g), (acc, n_a)):
        z = noise / (density / math.sqrt(DT))
        assert np.all(np.abs(z.mean(axis=0)) < 4.5 / math.sqrt(n))
        assert np.all(np.abs(z.std(axis=0) - 1.0) < 0.03)
        assert np.all(np.abs([np.corrcoef(z[1:, i], z[:-1, i])[0, 1] for i in range(3)]) < 0.04)


def test_imu_bias_walks_with_the_given_random_walk():
    """Noise off: the outputs are truth + bias exactly; the bias' increments
    have std K sqrt(dt), and over 1 s blocks the bias moves by K (the walk's
    growth, sqrt(t)), both from a long run."""
    n, k_g, k_a = 20000, 2e-5, 3e-4
    rows = _imu({"gyro_noise_density": 0.0, "accel_noise_density": 0.0, "gyro_bias_walk": k_g,
                 "accel_bias_walk": k_a, "seed": 8, "gyro_bias_0_x": 0.01}, np.zeros((n, 9)))
    gyro_bias = _outputs(IMU, rows, ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z"])
    accel_bias = _outputs(IMU, rows, ["accel_bias_x", "accel_bias_y", "accel_bias_z"])
    np.testing.assert_array_equal(_outputs(IMU, rows, ["gyro_x", "gyro_y", "gyro_z"]), gyro_bias)
    np.testing.assert_array_equal(_outputs(IMU, rows, ["acc_x", "acc_y", "acc_z"]), accel_bias + [0.0, 0.0, -G])
    assert gyro_bias[0, 0] == 0.01  # the initial bias
    for bias, walk in ((gyro_bias, k_g), (accel_bias, k_a)):
        steps = np.diff(bias, axis=0) / (walk * math.sqrt(DT))
        assert np.all(np.abs(steps.std(axis=0) - 1.0) < 0.03)
        per_second = np.diff(bias[::round(1 / DT)], axis=0) / walk  # 200 one-second moves per axis
        assert np.all(np.abs(per_second.std(axis=0) - 1.0) < 0.2)


def test_imu_specific_force_and_rate_are_averages_over_the_step():
    """Known answers, noise off: a level vehicle speeding up at a = 2 m/s^2
    north reads (a, 0, -g) from the second step (the first has no step
    before it: (0, 0, -g)); pitched up by theta at rest it reads
    g (sin theta, 0, -cos theta); a rate ramp reads the mean of its ends."""
    off = {"gyro_noise_density": 0.0, "accel_noise_density": 0.0, "gyro_bias_walk": 0.0, "accel_bias_walk": 0.0}
    t = np.arange(5) * DT
    ramp = np.zeros((5, 9))
    ramp[:, 0] = 2.0 * t
    ramp[:, 6] = 0.3 * t  # p
    rows = _imu(off, ramp)
    acc = _outputs(IMU, rows, ["acc_x", "acc_y", "acc_z"])
    np.testing.assert_allclose(acc[1:], np.tile([2.0, 0.0, -G], (4, 1)), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(acc[0], [0.0, 0.0, -G])
    np.testing.assert_allclose(_outputs(IMU, rows, ["gyro_x"])[1:, 0], 0.3 * (t[1:] - DT / 2), rtol=0, atol=1e-15)
    theta = 0.2
    pitched = np.zeros((3, 9))
    pitched[:, 4] = theta
    acc = _outputs(IMU, _imu(off, pitched), ["acc_x", "acc_y", "acc_z"])
    np.testing.assert_allclose(acc, np.tile([G * math.sin(theta), 0.0, -G * math.cos(theta)], (3, 1)),
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("delay", [0, 2])
def test_gnss_fix_is_fresh_once_per_sample_after_its_latency(delay):
    """10 Hz at dt = 0.01: a new fix every 10 steps, delivered ``delay``
    steps late with ``fresh`` = 1 on the step it arrives, 0 otherwise (also
    while the latency's line still holds the first sample)."""
    n = 60
    u = np.random.default_rng(2).normal(size=(n, 6))
    gnss = Sensor(GNSS_6, parameters={"sample_rate": 10.0, "delay_steps": delay})
    rows = gnss.run(u)
    fresh = _outputs(GNSS_6, rows, ["fresh"])[:, 0]
    expected = np.zeros(n)
    expected[delay::10] = 1.0
    np.testing.assert_array_equal(fresh, expected)
    sampled = u[((np.arange(n) - delay) // 10 * 10).clip(0)]
    np.testing.assert_array_equal(_outputs(GNSS_6, rows, [f"{s}_m" for s in "xyzuvw"]), sampled)


FIX_SIGMA = {**{f"sigma_{a}_m": 0.02 for a in "xyz"}, **{f"sigma_{a}_m": 0.05 for a in "uvw"}}  # RTK GNSS


def _straight_line(n):
    """Inputs of the EKF for a vehicle drifting with the air at v0 (no drag,
    level, no rotation): exact IMU and fix, the fix fresh every 10 steps."""
    v0 = np.array([2.0, 1.0, 0.0])  # level: the vertical wind is modelled near zero (E13)
    t = np.arange(n) * DT
    rows = []
    for k, tk in enumerate(t):
        p = np.array([0.0, 0.0, -10.0]) + v0 * tk
        rows.append({"acc_z": -G, "x_m": p[0], "y_m": p[1], "z_m": p[2], "u_m": v0[0], "v_m": v0[1], "w_m": v0[2],
                     "fresh": float(k % 10 == 0), "t_imu": tk, "t_fix": tk})
    return v0, t, [ESTIMATOR.input_values(**r) for r in rows]


def test_estimator_on_a_straight_line_finds_the_known_answer():
    """Drifting with a wind equal to its velocity, the vehicle feels no drag
    and the accelerometer reads (0, 0, -g): the only answer is position and
    velocity on the line, level attitude, no biases and a wind equal to the
    velocity. From an estimate 0.5 m off, at rest, in still air, the EKF gets
    there (to 2 mm, 2 mm/s, 2 mm/s of wind) and its variances shrink."""
    v0, t, inputs = _straight_line(3000)
    # the start knows it does not know the velocity (3 m/s): at its default 0.2 m/s the gate would rightly
    # refuse the first fixes (2.2 m/s off, E19) and restart from one (E21)
    start = {"x_0": 0.5, "y_0": -0.3, "z_0": -9.8, "P0_velocity": 3.0, **FIX_SIGMA}
    rows = Sensor(ESTIMATOR, parameters=start).run(inputs, read_before=False)
    last = dict(zip([v.name for v in ESTIMATOR.outputs], rows[-1]))
    truth = {"x": v0[0] * t[-1], "y": v0[1] * t[-1], "z": -10.0 + v0[2] * t[-1], "u": v0[0], "v": v0[1],
             "w": v0[2], "wind_x": v0[0], "wind_y": v0[1]}
    for name, value in truth.items():
        assert abs(last[name] - value) < 2e-3, (name, last[name], value)
    for name in ("phi", "theta", "psi", "gyro_bias_x", "accel_bias_x", "accel_bias_z"):
        assert abs(last[name]) < 1e-3, (name, last[name])
    # the variances fall well below a single fix's (the fixes and the IMU combined) and the wind's prior
    assert last["var_x"] < FIX_SIGMA["sigma_x_m"] ** 2 / 5 and last["var_u"] < FIX_SIGMA["sigma_u_m"] ** 2 / 5
    assert last["var_wind_x"] < ESTIMATOR.variable("P0_wind").start ** 2 / 100
    assert np.all(_outputs(ESTIMATOR, rows, ["nis_fix"])[:, 0][np.arange(3000) % 10 != 0] == 0.0)
    assert last["outliers_fix"] == last["resets_fix"] == 0.0


@pytest.mark.parametrize("model, values", [(ESTIMATOR, {}), (ESTIMATOR_GM, {"gm_sigma_x_m": 0.02, "gm_sigma_z_m": 0.03})],
                         ids=lambda m: getattr(m, "identifier", ""))
def test_estimator_fmu_is_its_casadi_function_step_for_step(model, values):
    """The FMU's C (generated from CasADi) and CasADi's own evaluation of
    ``dstep`` agree bit for bit on every output and discrete state over 300
    noisy steps (EstimatorGM: with the fix's correlated error, E27)."""
    rng = np.random.default_rng(5)
    _, _, inputs = _straight_line(300)
    inputs = np.array(inputs) + rng.normal(scale=0.01, size=(300, len(model.inputs)))
    names = [v.name for v in model.inputs]
    inputs[:, names.index("fresh")] = (np.arange(300) % 10 == 0)
    inputs[:, names.index("t_imu")] = inputs[:, names.index("t_fix")] = np.arange(300) * DT
    parameters = model.parameter_values(z_0=-10.0, **values)
    fmu = Sensor(model, parameters={"z_0": -10.0, **values})
    f = model.functions
    z = np.array(f["dinit"](parameters, [])).ravel()
    discrete = [fmu.vr[v.name] for v in model.discrete_states]
    for n, u in enumerate(inputs):
        y_fmu = fmu.sample(u, read_before=False)
        y, z = (np.array(a).ravel() for a in f["dstep"](n * DT, u, parameters, z))
        np.testing.assert_array_equal(y_fmu, y)
        np.testing.assert_array_equal(np.array(fmu.get(discrete)), z)
    assert len(ESTIMATED_STATES) == 18
