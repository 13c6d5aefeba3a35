"""``calibrate`` on a sensed log of an X frame with rotor aerodynamics in a
constant wind (issue 42's "Done when", cheap form: one seed, a short log, few
names; the 20-seed coverage of every parameter is
``benchmarks/calibration_coverage.py --aero``): the rotor coefficients
recovered within their 95 % intervals, and the same log fitted with the
aerodynamics left out leaves residuals far from white."""
from __future__ import annotations

import numpy as np
import pytest

from quadrotor_paper.synthetic_log import HIDDEN_X_AERO, WIND, fly_sensed_log, sensed_column_map

AERO = ("k_rotor_drag", "k_inflow", "k_translational_lift")


@pytest.fixture(scope="module")
def x_aero_log(tmp_path_factory):
    return fly_sensed_log(tmp_path_factory.mktemp("x_aero"), seed=1, duration=2.0, hidden=HIDDEN_X_AERO)


def _calibrate(log, fit, guess, fix):
    from cosim.calibration import CalibrationSettings, calibrate
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model

    fmu = built_fmu("Quadrotor", 2, lambda: model("Quadrotor"))
    fixed = {k: v for k, v in HIDDEN_X_AERO.items() if k not in fit} | {"z_0": -15.0} | fix
    return calibrate(log, fmu, CalibrationSettings(fit=list(fit), guess=guess, fix=fixed, segment=2.0, holdout=0.0,
                                                   initial_states="estimated"), sensed_column_map())


def test_the_x_frame_rotor_coefficients_are_recovered_within_their_intervals(x_aero_log):
    fit = (*AERO, "wind_x", "wind_y")
    cal = _calibrate(x_aero_log, fit, {"k_rotor_drag": 1e-4, "k_inflow": 1e-4, "k_translational_lift": 0.005}, {})
    assert cal.converged
    truth = {**HIDDEN_X_AERO, **WIND}
    for j, name in enumerate(fit):
        lo, hi = cal.stats.ci95[j]
        assert lo <= truth[name] <= hi, (name, cal.fit.theta[j], lo, hi)
        assert hi - lo < 0.5 * abs(truth[name]), name  # an interval that says something
    # and the velocity residuals are white: |r1| within a few 1/sqrt(n) of 0 (n = 200 samples)
    assert max(abs(cal.residuals[v]["lag1_autocorrelation"]) for v in ("u", "v", "w")) < 0.3


@pytest.mark.slow  # a second fit with estimated initial states: about 5 CPU-s
def test_the_same_log_without_the_rotor_aerodynamics_leaves_correlated_residuals(x_aero_log):
    """The aerodynamics left out (k_* fixed at 0), the thrust coefficient and the
    wind fitted: the velocity residuals' lag-1 autocorrelation is far above the
    level of white noise (|r1| < 3 / sqrt(n)), as the fit with them is not."""
    fit = ("b", "wind_x", "wind_y")
    cal = _calibrate(x_aero_log, fit, {}, dict.fromkeys(AERO, 0.0))
    lag1 = {name: r["lag1_autocorrelation"] for name, r in cal.residuals.items()}
    n = 200  # samples of the 2 s log at the 10 ms step
    velocities = [lag1[v] for v in ("u", "v", "w")]
    assert min(velocities) > 0.5 > 3 / np.sqrt(n) and max(velocities) > 0.9, lag1
