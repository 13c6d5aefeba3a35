"""The FNN of section 4.1 against a plain-loop reference, and its initial values."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from fnn_controller.fnn import (ALPHA, AXIS_STATE_SIZE, C1, C2, F, N_MF, N_RULES, PRIMED, SIGMA1, SIGMA2,
                                X1_PREV, X2_PREV, FnnInit, firing_strength, fnn_output, initial_axis_expression,
                                membership, normalized_firing_strength)
from fnn_controller.position import FNN_STATE_SIZE, axis_slice, initial_fnn_state
from fnn_controller.variants.pd_lm import PD_LM

x1, x2 = ca.SX.sym("x1"), ca.SX.sym("x2")
c1, c2 = ca.SX.sym("c1", 3), ca.SX.sym("c2", 3)
s1, s2 = ca.SX.sym("s1", 3), ca.SX.sym("s2", 3)
f = ca.SX.sym("f", 9)
W = firing_strength(x1, x2, c1, c2, s1, s2)
W_BAR = normalized_firing_strength(x1, x2, c1, c2, s1, s2)
FORWARD = ca.Function("forward", [x1, x2, c1, c2, s1, s2, f],
                      [W, W_BAR, fnn_output(f, W_BAR)])


def reference_forward(x1, x2, c1, c2, sigma1, sigma2, f):
    """Eqs. (20)-(25) written as plain loops, rule k = (j - 1) J + i."""
    mu1 = [math.exp(-((x1 - c1[i]) ** 2) / sigma1[i] ** 2) for i in range(3)]  # eq. 21
    mu2 = [math.exp(-((x2 - c2[j]) ** 2) / sigma2[j] ** 2) for j in range(3)]  # eq. 22
    w = [0.0] * 9
    for i in range(3):
        for j in range(3):
            w[j * 3 + i] = mu1[i] * mu2[j]  # eq. 20
    total = sum(w)
    w_bar = [wk / total for wk in w]  # eq. 25
    tau_n = sum(f[k] * w[k] for k in range(9)) / total  # eq. 24, first form
    return np.array(w), np.array(w_bar), tau_n


@pytest.mark.parametrize("seed", range(20))
def test_forward_pass_matches_plain_loop_reference(seed):
    rng = np.random.default_rng(seed)
    args = (rng.uniform(-4, 4), rng.uniform(-40, 40), np.sort(rng.uniform(-4, 4, 3)),
            np.sort(rng.uniform(-40, 40, 3)), rng.uniform(0.5, 3, 3), rng.uniform(5, 30, 3),
            rng.uniform(-2, 2, 9))
    w, w_bar, tau_n = (np.array(v).ravel() for v in FORWARD(*args))
    w_ref, w_bar_ref, tau_n_ref = reference_forward(*args)
    np.testing.assert_allclose(w, w_ref, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(w_bar, w_bar_ref, rtol=1e-10)
    assert tau_n == pytest.approx(tau_n_ref, rel=1e-10, abs=1e-14)
    # normalized strengths sum to 1 and tau_n is their f-weighted average (eq. 24, second form)
    assert w_bar.sum() == pytest.approx(1.0, abs=1e-14)
    assert tau_n == pytest.approx(float(np.dot(args[-1], w_bar)), abs=1e-14)
    assert min(args[-1]) - 1e-14 <= tau_n <= max(args[-1]) + 1e-14


def test_rule_order_is_the_papers_k_equals_j_times_I_plus_i():
    # only MF i = 2 of x1 and j = 0 of x2 are near the input: rule k = 0 * 3 + 2 dominates
    w_bar = np.array(FORWARD(3.0, -30.0, [-3, 0, 3], [-30, 0, 30], [0.5] * 3, [5] * 3, np.zeros(9))[1]).ravel()
    assert np.argmax(w_bar) == 2 and w_bar[2] > 0.99


def test_membership_is_the_gaussian_of_eqs_21_22():
    mu = np.array(ca.Function("mu", [x1, c1, s1], [membership(x1, c1, s1)])(1.0, [1.0, 2.0, -1.0], [1.0, 2.0, 4.0])).ravel()
    np.testing.assert_allclose(mu, [1.0, math.exp(-0.25), math.exp(-0.25)], rtol=1e-15)


def test_normalized_strengths_stay_finite_when_every_strength_underflows():
    # narrow MFs far from the input: every W_ij = exp(-1e6) is 0 in floating point,
    # eq. 25 computed literally is 0/0; the shifted form still sums to 1
    args = (50.0, 150.0, [-3, 0, 3], [-30, 0, 30], [0.05] * 3, [0.5] * 3, np.arange(9.0))
    w, w_bar, tau_n = (np.array(v).ravel() for v in FORWARD(*args))
    assert np.all(w == 0.0)
    assert np.all(np.isfinite(w_bar)) and w_bar.sum() == pytest.approx(1.0)
    assert np.argmax(w_bar) == 2 * 3 + 2  # nearest MFs: i = 2, j = 2
    assert tau_n.item() == pytest.approx(8.0)


def test_initial_axis_state_has_the_values_of_section_5_1():
    state = np.array(ca.DM(initial_axis_expression(FnnInit(), np.random.default_rng(0).random(N_RULES)))).ravel()
    assert state.shape == (AXIS_STATE_SIZE,)
    np.testing.assert_array_equal(state[C1], [-3.0, 1e-4, 3.0])
    np.testing.assert_array_equal(state[C2], [-30.0, 1e-4, 30.0])
    np.testing.assert_array_equal(state[SIGMA1], [1.5] * N_MF)
    np.testing.assert_array_equal(state[SIGMA2], [15.0] * N_MF)
    assert state[ALPHA] == 0.001
    assert np.all((state[F] >= 0.0) & (state[F] <= 0.001)) and state[F].size == N_RULES
    assert state[X1_PREV] == state[X2_PREV] == state[PRIMED] == 0.0
    assert FnnInit().f_high == 0.001


def test_initial_weights_are_reproducible_per_seed_and_differ_between_seeds():
    a, b, c = initial_fnn_state(PD_LM, 7), initial_fnn_state(PD_LM, 7), initial_fnn_state(PD_LM, 8)
    assert a.shape == (FNN_STATE_SIZE,)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # the three axes get different draws from the one generator
    assert not np.array_equal(a[axis_slice(0)][F], a[axis_slice(1)][F])
    # a Generator is accepted as well, and no implicit global randomness
    np.testing.assert_array_equal(initial_fnn_state(PD_LM, np.random.default_rng(7)), a)
    with pytest.raises(TypeError):
        initial_fnn_state(PD_LM, None)
