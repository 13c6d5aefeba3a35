"""The motion capture's attitude (issue 29, docs/estimation.md "The lab's
attitude", E29-E31): a heading error corrected by the motion capture's
frames on a known answer, a mislabelled frame refused and counted without a
trace, a rigid body redefined restarting the attitude after its run of
refusals, the extrapolated rate's noise in the output predictor, and the
lab in libcosim's ordering on seeds its attitude NEES was out of band on."""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from fmu_models.models.estimator import ESTIMATOR_MOCAP, chi2_quantile_odd

from test_estimation_gating import DT, G, outputs

PSI = 0.15  # rad: the true heading; the filter starts at 0
OUTPUTS = [v.name for v in ESTIMATOR_MOCAP.outputs]
SIGMA = {"sigma_phi_m": 7.1e-4, "sigma_theta_m": 7.1e-4, "sigma_psi_m": 5.0e-4,
         **{f"sigma_{a}_m": 1e-4 for a in "xyz"}, **{f"sigma_{a}_m": 0.017 for a in "uvw"}}  # the lab's OptiTrack


def _run(inputs, **parameters):
    """EstimatorMocap's outputs, row per step, from its FMU (the C of its
    CasADi step function), with the lab's motion-capture noise, at hover 10 m up."""
    return outputs(ESTIMATOR_MOCAP, inputs, {"z_0": -10.0, **SIGMA, **parameters})


def _col(rows, name):
    return rows[:, OUTPUTS.index(name)]


def _hover(n, psi=PSI, frames=None, imu_lag=0, omega=-1.0):
    """A vehicle hovering at (0, 0, -10), level, heading ``psi``: exact IMU
    (``imu_lag`` steps late, with its stamp) and an exact motion-capture
    frame every step, whose heading at step k is ``frames.get(k, psi)``;
    rotor commands ``omega`` (-1: unconnected)."""
    frames = frames or {}
    rows = []
    for k in range(n):
        rows.append(ESTIMATOR_MOCAP.input_values(
            acc_z=-G, z_m=-10.0, fresh=1.0, t_imu=max(k - imu_lag, 0) * DT, t_fix=max(k - imu_lag, 0) * DT,
            psi_m=frames.get(k, psi), **{f"Omega_{i}": omega for i in range(1, 5)}))
    return np.array(rows)


def test_a_heading_error_is_corrected_by_the_motion_capture_attitude():
    """Known answer: started 0.15 rad off its heading (and knowing it, 0.2
    rad), the filter takes the frames' heading within a step (the frame's
    0.5 mrad against 200 mrad) and keeps it (to 1e-7 rad); its variance falls
    to the frames' own order; the exact frames' NIS is far below 3."""
    rows = _run(_hover(200), P0_attitude=0.2)
    psi = _col(rows, "psi")
    assert abs(psi[0] - PSI) < 1e-5 and abs(psi[-1] - PSI) < 1e-7
    assert np.sqrt(_col(rows, "var_psi")[-1]) < 5.0e-4
    assert np.all(_col(rows, "nis_attitude")[1:] < 1e-5)
    assert _col(rows, "outliers_attitude")[-1] == 0.0 and _col(rows, "resets_attitude")[-1] == 0.0


def test_a_mislabelled_frame_is_refused_counted_and_leaves_no_trace():
    """One frame's heading 0.5 rad off (a rigid body the motion capture
    mislabels): refused by the chi-square gate (3 degrees of freedom),
    counted, and whatever its value (0.5 or 1.0 rad off) the estimate is bit
    for bit the same: a refused attitude changes nothing."""
    start = {"P0_attitude": 0.2}
    off = _run(_hover(150, frames={100: PSI + 0.5}), **start)
    further = _run(_hover(150, frames={100: PSI + 1.0}), **start)
    assert _col(off, "nis_attitude")[100] > chi2_quantile_odd(3, 0.9999)
    assert _col(off, "outliers_attitude")[-1] == 1.0 and _col(off, "outliers_attitude")[99] == 0.0
    for name in ("phi", "theta", "psi", "x", "u", "var_psi", "gyro_bias_z"):
        np.testing.assert_array_equal(_col(off, name), _col(further, name))
    assert abs(_col(off, "psi")[100] - PSI) < 1e-7  # the fix of that frame was used, its attitude was not


def test_a_redefined_rigid_body_restarts_the_attitude_after_its_run_of_refusals():
    """From step 50 every frame says the heading is 1 rad more (the rigid
    body redefined): refused ``reset_after_attitude`` (5) times, then the
    attitude starts again from the frame, at its noise, and is kept."""
    rows = _run(_hover(80, frames={k: PSI + 1.0 for k in range(50, 80)}), P0_attitude=0.2)
    outliers, resets = _col(rows, "outliers_attitude"), _col(rows, "resets_attitude")
    assert outliers[53] == 4.0 and resets[53] == 0.0 and abs(_col(rows, "psi")[53] - PSI) < 1e-6
    assert outliers[54] == 5.0 and resets[54] == 1.0
    assert abs(_col(rows, "psi")[54] - (PSI + 1.0)) < 1e-9
    assert _col(rows, "var_psi")[54] == pytest.approx(5.0e-4 ** 2, rel=1e-6)
    assert outliers[-1] == 5.0 and resets[-1] == 1.0 and abs(_col(rows, "psi")[-1] - (PSI + 1.0)) < 1e-7


def test_the_output_predictor_counts_the_extrapolated_rate_noise():
    """E31 on a known answer: with the IMU and the frames a step late (a
    Jacobi importer) the output is the posterior predicted one step (E23,
    E26), over which the rate is extrapolated from the last two gyro
    samples: ``1.5 g_n - 0.5 g_(n-1)`` with the rotor commands connected,
    ``2 g_n - g_(n-1)`` along the IMU's trend, white variances 2.5 and 5
    times a sample's ``N_g^2 / dt``. Level, the heading takes it whole: the
    two late runs' heading variances differ by ``dt^2 (5 - 2.5) N_g^2 / dt``;
    on time nothing is predicted and they are equal."""
    n_g2 = 2.4e-4 ** 2 / DT  # the gyro's white variance per sample (the IMU's default density)
    command, trend = (_col(_run(_hover(30, imu_lag=1, omega=omega)), "var_psi") for omega in (300.0, -1.0))
    np.testing.assert_allclose(trend[2:] - command[2:], DT ** 2 * (5.0 - 2.5) * n_g2, rtol=1e-6)
    np.testing.assert_array_equal(*(_col(_run(_hover(30, omega=omega)), "var_psi") for omega in (300.0, -1.0)))


@pytest.mark.parametrize("seed", [6, 7])
def test_the_lab_in_the_exchange_ordering_has_its_attitude_nees_in_band(tmp_path, seed):
    """``figure8_lab_estimated`` (IMU and the OptiTrack's pose) in libcosim's
    ordering on two seeds its attitude NEES was out of band on with the
    magnetometer (5.66 and 5.03): the attitude, velocity and position NEES
    inside Bar-Shalom's band for k = 3 over 20 runs, [2.02, 4.16], the
    attitude's NIS near its 3 degrees of freedom, and the counts in the
    summary and its page."""
    from quadrotor_paper.cli import main

    out = tmp_path / "r"
    assert main(["run", "figure8_lab_estimated", "--set", f"simulation.seed={seed}", "--set",
                 "simulation.ordering=exchange", "--out", str(out), "--quiet", "--no-plots"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for block in ("attitude", "velocity", "position"):
        assert 2.02 <= summary[f"nees_{block}"] <= 4.16, (block, summary[f"nees_{block}"])
    assert summary["outliers_attitude"] <= 3 and summary["resets_attitude"] == 0
    assert f"motion-capture attitudes refused {summary['outliers_attitude']:.0f}" in (out / "summary.md").read_text()


@pytest.mark.parametrize("dof, said", [(2.0, "(3, 3, 3 and 2 when consistent)"), (3.0, "(3 each when consistent)"),
                                       (None, "(3 each when consistent)")])
def test_the_run_summary_says_what_a_consistent_wind_nees_is(dof, said):
    """The summary line's consistent values: 3 for position, velocity and
    attitude, the wind's own count (``nees_wind_dof``: 2 without a vertical
    wind state, as ``circles_estimated``'s filter; 3 with one, as the lab's;
    3 when the wind was judged on no row)."""
    from quadrotor_paper.run_summary import summary_lines

    summary = {"status": "ok", "error": None, "seed": 0, "variant": None, "wall_time_s": 1.0,
               "real_time_factor": 50.0, "nees_position": 3.0, "nees_velocity": 3.0, "nees_attitude": 3.0,
               "nees_wind": 2.0, "nees_wind_dof": dof, "nis_fix": 6.0}
    lines = summary_lines(SimpleNamespace(name="m", description="d"), SimpleNamespace(span=(0.0, 50.0)), summary,
                          [], None)
    estimate = next(line for line in lines if line.startswith("- estimate:"))
    assert said in estimate
