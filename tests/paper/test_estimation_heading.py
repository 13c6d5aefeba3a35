"""The heading (issue 29, docs/estimation.md "Heading", E24, E28): the
magnetometer's gate quantile for 3 degrees of freedom, a heading error
corrected by the magnetometer (and not without it), a disturbed field
refused and counted, the heading started from the first sample the gate
accepts, the hard-iron offset the calibration found taken off."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_models.models.estimator import ESTIMATOR_MAG, chi2_quantile_odd
from fmu_models.models.magnetometer import MAGNETOMETER_DEFAULTS, body_field, heading_from_field
from fmu_models.models.quadrotor import rotation_matrix

from test_estimation_gating import DT, G, _run as run_estimator

FIELD = np.array([MAGNETOMETER_DEFAULTS[f"field_{d}"] for d in ("north", "east", "down")])
PSI = 0.15  # rad: the true heading; the filter starts at 0
OUTPUTS = [v.name for v in ESTIMATOR_MAG.outputs]


def _run(inputs, **parameters):
    """EstimatorMag's outputs, row per step, from its FMU (the C of its CasADi step function)."""
    return run_estimator(inputs, ESTIMATOR_MAG, **parameters)


def _col(rows, name):
    return rows[:, OUTPUTS.index(name)]


@pytest.mark.parametrize("k", [3, 5])
def test_the_odd_gate_is_the_chi_square_quantile_of_its_level(k):
    # scipy.stats' chi2.ppf(q, k) is 2 gammaincinv(k / 2, q), the same bits, here without importing
    # scipy.stats (about 0.9 s of CPU more in a process that imports it for nothing else)
    from scipy.special import gammaincinv

    for level in (0.5, 0.95, 0.9999, 1 - 1e-6):
        assert float(chi2_quantile_odd(k, level)) == pytest.approx(2 * gammaincinv(k / 2, level), rel=1e-9)
    with pytest.raises(ValueError, match="k = 4"):
        chi2_quantile_odd(4, 0.99)


def _hover(n, fresh_mag, disturbed=(), missing=(), psi=PSI, offset=(0.0, 0.0, 0.0), zero=()):
    """A vehicle hovering at (0, 0, -10) with heading ``psi``: exact IMU, a fix
    every 10 steps, the magnetometer's exact field (``fresh_mag``) plus a
    hard-iron ``offset``; at the steps in ``disturbed`` the field is off by
    20 uT on x_B (a steel beam), at those in ``missing`` there is no sample,
    at those in ``zero`` the sample is 0 (fmpy's connectors before the first
    transfer)."""
    inputs = [v.name for v in ESTIMATOR_MAG.inputs]
    mag = np.array(rotation_matrix(0.0, 0.0, psi), float).T @ FIELD + np.array(offset)
    rows = np.zeros((n, len(inputs)))
    for k in range(n):
        m = mag + (np.array([20e-6, 0, 0]) if k in disturbed else 0.0)
        m = 0.0 * m if k in zero else m
        rows[k] = ESTIMATOR_MAG.input_values(acc_z=-G, z_m=-10.0, fresh=float(k % 10 == 0), t_imu=k * DT, t_fix=k * DT,
                                         mag_x=m[0], mag_y=m[1], mag_z=m[2],
                                         fresh_mag=0.0 if k in missing else fresh_mag)
    return rows


@pytest.mark.parametrize("attitude", [(0.1, -0.2, 2.5), (0.0, 0.0, -3.0), (-0.3, 0.25, 0.15)])
def test_the_heading_from_the_field_is_the_one_that_made_it(attitude):
    """E28 inverts E24: the field seen at (phi, theta, psi) gives psi back."""
    field = body_field(attitude, FIELD)
    assert float(heading_from_field(attitude[0], attitude[1], field, FIELD)) == pytest.approx(attitude[2], abs=1e-12)


def test_the_heading_starts_from_the_first_sample_the_gate_accepts():
    """A heading 2.5 rad from psi_0 with a start sure to 0.05 rad: from the
    first sample (E28) the heading is the field's; the first sample, 0 as in
    fmpy's start, fails the gate at any heading (its size is not the field's):
    refused, counted, and the heading set by the second. Without E28 every
    sample is refused, the heading stays at psi_0."""
    start = {"P0_attitude": 0.05, "sigma_mag": 0.6e-6}
    rows = _run(_hover(30, 1.0, psi=2.5, zero=(0,)), **start)
    psi = _col(rows, "psi")
    assert psi[0] == 0.0 and _col(rows, "outliers_mag")[0] == 1.0  # the zero field refused, nothing set
    assert abs(psi[1] - 2.5) < 1e-6 and abs(psi[-1] - 2.5) < 1e-6
    assert _col(rows, "outliers_mag")[-1] == 1.0 and np.all(_col(rows, "nis_mag")[1:] < 1e-6)
    old = _run(_hover(30, 1.0, psi=2.5, zero=(0,)), heading_from_mag=0, **start)
    assert np.all(_col(old, "psi") == 0.0) and _col(old, "outliers_mag")[-1] == 30.0


def test_the_calibrated_offset_is_taken_off():
    """A hard-iron offset of (5, -3, 8) uT: the filter told the calibration's
    offset (``mag_bias_*``) finds the heading as with a clean field; not told,
    it refuses every sample (the offset is 14 standard deviations)."""
    start = {"P0_attitude": 0.05, "sigma_mag": 0.6e-6}
    offset = (5e-6, -3e-6, 8e-6)
    told = _run(_hover(20, 1.0, offset=offset), mag_bias_x=offset[0], mag_bias_y=offset[1], mag_bias_z=offset[2],
                **start)
    clean = _run(_hover(20, 1.0), **start)
    np.testing.assert_allclose(_col(told, "psi"), _col(clean, "psi"), atol=1e-12)
    assert abs(_col(told, "psi")[-1] - PSI) < 1e-6 and _col(told, "outliers_mag")[-1] == 0.0
    assert _col(_run(_hover(20, 1.0, offset=offset), **start), "outliers_mag")[-1] == 20.0


def test_a_heading_error_is_corrected_by_the_magnetometer():
    start = {"P0_attitude": 0.2, "sigma_mag": 0.6e-6,  # the start knows it does not know its heading
             "heading_from_mag": 0}  # and is not told it from the first sample (E28): the correction alone
    with_mag = _run(_hover(500, 1.0), **start)
    without = _run(_hover(500, 0.0), **start)  # fresh_mag = 0: the Estimator's filter (no magnetometer)
    assert abs(_col(with_mag, "psi")[-1] - PSI) < 1e-3
    assert np.sqrt(_col(with_mag, "var_psi")[-1]) < 0.01
    # without it, at hover nothing sees the heading: it stays where it started
    assert abs(_col(without, "psi")[-1]) < 1e-3 and _col(without, "var_psi")[-1] > 0.19 ** 2
    assert np.all(_col(without, "nis_mag") == 0.0)
    # its NIS is that of an exact field once converged (far below 3), and nothing was refused
    assert _col(with_mag, "outliers_mag")[-1] == 0.0


def test_a_disturbed_field_is_refused_counted_and_leaves_the_heading():
    start = {"P0_attitude": 0.2, "sigma_mag": 0.6e-6}
    clean = _run(_hover(400, 1.0, missing=(300,)), **start)  # as if that sample had never come
    disturbed = _run(_hover(400, 1.0, disturbed=(300,)), **start)
    assert _col(disturbed, "outliers_mag")[-1] == 1.0 and _col(clean, "outliers_mag")[-1] == 0.0
    assert _col(disturbed, "nis_mag")[300] > chi2_quantile_odd(3, 0.9999)
    for name in ("phi", "theta", "psi", "x", "u", "var_psi"):  # the refused sample changed nothing
        np.testing.assert_array_equal(_col(disturbed, name), _col(clean, name))
