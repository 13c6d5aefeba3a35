"""The motion capture's FMUs (issue 29, docs/sensors.md "Mocap9",
docs/estimation.md E29-E31): ``Mocap9`` and ``EstimatorMocap`` build and
validate, the motion capture's angles carry the noise asked for and its
position the noise of ``GNSS6``'s law, and the EstimatorMocap FMU is its
CasADi function step for step."""
from __future__ import annotations

import math

import numpy as np
import pytest
from tests.fmu_validation import validate_fmu

from tests.catalog_fmus import catalog_fmu
from fmu_models.models.estimator import ANGLES, ESTIMATOR_MOCAP
from fmu_models.models.sensors import MOCAP_9

from tests.fmus.sensor_harness import DT, Sensor

G = 9.81


@pytest.mark.parametrize("model", [MOCAP_9, ESTIMATOR_MOCAP], ids=lambda m: m.identifier)
def test_builds_and_validates(model):
    assert validate_fmu(str(catalog_fmu(model, 2))) == []


def test_the_motion_capture_angles_have_their_noise_every_frame():
    """At 120 Hz (a frame every 10 ms step) each angle is the truth plus white
    noise of its sigma (std within 4 %, mean within 4.5 standard errors,
    independent from step to step), and every step is fresh, stamped with its time."""
    n, sigma = 5000, {"sigma_phi": 7.1e-4, "sigma_theta": 7.1e-4, "sigma_psi": 5.0e-4}
    truth = np.zeros((n, 9))
    truth[:, 8] = 0.3  # a heading
    rows = Sensor(MOCAP_9, parameters={"sample_rate": 120.0, "seed": 3, **sigma}).run(truth)
    names = [v.name for v in MOCAP_9.outputs]
    for k, angle in enumerate(ANGLES):
        error = (rows[:, names.index(f"{angle}_m")] - truth[:, 6 + k]) / sigma[f"sigma_{angle}"]
        assert abs(error.std() - 1.0) < 0.04 and abs(error.mean()) < 4.5 / math.sqrt(n)
        assert abs(np.corrcoef(error[1:], error[:-1])[0, 1]) < 0.05
    assert np.all(rows[:, names.index("fresh")] == 1.0)
    np.testing.assert_allclose(rows[:, names.index("t_sample")], np.arange(n) * DT, atol=1e-9)


def test_estimator_mocap_fmu_is_its_casadi_function_step_for_step():
    """The FMU's C (generated from CasADi) and CasADi's own evaluation of
    ``dstep`` agree bit for bit on every output and discrete state over 300
    noisy steps with a frame every step, one mislabelled and the rotor
    commands connected (E29-E31)."""
    rng = np.random.default_rng(5)
    names = [v.name for v in ESTIMATOR_MOCAP.inputs]
    inputs = np.array([ESTIMATOR_MOCAP.input_values(acc_z=-G, z_m=-10.0, fresh=1.0, t_imu=k * DT, t_fix=k * DT,
                                                    psi_m=0.1, **{f"Omega_{i}": 300.0 for i in range(1, 5)})
                       for k in range(300)])
    inputs += rng.normal(scale=1e-3, size=inputs.shape)
    inputs[:, names.index("fresh")] = 1.0
    inputs[:, names.index("t_imu")] = inputs[:, names.index("t_fix")] = np.arange(300) * DT
    inputs[150, names.index("psi_m")] += 0.5  # refused by the gate
    values = {"z_0": -10.0, "sigma_psi_m": 1e-3}
    parameters = ESTIMATOR_MOCAP.parameter_values(**values)
    fmu = Sensor(ESTIMATOR_MOCAP, parameters=values)
    f = ESTIMATOR_MOCAP.functions
    z = np.array(f["dinit"](parameters, [])).ravel()
    discrete = [fmu.vr[v.name] for v in ESTIMATOR_MOCAP.discrete_states]
    outputs = [v.name for v in ESTIMATOR_MOCAP.outputs]
    for n, u in enumerate(inputs):
        y_fmu = fmu.sample(u, read_before=False)
        y, z = (np.array(a).ravel() for a in f["dstep"](n * DT, u, parameters, z))
        np.testing.assert_array_equal(y_fmu, y)
        np.testing.assert_array_equal(np.array(fmu.get(discrete)), z)
    assert y[outputs.index("outliers_attitude")] >= 1.0
