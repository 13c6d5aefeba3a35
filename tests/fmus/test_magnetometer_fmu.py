"""The Magnetometer3 FMU (issue 29, docs/sensors.md "Magnetometer", E24):
its output against its law (the site's field rotated into the body frame,
plus the hard-iron offset) with the noise off, and the noise's statistics
over a long run with it on."""
from __future__ import annotations

import numpy as np
import pytest
from tests.fmu_validation import validate_fmu

from fmu_models.export.build import cached_fmu
from fmu_models.models.magnetometer import MAGNETOMETER, MAGNETOMETER_DEFAULTS
from fmu_models.models.quadrotor import rotation_matrix

from tests.fmus.sensor_harness import DT, Sensor

FIELD = np.array([MAGNETOMETER_DEFAULTS[f"field_{d}"] for d in ("north", "east", "down")])
OUT = ["mag_x", "mag_y", "mag_z"]


def _run(parameters, attitudes):
    rows = Sensor(MAGNETOMETER, parameters=parameters).run(attitudes, read_before=False)
    names = [v.name for v in MAGNETOMETER.outputs]
    return rows[:, [names.index(n) for n in OUT]], rows[:, names.index("t_sample")]


def test_builds_and_validates():
    assert validate_fmu(str(cached_fmu(MAGNETOMETER, 2))) == []


def test_output_is_the_field_rotated_into_the_body_plus_the_offset():
    """Noise off: every sample is R(phi, theta, psi)^T m_W + b_m (E24), at
    attitudes all round the heading circle, and stamped with its step's time."""
    rng = np.random.default_rng(3)
    n = 200
    attitudes = np.column_stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), rng.uniform(-np.pi, np.pi, n)])
    bias = np.array([2e-6, -1e-6, 0.5e-6])
    mag, stamp = _run({"sigma_mag": 0.0, "bias_x": bias[0], "bias_y": bias[1], "bias_z": bias[2]}, attitudes)
    for k in range(n):
        R = np.array(rotation_matrix(*attitudes[k]), float)
        np.testing.assert_allclose(mag[k], R.T @ FIELD + bias, rtol=0, atol=1e-18)
    np.testing.assert_allclose(stamp, np.arange(n) * DT, rtol=0, atol=1e-12)
    # a quarter turn in heading moves the north field onto -y_B
    level_east = _run({"sigma_mag": 0.0}, np.array([[0.0, 0.0, np.pi / 2]]))[0][0]
    assert level_east == pytest.approx([FIELD[1], -FIELD[0], FIELD[2]], abs=1e-18)


def test_noise_has_the_given_standard_deviation_and_is_white():
    n, sigma = 20000, MAGNETOMETER_DEFAULTS["sigma_mag"]
    mag, _ = _run({"seed": 11}, np.zeros((n, 3)))
    z = (mag - FIELD) / sigma
    assert np.all(np.abs(z.mean(axis=0)) < 4.5 / np.sqrt(n))
    assert np.all(np.abs(z.std(axis=0) - 1.0) < 0.03)
    assert np.all(np.abs([np.corrcoef(z[1:, i], z[:-1, i])[0, 1] for i in range(3)]) < 0.04)
    assert abs(np.corrcoef(z[:, 0], z[:, 1])[0, 1]) < 0.04
