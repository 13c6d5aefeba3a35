"""SMC (Theorem 1) and LM (Theorem 3) learning laws: known answers, the
rank-one identity, convergence on a test plant with an unknown constant
disturbance, the Lyapunov derivative of eq. 64, and the parameter bounds
under randomized inputs."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fnn_controller.fast import FastFunction
from fnn_controller.fnn import (ALPHA, AXIS_STATE_SIZE, C1, C2, F, PRIMED, SIGMA1, SIGMA2, X1_PREV, X2_PREV,
                                normalized_firing_strength)
from fnn_controller.learning import (AxisGains, LearningBounds, learning_step, lm_delta, lm_f_rate, sigma_rate,
                                     smc_f_rate)
from fnn_controller.position import axis_slice, initial_fnn_state, position_controller_function
from fnn_controller.position_parameters import PositionParams
from fnn_controller.variants import variant as lookup
from fnn_controller.variants.pd_lm import PD_LM

PARAMS = PositionParams()
DT = PARAMS.dt

# ---------------------------------------------------------------- known answers

w_sym = ca.SX.sym("w", 9)
tau_c_sym, alpha_sym = ca.SX.sym("tau_c"), ca.SX.sym("alpha")
gamma_sym, alpha_bar_sym = ca.SX.sym("gamma"), ca.SX.sym("alpha_bar")
LM_RATE = ca.Function("lm", [w_sym, tau_c_sym, gamma_sym, alpha_bar_sym],
                      [lm_f_rate(w_sym, tau_c_sym, gamma_sym, alpha_bar_sym), lm_delta(w_sym, alpha_bar_sym)])
SMC_RATE = ca.Function("smc", [w_sym, alpha_sym, tau_c_sym], [smc_f_rate(w_sym, alpha_sym, tau_c_sym)])


def random_w_bar(rng):
    w = rng.exponential(size=9) ** rng.uniform(0.5, 6)  # from flat to one dominant rule
    return w / w.sum()


@pytest.mark.parametrize("seed", range(25))
def test_lm_rank_one_identity_equals_the_explicit_solve_of_eq_61(seed):
    rng = np.random.default_rng(seed)
    w_bar = random_w_bar(rng)
    alpha_bar = rng.choice([0.0, 1e-3, 0.9, 1.1, 5.0])
    gamma, tau_c = rng.uniform(0.1, 3), rng.choice([-2.3, 0.7])
    delta = max(w_bar @ w_bar, alpha_bar)  # eq. 62
    explicit = -gamma * np.linalg.solve(np.outer(w_bar, w_bar) + delta * np.eye(9), w_bar) * np.sign(tau_c)
    rate, delta_ca = LM_RATE(w_bar, tau_c, gamma, alpha_bar)
    assert float(delta_ca) == pytest.approx(delta, rel=1e-15)
    np.testing.assert_allclose(np.array(rate).ravel(), explicit, rtol=1e-10, atol=1e-15)


@pytest.mark.parametrize("seed", range(10))
def test_smc_consequent_law_moves_tau_n_at_minus_alpha_sgn(seed):
    # eq. 37 in eq. 45 with W_bar fixed gives sum_ij f_dot W_bar = -alpha sgn(tau_c) (eq. 48)
    rng = np.random.default_rng(seed)
    w_bar, alpha = random_w_bar(rng), rng.uniform(1e-3, 5)
    for tau_c, expected in ((0.3, -alpha), (-4.0, alpha), (0.0, 0.0)):
        f_dot = np.array(SMC_RATE(w_bar, alpha, tau_c)).ravel()
        assert f_dot @ w_bar == pytest.approx(expected, rel=1e-12, abs=1e-15)


def test_sigma_law_is_the_papers_away_from_the_floor_and_floored_near_it():
    x, c, s = ca.SX.sym("x"), ca.SX.sym("c", 3), ca.SX.sym("s", 3)
    law = ca.Function("s", [x, c, s, alpha_sym, tau_c_sym], [sigma_rate(x, c, s, alpha_sym, tau_c_sym, 0.5)])
    c_val, s_val, alpha, tau_c = np.array([-3.0, 1e-4, 3.0]), np.array([1.5, 1.5, 1.5]), 0.2, -1.0
    rate = np.array(law(0.0, c_val, s_val, alpha, tau_c)).ravel()
    paper = -s_val**3 / (0.0 - c_val) ** 2 * alpha * np.sign(tau_c)  # eq. 35
    np.testing.assert_allclose(rate[[0, 2]], paper[[0, 2]], rtol=1e-15)  # |A| = 2 >= a_min
    assert rate[1] == pytest.approx(-(1.5**3) / (0.5 * 1.5) ** 2 * alpha * -1.0)  # |A| ~ 7e-5: floored
    assert abs(paper[1]) > 1e6 * abs(rate[1])


def _axis_step(rule, state, x1, x2, tau_c, gamma=1.5, nu=0.85, alpha_bar=1.1):
    state_sym = ca.SX.sym("state", AXIS_STATE_SIZE)
    w_bar = normalized_firing_strength(x1, x2, state_sym[C1], state_sym[C2], state_sym[SIGMA1], state_sym[SIGMA2])
    step = learning_step(AxisGains(rule, DT, gamma, nu, alpha_bar), state_sym, x1, x2, tau_c, w_bar)
    return np.array(ca.Function("step", [state_sym], [step])(state)).ravel()


@pytest.mark.parametrize("rule", ["smc", "lm"])
def test_sgn_of_zero_learns_nothing(rule):
    state = initial_fnn_state(PD_LM, 3)[axis_slice(0)]
    state[PRIMED], state[X1_PREV], state[X2_PREV] = 1.0, 0.2, -1.0
    nxt = _axis_step(rule, state, 0.2, -1.0, 0.0)
    for part in (C1, C2, SIGMA1, SIGMA2, F):
        np.testing.assert_array_equal(nxt[part], state[part])
    # alpha decays by eq. 38 under SMC, is held under LM
    expected_alpha = state[ALPHA] * (1 - DT * 1.5 * 0.85) if rule == "smc" else state[ALPHA]
    assert nxt[ALPHA] == pytest.approx(expected_alpha, rel=1e-15)


def test_lm_holds_alpha_and_smc_adapts_it_by_eq_38():
    state = initial_fnn_state(PD_LM, 3)[axis_slice(0)]
    assert _axis_step("lm", state, 1.0, 0.0, 2.5)[ALPHA] == state[ALPHA]
    expected = state[ALPHA] + DT * (1.5 * 2.5 - 1.5 * 0.85 * state[ALPHA])
    assert _axis_step("smc", state, 1.0, 0.0, 2.5)[ALPHA] == pytest.approx(expected, rel=1e-15)


@pytest.mark.parametrize("rule", ["smc", "lm"])
def test_centres_follow_the_input_increments_of_eqs_33_34(rule):
    state = initial_fnn_state(PD_LM, 4)[axis_slice(1)]
    first = _axis_step(rule, state, 0.7, -2.0, 1.0)  # no previous input yet: c unchanged
    np.testing.assert_array_equal(first[C1], state[C1])
    np.testing.assert_array_equal(first[C2], state[C2])
    assert (first[X1_PREV], first[X2_PREV], first[PRIMED]) == (0.7, -2.0, 1.0)
    second = _axis_step(rule, first, 1.0, -2.5, 1.0)
    np.testing.assert_allclose(second[C1], state[C1] + 0.3, rtol=1e-15)
    np.testing.assert_allclose(second[C2], state[C2] - 0.5, rtol=1e-15)


# ------------------------------------------- convergence on a test plant (Thms 1, 3)

class VelocityLoopPlant:
    """Each axis: p_dot = v + d, v_dot = lam (tau - v): the quadrotor seen by
    the position controller (an inner velocity loop of bandwidth lam = k_v)
    with an unknown constant drift d (wind). Integrated exactly per step."""

    def __init__(self, d, lam=5.0, p0=(0.0, 0.0, 0.0), v0=(0.0, 0.0, 0.0)):
        self.d, self.lam = np.asarray(d, float), lam
        self.p, self.v = np.array(p0, float), np.array(v0, float)

    def step(self, tau, dt):
        decay = np.exp(-self.lam * dt)
        v_next = tau + (self.v - tau) * decay
        self.p = self.p + (tau + self.d) * dt + (self.v - tau) * (1 - decay) / self.lam
        self.v = v_next


def run_learning(variant, d=(1.0, -0.8, 0.5), t_end=30.0, seed=0, p0=(0.0, 0.0, 0.0), v0=(0.0, 0.0, 0.0)):
    ff = FastFunction(position_controller_function(lookup(variant)), state=("fnn_state", "fnn_state_next"))
    ff.state[:] = initial_fnn_state(lookup(variant), seed)
    plant = VelocityLoopPlant(d, p0=p0, v0=v0)
    n = int(round(t_end / DT))
    log = {k: np.zeros((n, 3)) for k in ("tau_c", "tau_n", "tau")}
    states = np.zeros((n + 1, ff.state.size))
    states[0] = ff.state
    for k in range(n):
        ff.inputs["e"][:] = -plant.p  # p* = 0
        ff.inputs["e_dot"][:] = -(plant.v + plant.d)  # p*_dot - p_dot
        ff.evaluate()
        out = ff.pending
        for key, name in (("tau_c", "tau_c"), ("tau_n", "tau_n"), ("tau", "v_ref")):
            log[key][k] = out[name]
        ff.commit()
        states[k + 1] = ff.state
        plant.step(log["tau"][k], DT)
    log["t"] = np.arange(n) * DT
    log["states"] = states
    return log


def fnn_share(log, t0, t1):
    """Mean share of the FNN in the control signal, |tau_n| / (|tau_c| + |tau_n|)."""
    sel = (log["t"] >= t0) & (log["t"] < t1)
    tc, tn = np.abs(log["tau_c"][sel]), np.abs(log["tau_n"][sel])
    return (tn / (tc + tn)).mean(axis=0)


@pytest.fixture(scope="module")
def runs():
    return {variant: run_learning(variant) for variant in ("pd", "pd+smc", "pd+lm")}


def test_pd_alone_keeps_the_steady_state_error_of_the_disturbance(runs):
    log = runs["pd"]
    # tau = kp e = -d at steady state: e = -d / kp, the PD never hands over
    np.testing.assert_allclose(log["tau_c"][-1], [-1.0, 0.8, -0.5], atol=1e-6)
    assert np.all(log["tau_n"] == 0.0)


def test_smc_drives_tau_c_to_a_small_neighbourhood_in_finite_time_and_the_fnn_takes_over(runs):
    log = runs["pd+smc"]
    tc = np.abs(log["tau_c"])
    assert np.all(tc.max(axis=0) > 0.45)  # the disturbance first shows up in the PD
    # Theorem 1: |tau_c| enters a neighbourhood of zero in finite time and stays there
    neighbourhood = np.array([0.02, 0.02, 0.15])  # nu_z = 0.2 vs 0.85: coarser on z
    late = log["t"] >= 12.0
    assert np.all(tc[late].max(axis=0) < neighbourhood)
    # Figs. 7-8: the FNN takes over (its share grows toward 1) and cancels the disturbance
    assert np.all(fnn_share(log, 0.0, 1.0) < 0.3)
    assert np.all(fnn_share(log, 20.0, 30.0) > [0.97, 0.97, 0.85])
    np.testing.assert_allclose(log["tau_n"][late].mean(axis=0), [1.0, -0.8, 0.5], atol=0.05)


def test_lm_drives_tau_c_to_a_small_neighbourhood_in_finite_time_and_the_fnn_takes_over(runs):
    log = runs["pd+lm"]
    tc = np.abs(log["tau_c"])
    # Theorem 3; the sgn law moves tau_n at a fixed rate, so tau_c keeps a
    # small limit cycle (relay + velocity loop) instead of decaying to 0
    late = log["t"] >= 5.0
    assert np.all(tc[late].max(axis=0) < 0.3)
    assert np.all(np.sqrt((log["tau_c"][late] ** 2).mean(axis=0)) < 0.15)
    early, late_share = fnn_share(log, 0.0, 0.5), fnn_share(log, 20.0, 30.0)
    assert np.all(early < 0.5)
    assert np.all(late_share > 0.7) and np.all(late_share > early + 0.3)
    np.testing.assert_allclose(log["tau_n"][late].mean(axis=0), [1.0, -0.8, 0.5], atol=0.1)


def _w_bar_function():
    state = ca.SX.sym("state", AXIS_STATE_SIZE)
    x1, x2 = ca.SX.sym("x1"), ca.SX.sym("x2")
    w_bar = normalized_firing_strength(x1, x2, state[C1], state[C2], state[SIGMA1], state[SIGMA2])
    return ca.Function("w_bar", [state, x1, x2], [w_bar])


def test_lm_lyapunov_derivative_of_eq_64_is_negative_while_tau_c_is_large():
    """Start at the PD's steady state under a constant drift d (tau_c = -d,
    tau_dot = 0) with a fresh FNN: while |tau_c| is large the LM law makes
    V_c = tau_c^2 / 2 (eq. 63) decrease at every sample. (At the very first
    sample V_c_dot is ~0: what the FNN learns reaches e only through the
    plant, two integrations away, so tau_dot = -tau_n_dot there.)"""
    d, kp = np.array([1.0, -0.8, 0.5]), PARAMS.kp
    log = run_learning("pd+lm", d=d, t_end=3.0, p0=d / kp, v0=-d)
    w_bar_of = _w_bar_function()
    gamma, alpha_bar = np.array(PARAMS.gamma_lm), np.array(PARAMS.alpha_bar)
    for axis in range(3):
        tc, tau = log["tau_c"][:, axis], log["tau"][:, axis]
        assert abs(tc[0]) == pytest.approx(abs(d[axis]), rel=0.01)
        large = np.abs(tc) > 0.3 * abs(d[axis])
        end = np.argmin(large)  # first sample inside the neighbourhood
        assert 0 < end < len(tc) - 1
        for k in range(end):
            state = log["states"][k][axis_slice(axis)]
            x1, x2 = log["states"][k + 1][axis_slice(axis)][[X1_PREV, X2_PREV]]  # inputs at k
            w_bar = np.array(w_bar_of(state, x1, x2)).ravel()
            f_dot = (log["states"][k + 1][axis_slice(axis)][F] - state[F]) / DT
            tau_dot = (tau[k + 1] - tau[k]) / DT
            v_dot = tc[k] * (f_dot @ w_bar + tau_dot)  # eq. 64
            # the learning term equals the first term of the proof of Theorem 3
            ww = w_bar @ w_bar
            learning_term = -gamma[axis] * abs(tc[k]) * ww / (max(ww, alpha_bar[axis]) + ww)
            assert tc[k] * (f_dot @ w_bar) == pytest.approx(learning_term, rel=1e-9)
            if k == 0:
                assert abs(v_dot) < 1e-4
                continue
            assert v_dot < 0.0, (axis, k, v_dot)
            # and the sampled V_c itself decreases
            assert tc[k + 1] ** 2 < tc[k] ** 2


# ---------------------------------------------- bounds under randomized inputs

BOUNDS = LearningBounds()


def _check_bounds(states, label):
    s = states.reshape(len(states), 3, AXIS_STATE_SIZE)
    assert np.all(np.isfinite(s)), label
    assert np.all(np.abs(s[..., C1]) <= BOUNDS.c1_max), label
    assert np.all(np.abs(s[..., C2]) <= BOUNDS.c2_max), label
    assert np.all((s[..., SIGMA1] >= BOUNDS.sigma1_min) & (s[..., SIGMA1] <= BOUNDS.sigma1_max)), label
    assert np.all((s[..., SIGMA2] >= BOUNDS.sigma2_min) & (s[..., SIGMA2] <= BOUNDS.sigma2_max)), label
    assert np.all(np.abs(s[..., F]) <= BOUNDS.f_max), label
    assert np.all((s[..., ALPHA] >= 0.0) & (s[..., ALPHA] <= BOUNDS.alpha_max)), label
    # eqs. 28-29 are norm bounds: implied by the element-wise boxes
    assert np.all(np.linalg.norm(s[..., SIGMA1], axis=-1) <= np.sqrt(3) * BOUNDS.sigma1_max * (1 + 1e-12))


FAST = {variant: FastFunction(position_controller_function(lookup(variant)), state=("fnn_state", "fnn_state_next"))
        for variant in ("pd+smc", "pd+lm")}


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), scale=st.sampled_from([0.01, 1.0, 30.0, 1e3]),
       variant=st.sampled_from(["pd+smc", "pd+lm"]), zero_fraction=st.sampled_from([0.0, 0.3]))
def test_parameters_stay_in_their_bounds_and_outputs_finite_under_random_inputs(seed, scale, variant,
                                                                                 zero_fraction):
    rng = np.random.default_rng(seed)
    n = 2500
    # random walks with jumps, exact zeros (tau_c = 0, x = c) and extreme values
    e = np.cumsum(rng.normal(0, 0.05 * scale, (n, 3)), axis=0) + rng.choice([0, 1], (n, 3), p=[0.98, 0.02]) \
        * rng.normal(0, 5 * scale, (n, 3))
    e_dot = rng.normal(0, scale, (n, 3)) * rng.choice([1.0, 10.0], (n, 3), p=[0.9, 0.1])
    zero = rng.random(n) < zero_fraction
    e[zero], e_dot[zero] = 0.0, 0.0
    ff = FAST[variant]
    ff.state[:] = initial_fnn_state(lookup(variant), rng)
    states = np.zeros((n, ff.state.size))
    outputs = np.zeros((n, 9))
    e_in, e_dot_in = ff.inputs["e"], ff.inputs["e_dot"]  # the arrays the evaluation reads, looked up once
    for k in range(n):
        e_in[:] = e[k]
        e_dot_in[:] = e_dot[k]
        ff.evaluate()
        ff.commit()
        states[k] = ff.state
        row, out = outputs[k], ff.outputs
        row[:3], row[3:6], row[6:] = out["v_ref"], out["tau_c"], out["tau_n"]
    assert np.all(np.isfinite(outputs))
    # |tau_n| <= B_f: a weighted average of the f_ij (to rounding of sum W_bar = 1)
    assert np.all(np.abs(outputs[:, 6:]) <= BOUNDS.f_max * (1 + 1e-12))
    _check_bounds(states, f"{variant} seed={seed} scale={scale}")


def test_bounds_are_validated():
    with pytest.raises(ValueError, match="a_min"):
        LearningBounds(a_min=0.0)
    with pytest.raises(ValueError, match="sigma1_min"):
        LearningBounds(sigma1_min=20.0)


def test_the_boundary_layer_saturates_and_zero_is_the_papers_sgn():
    from fnn_controller.learning import switching

    tau_c = ca.SX.sym("tau_c")
    phi = ca.SX.sym("phi")
    f = ca.Function("s", [tau_c, phi], [switching(tau_c, phi)])
    for value in (-3.0, -0.2, -0.05, 0.0, 0.05, 0.2, 3.0):
        assert float(f(value, 0.0)) == np.sign(value)  # phi = 0: sgn, exactly
        assert float(f(value, 0.1)) == pytest.approx(np.clip(value / 0.1, -1, 1), abs=1e-15)
        assert float(switching(value, 0.0)) == np.sign(value)  # a number phi builds sgn itself
