"""The fix's error correlated in time as three more states of the filter
(issue 29, docs/estimation.md E27; the receiver GNSS6GM's E25): with its
size at 0 the filter is the 18-state one; a constant offset of the fix is
first taken partly as the receiver's error, in the ratio of the prior's
covariances, the NIS holding the error's covariance, then moved into the
position as the model lets the error decay; a run of refusals restarts the
error with the position; fixes with a true Gauss-Markov error have the NIS
of their degrees of freedom; and circles_estimated flies the receiver with
this filter, consistently."""
from __future__ import annotations

import math

import numpy as np

from fmu_models.models.estimator import ESTIMATOR, ESTIMATOR_GM, FIX_BIAS_STATES

from test_estimation_gating import outputs

DT = 0.01
G = 9.81
WHITE = {**{f"sigma_{a}_m": 0.01 for a in "xyz"}, **{f"sigma_{a}_m": 0.05 for a in "uvw"}}
OUTPUTS = [v.name for v in ESTIMATOR_GM.outputs]


def _rows(model, n, x_fix=lambda k: 0.0, every=10):
    """Inputs of a vehicle at rest at (0, 0, -10), level (exact IMU); a fix
    every ``every`` steps, its x ``x_fix(k)``, stamped when taken."""
    rows = np.zeros((n, len(model.inputs)))
    for k in range(n):
        rows[k] = model.input_values(acc_z=-G, x_m=x_fix(k), z_m=-10.0, fresh=float(k % every == 0),
                                     t_imu=k * DT, t_fix=k * DT)
    return rows


def _run(model, inputs, **parameters):
    """The model's outputs, row per step, from its FMU (the C of its CasADi step function)."""
    return outputs(model, inputs, {"z_0": -10.0, **WHITE, **parameters})


def _col(rows, name, model=ESTIMATOR_GM):
    return rows[:, [v.name for v in model.outputs].index(name)]


def test_without_a_correlated_error_the_filter_is_the_white_one():
    """gm_sigma = 0: the three states stay 0 with variance 0, and every output
    the two filters share is the 18-state filter's (a fix jump and a restart
    after refusals included), to round-off."""
    n = 700
    jump = lambda k: 3.0 if k >= 400 else 0.0  # off for good: refused, then the restart (E21)
    gm = _run(ESTIMATOR_GM, _rows(ESTIMATOR_GM, n, jump))
    white = _run(ESTIMATOR, _rows(ESTIMATOR, n, jump))
    assert _col(gm, "resets_fix")[-1] == 1.0
    for name in [v.name for v in ESTIMATOR.outputs]:
        np.testing.assert_allclose(_col(gm, name), _col(white, name, ESTIMATOR), rtol=1e-9, atol=1e-12,
                                   err_msg=name)
    for name in FIX_BIAS_STATES:
        assert np.all(_col(gm, name) == 0.0) and np.all(_col(gm, f"var_{name}") == 0.0)


def test_an_offset_is_shared_in_the_ratio_of_the_prior_and_its_nis_holds_the_error_covariance():
    """At rest, the fix 3 cm off along x at step 500 (the velocity fix made
    uninformative, so that the x channel decides alone): that fix's NIS is
    ``d^2 / s`` with ``s = P_pp + 2 P_pb + P_bb + r``, the receiver's error's
    covariance in it (the prior read from a twin run without that fix), the
    position taking ``(P_pp + P_pb) / s`` of the offset and the error
    ``(P_pb + P_bb) / s``."""
    at, d = 500, 0.03
    parameters = {"gm_tau": 1.0, **{f"gm_sigma_{a}_m": 0.02 for a in "xyz"}, **{f"sigma_{a}_m": 1.0e3 for a in "uvw"}}
    inputs = _rows(ESTIMATOR_GM, at + 1, lambda k: d if k >= at else 0.0)
    rows = _run(ESTIMATOR_GM, inputs, **parameters)
    inputs[at, [v.name for v in ESTIMATOR_GM.inputs].index("fresh")] = 0.0
    prior = _run(ESTIMATOR_GM, inputs, **parameters)
    P_pp, P_bb, P_pb = (_col(prior, name)[at] for name in ("var_x", "var_fix_bias_x", "cov_x_fix_bias_x"))
    r = WHITE["sigma_x_m"] ** 2
    s = P_pp + 2 * P_pb + P_bb + r
    assert P_pb < -0.1 * math.sqrt(P_pp * P_bb)  # the fixes saw their sum: their errors are anticorrelated
    assert abs(_col(rows, "nis_fix")[at] - d * d / s) < 1e-3 * d * d / s
    assert d * d / s > 1.5 * d * d / (P_pp + r)  # without the error's covariance: far off
    assert abs(_col(rows, "x")[at] - _col(prior, "x")[at] - d * (P_pp + P_pb) / s) < 1e-3 * d
    assert abs(_col(rows, "fix_bias_x")[at] - _col(prior, "fix_bias_x")[at] - d * (P_pb + P_bb) / s) < 1e-3 * d


def test_a_constant_offset_is_taken_as_the_receivers_error_then_moved_into_the_position():
    """At rest, the fix 3 cm off along x for good from step 500: the filter
    first takes a part of it as the receiver's correlated error (a jump the
    velocity fix does not see), then, as that error decays in its model
    (gm_tau), moves it into the position: half a gm_tau after the jump the
    error holds over a third of the offset, after 2 gm_tau a tenth to a
    half, after 10 under 3 %, the position then within 4 % of the offset.
    The white filter takes it into the position within half a second."""
    tau, d, at, n = 1.0, 0.03, 500, 1500
    offset = lambda k: d if k >= at else 0.0
    rows = _run(ESTIMATOR_GM, _rows(ESTIMATOR_GM, n, offset), gm_tau=tau,
                **{f"gm_sigma_{a}_m": 0.02 for a in "xyz"})
    bias, x = _col(rows, "fix_bias_x"), _col(rows, "x")
    half, two = at + round(tau / 2 / DT), at + round(2 * tau / DT)
    assert bias[half] > 0.33 * d and x[half] < 0.67 * d
    assert 0.1 * d < bias[two] < 0.5 * d
    assert abs(bias[-1]) < 0.03 * d and abs(x[-1] - d) < 0.04 * d
    white = _run(ESTIMATOR, _rows(ESTIMATOR, at + 50, offset))
    assert abs(_col(white, "x", ESTIMATOR)[-1] - d) < 0.1 * d


def test_a_run_of_refusals_restarts_the_correlated_error_with_the_position():
    """The fix 3 m off for good: after reset_after_fix refusals the position
    starts again from the fix, the receiver's error from its stationary prior
    N(0, gm_sigma^2), and the position's variance holds both, anticorrelated
    (the fix is their sum)."""
    sigma_gm, n = 0.02, 700
    rows = _run(ESTIMATOR_GM, _rows(ESTIMATOR_GM, n, lambda k: 3.0 if k >= 400 else 0.0),
                **{f"gm_sigma_{a}_m": sigma_gm for a in "xyz"})
    restart = int(np.argmax(_col(rows, "resets_fix") > 0))
    assert restart == 400 + 10 * (int(ESTIMATOR_GM.variable("reset_after_fix").start) - 1)
    assert abs(_col(rows, "x")[restart] - 3.0) < 1e-9 and _col(rows, "fix_bias_x")[restart] == 0.0
    # the restart's covariance, seen through the step's output (no prediction in feedthrough: t_imu = t)
    assert abs(_col(rows, "var_fix_bias_x")[restart] - sigma_gm ** 2) < 1e-12
    assert abs(_col(rows, "cov_x_fix_bias_x")[restart] + sigma_gm ** 2) < 1e-12
    assert abs(_col(rows, "var_x")[restart] - (WHITE["sigma_x_m"] ** 2 + sigma_gm ** 2)) < 1e-12
    assert abs(_col(rows, "x")[-1] - 3.0) < 0.02


def test_fixes_with_a_gauss_markov_error_have_the_nis_of_their_degrees_of_freedom():
    """At rest, every fix carrying the receiver's law (E25: white 1 cm plus a
    Gauss-Markov error of 3 cm, gm_tau 2 s) on all three axes: the mean NIS
    over the 100 fixes after 10 s is 6 for the filter that models the error
    (within 4.5 standard errors of the chi-square mean), while the white
    filter that takes only the white part sees far more than its 6."""
    rng = np.random.default_rng(5)
    tau, sigma_gm, n, every = 2.0, 0.03, 2000, 10
    a = math.exp(-DT / tau)
    e = np.zeros((n, 3))
    e[0] = sigma_gm * rng.standard_normal(3)
    for k in range(1, n):
        e[k] = a * e[k - 1] + sigma_gm * math.sqrt(1 - a * a) * rng.standard_normal(3)
    error = e + WHITE["sigma_x_m"] * rng.standard_normal((n, 3))
    velocity = 0.05 * rng.standard_normal((n, 3))

    def inputs(model):
        rows = _rows(model, n, every=every)
        names = [v.name for v in model.inputs]
        for j, axis in enumerate("xyz"):
            rows[:, names.index(f"{axis}_m")] += error[:, j]
            rows[:, names.index(f"{'uvw'[j]}_m")] += velocity[:, j]
        return rows

    gm = _run(ESTIMATOR_GM, inputs(ESTIMATOR_GM), gm_tau=tau, **{f"gm_sigma_{a}_m": sigma_gm for a in "xyz"})
    used = (_col(gm, "fix_used") > 0.5) & (np.arange(n) >= 1000)
    nis = _col(gm, "nis_fix")[used]
    assert len(nis) == 100
    assert abs(nis.mean() - 6.0) < 4.5 * math.sqrt(12.0 / len(nis)), nis.mean()
    white = _run(ESTIMATOR, inputs(ESTIMATOR)[:1200])
    fixes = (np.arange(1200) % every == 0) & (np.arange(1200) >= 1000)  # used or refused
    assert _col(white, "nis_fix", ESTIMATOR)[fixes].mean() > 2 * 6.0


def test_circles_estimated_flies_the_correlated_receiver_consistently():
    """circles_estimated flies GNSS6GM into EstimatorGM (E25, E27), the wind
    steady between the gust's steps and no vertical wind state. On seed 1
    the fix's NIS (a time average over about 450 fixes) and the drag
    measurement's (over the steady rows) sit inside the 20-seed study's
    bands (k = 6 and 2; over 20 seeds each run's were 5.75-6.61 and
    1.76-1.92), the position's NEES is that of a filter holding the
    receiver's error (a single run has one correlated error per axis: a
    loose bound), and the steady wind's NEES, of the horizontal wind's 2
    degrees of freedom, is finite and its error small."""
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master
    from quadrotor_paper.experiments import estimation_metrics

    scenario = load_scenario("circles_estimated", {"simulation.seed": 1})
    assert scenario.fmus["GNSS"]["model"] == "GNSS6GM" and scenario.fmus["Estimator"]["model"] == "EstimatorGM"
    with build_master(scenario) as master:
        metrics = estimation_metrics(scenario, master.run(scenario.duration))
    assert 4.58 < metrics["nis_fix"] < 7.61 and 1.22 < metrics["nis_acc"] < 2.97, metrics
    assert 0.5 < metrics["nees_position"] < 8.0 and 2.02 < metrics["nees_velocity"] < 4.16
    assert 0.3 < metrics["nees_wind"] < 6.0 and metrics["est_rmse_wind_settled_mps"] < 0.05
