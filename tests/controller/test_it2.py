"""The interval type-2 FNN (fnn_controller/it2.py) and its two variants:
forward pass and learning step against plain-loop references, reduction to
the type-1 FNN without uncertainty, the type reduction's bracket, the SMC
consequent law's known answer (eq. IT-8), the q law's sign (IT-9), bounds
under random inputs, and the closed loop learning away the ramp lag."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from fnn_controller.fast import FastFunction
from fnn_controller.fnn import firing_strength, fnn_output, normalized_firing_strength
from fnn_controller.it2 import (ALPHA, C1, C2, F, IT2_AXIS_STATE_SIZE, IT2_DEFAULTS, PRIMED, Q, SIGMA1, SIGMA2,
                                X1_PREV, X2_PREV, IT2Params, it2_learning_step, it2_normalized_firing_strengths,
                                it2_regressor, q_rate, type_reduction)
from fnn_controller.learning import AxisGains, LearningBounds, learning_step
from fnn_controller.position import initial_fnn_state, position_controller_function
from fnn_controller.position_parameters import PositionParams
from fnn_controller.variants import variant
from test_geometric import plant_fmu  # noqa: F401  (fixture)
from test_position import _ramp, fly

IT2_VARIANTS = ("pd+it2-smc", "pd+it2-lm")
PARAMS = PositionParams()
BOUNDS = LearningBounds()
DT = PARAMS.dt

# ------------------------------------------------------------- symbolic forward

def it2_membership(x, c, sigma, spread):
    """The definition the tests check the law against: lower and upper membership grades of one input (uncertain width).

    Returns ``(mu_lower, mu_upper)``, each of length I, with
    ``mu_lower = exp(-((x - c) / sigma)^2)`` (eqs. 21-22) and
    ``mu_upper = exp(-((x - c) / ((1 + d) sigma))^2)``; ``0 < mu_lower <= mu_upper <= 1``.
    """
    return ca.exp(-((x - c) / sigma) ** 2), ca.exp(-((x - c) / ((1 + spread) * sigma)) ** 2)


def it2_firing_strengths(x1, x2, c1, c2, sigma1, sigma2, spread):
    """The definition the tests check the law against: lower and upper firing strengths ``(W_lower, W_upper)`` of the I*J rules,
    product T-norm (eqs. 20, 23 for each bound), rule k = j * I + i."""
    return (firing_strength(x1, x2, c1, c2, sigma1, sigma2),
            firing_strength(x1, x2, c1, c2, (1 + spread) * sigma1, (1 + spread) * sigma2))



x1, x2, d, q = ca.SX.sym("x1"), ca.SX.sym("x2"), ca.SX.sym("d"), ca.SX.sym("q")
c1, c2 = ca.SX.sym("c1", 3), ca.SX.sym("c2", 3)
s1, s2 = ca.SX.sym("s1", 3), ca.SX.sym("s2", 3)
f = ca.SX.sym("f", 9)
W_LO, W_UP = it2_firing_strengths(x1, x2, c1, c2, s1, s2, d)
WB_LO, WB_UP = it2_normalized_firing_strengths(x1, x2, c1, c2, s1, s2, d)
TAU_N, Y_LO, Y_UP = type_reduction(f, WB_LO, WB_UP, q)
FORWARD = ca.Function("forward", [x1, x2, c1, c2, s1, s2, f, d, q],
                      [W_LO, W_UP, WB_LO, WB_UP, Y_LO, Y_UP, TAU_N, it2_regressor(WB_LO, WB_UP, q)])
TYPE1 = ca.Function("type1", [x1, x2, c1, c2, s1, s2, f],
                    [fnn_output(f, normalized_firing_strength(x1, x2, c1, c2, s1, s2))])


def reference_forward(x1, x2, c1, c2, sigma1, sigma2, f, d, q):
    """The IT2 FNN as plain loops, rule k = j * I + i: uncertain-width
    Gaussians (lower width sigma, upper (1 + d) sigma), product T-norm per
    bound, each bound normalized, q-factor type reduction (eq. IT-4)."""
    lo1 = [math.exp(-((x1 - c1[i]) ** 2) / sigma1[i] ** 2) for i in range(3)]
    up1 = [math.exp(-((x1 - c1[i]) ** 2) / ((1 + d) * sigma1[i]) ** 2) for i in range(3)]
    lo2 = [math.exp(-((x2 - c2[j]) ** 2) / sigma2[j] ** 2) for j in range(3)]
    up2 = [math.exp(-((x2 - c2[j]) ** 2) / ((1 + d) * sigma2[j]) ** 2) for j in range(3)]
    w_lo, w_up = [0.0] * 9, [0.0] * 9
    for i in range(3):
        for j in range(3):
            w_lo[j * 3 + i] = lo1[i] * lo2[j]
            w_up[j * 3 + i] = up1[i] * up2[j]
    y_lo = sum(f[k] * w_lo[k] for k in range(9)) / sum(w_lo)
    y_up = sum(f[k] * w_up[k] for k in range(9)) / sum(w_up)
    wb_lo = [w / sum(w_lo) for w in w_lo]
    wb_up = [w / sum(w_up) for w in w_up]
    return (np.array(w_lo), np.array(w_up), np.array(wb_lo), np.array(wb_up), y_lo, y_up,
            q * y_lo + (1 - q) * y_up)


def _random_forward_args(rng, d=None, q=None):
    return (rng.uniform(-4, 4), rng.uniform(-40, 40), np.sort(rng.uniform(-4, 4, 3)),
            np.sort(rng.uniform(-40, 40, 3)), rng.uniform(0.5, 3, 3), rng.uniform(5, 30, 3),
            rng.uniform(-2, 2, 9), rng.uniform(0, 1) if d is None else d, rng.uniform(0, 1) if q is None else q)


def _forward(*args):
    return [np.array(v).ravel() for v in FORWARD(*args)]


@pytest.mark.parametrize("seed", range(20))
def test_forward_pass_matches_plain_loop_reference(seed):
    args = _random_forward_args(np.random.default_rng(seed))
    w_lo, w_up, wb_lo, wb_up, y_lo, y_up, tau_n, w_q = _forward(*args)
    ref = reference_forward(*args)
    np.testing.assert_allclose(w_lo, ref[0], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(w_up, ref[1], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(wb_lo, ref[2], rtol=1e-10)
    np.testing.assert_allclose(wb_up, ref[3], rtol=1e-10)
    assert y_lo.item() == pytest.approx(ref[4], rel=1e-10, abs=1e-14)
    assert y_up.item() == pytest.approx(ref[5], rel=1e-10, abs=1e-14)
    assert tau_n.item() == pytest.approx(ref[6], rel=1e-10, abs=1e-14)
    # the regressor W_bar_q (IT-5) sums to 1 and tau_n = f . W_bar_q
    assert w_q.sum() == pytest.approx(1.0, abs=1e-14)
    assert tau_n.item() == pytest.approx(float(args[6] @ w_q), abs=1e-14)
    # uncertain width: the upper MF is above the lower one everywhere
    assert np.all(w_up >= w_lo)


def test_membership_bounds_are_the_two_gaussians():
    mu = ca.Function("mu", [x1, c1, s1, d], list(it2_membership(x1, c1, s1, d)))
    lo, up = (np.array(v).ravel() for v in mu(1.0, [1.0, 2.0, -1.0], [1.0, 2.0, 4.0], 1.0))
    np.testing.assert_allclose(lo, [1.0, math.exp(-0.25), math.exp(-0.25)], rtol=1e-15)
    np.testing.assert_allclose(up, [1.0, math.exp(-0.25 / 4), math.exp(-0.25 / 4)], rtol=1e-15)


@pytest.mark.parametrize("seed", range(10))
def test_without_uncertainty_the_it2_fnn_is_the_type1_fnn(seed):
    """d = 0: lower = upper MF, so for every q the output is eq. 24's."""
    rng = np.random.default_rng(seed)
    for q_value in (0.0, rng.uniform(), 1.0):
        args = _random_forward_args(rng, d=0.0, q=q_value)
        _, _, wb_lo, wb_up, y_lo, y_up, tau_n, _ = _forward(*args)
        type1 = float(TYPE1(*args[:7]))
        np.testing.assert_array_equal(wb_lo, wb_up)
        assert tau_n.item() == pytest.approx(type1, rel=1e-14, abs=1e-15)


@pytest.mark.parametrize("seed", range(20))
def test_type_reduction_lies_between_the_lower_and_upper_weighted_averages(seed):
    args = _random_forward_args(np.random.default_rng(seed))
    _, _, _, _, y_lo, y_up, tau_n, _ = _forward(*args)
    lo, hi = min(y_lo.item(), y_up.item()), max(y_lo.item(), y_up.item())
    assert lo - 1e-14 <= tau_n.item() <= hi + 1e-14
    # q = 1 is the lower average, q = 0 the upper one
    assert _forward(*args[:8], 1.0)[6].item() == pytest.approx(y_lo.item(), abs=1e-15)
    assert _forward(*args[:8], 0.0)[6].item() == pytest.approx(y_up.item(), abs=1e-15)


# ---------------------------------------------------------------- learning laws

def _sym_step(rule, spread, gamma, nu, alpha_bar, gamma_q, phi):
    state = ca.SX.sym("state", IT2_AXIS_STATE_SIZE)
    xs1, xs2, tc = ca.SX.sym("x1"), ca.SX.sym("x2"), ca.SX.sym("tau_c")
    wl, wu = it2_normalized_firing_strengths(xs1, xs2, state[C1], state[C2], state[SIGMA1], state[SIGMA2], spread)
    nxt = it2_learning_step(AxisGains(rule, DT, gamma, nu, alpha_bar, BOUNDS, phi), gamma_q, state, xs1, xs2, tc, wl, wu)
    return ca.Function("step", [state, xs1, xs2, tc], [nxt])


def reference_step(rule, state, x1, x2, tau_c, spread, gamma, nu, alpha_bar, gamma_q, phi):
    """One step of eqs. IT-6 ... IT-11 as plain loops (forward Euler, floors and projections)."""
    b = BOUNDS
    s = np.array(state, float)
    c1, c2, sig1, sig2 = s[C1], s[C2], s[SIGMA1], s[SIGMA2]
    f, alpha, q, primed = s[F], s[ALPHA], s[Q], s[PRIMED]
    sw = np.sign(tau_c) if phi == 0 else min(1.0, max(-1.0, tau_c / phi))
    _, _, wb_lo, wb_up, y_lo, y_up, _ = reference_forward(x1, x2, c1, c2, sig1, sig2, f, spread, q)
    out = s.copy()
    for i in range(3):
        out[C1][i] = np.clip(c1[i] + primed * (x1 - s[X1_PREV]), -b.c1_max, b.c1_max)
        out[C2][i] = np.clip(c2[i] + primed * (x2 - s[X2_PREV]), -b.c2_max, b.c2_max)
    for sl, x, c, sig, lo, hi in ((SIGMA1, x1, c1, sig1, b.sigma1_min, b.sigma1_max),
                                  (SIGMA2, x2, c2, sig2, b.sigma2_min, b.sigma2_max)):
        for i in range(3):
            rate = -sig[i] ** 3 / max((x - c[i]) ** 2, (b.a_min * sig[i]) ** 2) * alpha * sw
            out[sl][i] = np.clip(sig[i] + DT * rate, lo, hi)
    w_q = [q * wb_lo[k] + (1 - q) * wb_up[k] for k in range(9)]
    ww = sum(w * w for w in w_q)
    for k in range(9):
        if rule == "smc":
            f_dot = -w_q[k] / ww * alpha * sw
        else:
            f_dot = -gamma * w_q[k] / (max(ww, alpha_bar) + ww) * sw
        out[F][k] = np.clip(f[k] + DT * f_dot, -b.f_max, b.f_max)
    if rule == "smc":
        out[ALPHA] = np.clip(alpha + DT * (gamma * abs(tau_c) - gamma * nu * alpha), 0.0, b.alpha_max)
    out[Q] = np.clip(q - DT * gamma_q * (y_lo - y_up) * sw, 0.0, 1.0)
    out[X1_PREV], out[X2_PREV], out[PRIMED] = x1, x2, 1.0
    return out


def _random_state(rng):
    s = np.zeros(IT2_AXIS_STATE_SIZE)
    s[C1] = np.sort(rng.uniform(-4, 4, 3))
    s[C2] = np.sort(rng.uniform(-40, 40, 3))
    s[SIGMA1], s[SIGMA2] = rng.uniform(0.5, 3, 3), rng.uniform(5, 30, 3)
    s[F] = rng.uniform(-2, 2, 9)
    s[ALPHA], s[Q] = rng.uniform(0, 2), rng.uniform(0, 1)
    s[X1_PREV], s[X2_PREV], s[PRIMED] = rng.uniform(-4, 4), rng.uniform(-40, 40), rng.choice([0.0, 1.0])
    return s


@pytest.mark.parametrize("rule", ["smc", "lm"])
@pytest.mark.parametrize("phi", [0.0, 0.3])
def test_learning_step_matches_plain_loop_reference(rule, phi):
    rng = np.random.default_rng(17)
    spread, gamma, nu, alpha_bar, gamma_q = 0.3, 1.5, 0.85, 1.1, 2.0
    step = _sym_step(rule, spread, gamma, nu, alpha_bar, gamma_q, phi)
    for _ in range(10):
        state = _random_state(rng)
        x1v, x2v = rng.uniform(-4, 4), rng.uniform(-40, 40)
        for tau_c in (rng.uniform(-2, 2), 0.1, -0.05, 0.0):
            got = np.array(step(state, x1v, x2v, tau_c)).ravel()
            ref = reference_step(rule, state, x1v, x2v, tau_c, spread, gamma, nu, alpha_bar, gamma_q, phi)
            np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("rule", ["smc", "lm"])
def test_without_uncertainty_the_learning_step_is_the_type1_step(rule):
    """d = 0: W_bar_lower = W_bar_upper = W_bar, so c, sigma, f and alpha move
    exactly as under eqs. 33-38 / 57-62, and q stands still (y_lower = y_upper)."""
    from fnn_controller.fnn import AXIS_STATE_SIZE

    rng = np.random.default_rng(2)
    step = _sym_step(rule, 0.0, 1.5, 0.85, 1.1, 2.0, 0.0)
    t1 = ca.SX.sym("s", AXIS_STATE_SIZE)
    xs1, xs2, tc = ca.SX.sym("x1"), ca.SX.sym("x2"), ca.SX.sym("tau_c")
    w_bar = normalized_firing_strength(xs1, xs2, t1[0:3], t1[3:6], t1[6:9], t1[9:12])
    type1 = ca.Function("t1", [t1, xs1, xs2, tc], [learning_step(AxisGains(rule, DT, 1.5, 0.85, 1.1), t1, xs1, xs2, tc, w_bar)])
    for _ in range(10):
        state = _random_state(rng)
        x1v, x2v, tau_c = rng.uniform(-4, 4), rng.uniform(-40, 40), rng.uniform(-2, 2)
        got = np.array(step(state, x1v, x2v, tau_c)).ravel()
        ref = np.array(type1(np.delete(state, Q), x1v, x2v, tau_c)).ravel()
        np.testing.assert_allclose(np.delete(got, Q), ref, rtol=1e-13, atol=1e-15)
        assert got[Q] == pytest.approx(state[Q], abs=1e-14)


@pytest.mark.parametrize("seed", range(10))
def test_smc_consequent_law_moves_tau_n_at_minus_alpha_sgn(seed):
    """eq. IT-8 in IT-3 with the strengths and q fixed: sum f_dot W_bar_q = -alpha sgn(tau_c)."""
    rng = np.random.default_rng(seed)
    step = _sym_step("smc", 0.3, 1.5, 0.85, 1.1, 0.0, 0.0)
    state = _random_state(rng)
    x1v, x2v = rng.uniform(-4, 4), rng.uniform(-40, 40)
    _, _, _, _, _, _, _, w_q = _forward(x1v, x2v, state[C1], state[C2], state[SIGMA1], state[SIGMA2], state[F], 0.3,
                                        state[Q])
    state[F] = 0.0  # away from the f box
    for tau_c, expected in ((0.3, -state[ALPHA]), (-4.0, state[ALPHA]), (0.0, 0.0)):
        f_dot = (np.array(step(state, x1v, x2v, tau_c)).ravel()[F] - state[F]) / DT
        assert f_dot @ w_q == pytest.approx(expected, rel=1e-10, abs=1e-12)


@pytest.mark.parametrize("seed", range(10))
def test_q_law_never_increases_the_lyapunov_function(seed):
    """IT-9: tau_c (y_lower - y_upper) q_dot = -gamma_q |tau_c| (y_lower - y_upper)^2 <= 0."""
    rng = np.random.default_rng(seed)
    yl, yu, tc, gq = ca.SX.sym("yl"), ca.SX.sym("yu"), ca.SX.sym("tc"), ca.SX.sym("gq")
    rate = ca.Function("q", [yl, yu, tc, gq], [q_rate(yl, yu, tc, gq)])
    for _ in range(20):
        y_lo, y_up, tau_c, gamma_q = rng.normal(size=4)
        gamma_q = abs(gamma_q)
        q_dot = float(rate(y_lo, y_up, tau_c, gamma_q))
        assert tau_c * (y_lo - y_up) * q_dot == pytest.approx(-gamma_q * abs(tau_c) * (y_lo - y_up) ** 2, rel=1e-14)


def test_it2_parameters_are_validated_and_nested_in_the_position_parameters():
    assert PARAMS.it2 == IT2_DEFAULTS
    assert PositionParams(it2=IT2Params(spread=0.5)).it2.spread == 0.5
    with pytest.raises(ValueError, match="q0"):
        IT2Params(q0=1.5)
    with pytest.raises(ValueError, match="spread"):
        IT2Params(spread=-0.1)


# ------------------------------------------------------------------ the variants

@pytest.mark.parametrize("name", IT2_VARIANTS)
def test_initial_axis_state_has_the_type1_values_and_q0(name):
    v = variant(name)
    state = initial_fnn_state(v, 3, PARAMS).reshape(3, v.axis_state_size)
    type1 = initial_fnn_state(variant("pd+lm"), 3, PARAMS).reshape(3, 25)
    np.testing.assert_array_equal(np.delete(state, Q, axis=1), type1)  # same draws of f_ij(0)
    assert np.all(state[:, Q] == IT2_DEFAULTS.q0)
    assert [p for p, _ in v.axis_state_ports][Q] == "q"


FAST = {name: FastFunction(position_controller_function(variant(name)), state=("fnn_state", "fnn_state_next"))
        for name in IT2_VARIANTS}


@pytest.mark.parametrize("name", IT2_VARIANTS)
@pytest.mark.parametrize("seed, scale", [(0, 0.01), (1, 1.0), (2, 30.0), (3, 1e3)])
def test_parameters_stay_in_their_bounds_and_outputs_finite_under_random_inputs(name, seed, scale):
    rng = np.random.default_rng(seed)
    n = 1500
    e = np.cumsum(rng.normal(0, 0.05 * scale, (n, 3)), axis=0) + rng.choice([0, 1], (n, 3), p=[0.98, 0.02]) \
        * rng.normal(0, 5 * scale, (n, 3))
    e_dot = rng.normal(0, scale, (n, 3)) * rng.choice([1.0, 10.0], (n, 3), p=[0.9, 0.1])
    zero = rng.random(n) < 0.2
    e[zero], e_dot[zero] = 0.0, 0.0
    ff = FAST[name]
    ff.state[:] = initial_fnn_state(variant(name), rng, PARAMS)
    low, high = variant(name).axis_state_bounds(PARAMS)
    for k in range(n):
        ff.inputs["e"][:] = e[k]
        ff.inputs["e_dot"][:] = e_dot[k]
        ff.evaluate()
        ff.commit()
        s = ff.state.reshape(3, IT2_AXIS_STATE_SIZE)
        assert np.all(np.isfinite(s)) and np.all((s >= low) & (s <= high)), k
        tau_n = ff.outputs["tau_n"]
        assert np.all(np.isfinite(ff.outputs["v_ref"])) and np.all(np.abs(tau_n) <= BOUNDS.f_max * (1 + 1e-12))


@pytest.mark.parametrize("name", IT2_VARIANTS)
def test_fnn_learns_the_missing_feed_forward_and_takes_over(plant_fmu, name):  # noqa: F811
    """As the type-1 variants do (test_position): the 2.5 m/s ramp lag of the
    PD (1.056 m) is learned away and the IT2 FNN carries the command."""
    log = fly(plant_fmu, name, *_ramp(2.5), 30.0, seed=1)
    e_x = 2.5 * log["t"] - log["x"][:, 0]
    late = log["t"][:-1] >= 20.0
    assert np.abs(e_x[1:][late]).max() < 0.15
    share = np.abs(log["tau_n"][late, 0]) / (np.abs(log["tau_c"][late, 0]) + np.abs(log["tau_n"][late, 0]))
    assert share.mean() > 0.9
    assert np.all(np.isfinite(log["x"]))
