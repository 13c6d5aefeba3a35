"""Linear stability analysis (quadrotor_paper.stability): trims, linearizations from the
one source of truth, the python-control loops and the analyses -- known
answers wherever one can be derived by hand."""
from __future__ import annotations

import math
import warnings
from dataclasses import astuple

import casadi as ca
import numpy as np
import pytest

from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import DEFAULTS, QUADROTOR, hover_rotor_speed
from fnn_controller import GeometricParams, PositionParams
from quadrotor_paper.stability import (LoopModel, critical_gain_factor, forward_flight, gain_sweep, hover, linearize_controller,
                             linearize_controller_step, linearize_plant, linearize_plant_fmu, loop_margins,
                             ramp_error, trim_plant)
from quadrotor_paper.stability.analysis import affine_closed_loop, analyze, closed_loop_poles
from quadrotor_paper.stability.linearize import INPUT_NAMES
from quadrotor_paper.stability.operating_points import STATE_NAMES, default_operating_points

H = 0.01
NO_DRAG = {"k_drag_lin": 0.0, "k_drag_quad": 0.0}
I = {n: i for i, n in enumerate(STATE_NAMES)}


@pytest.fixture(scope="module")
def ops():
    return {"hover": hover(), "forward": forward_flight(2.5), "forward_wind": forward_flight(2.5, 3.0)}


@pytest.fixture(scope="module")
def analyses(ops):
    """:func:`analyze` of every operating point in continuous time and in the sampled loop, the outer loops'
    margins (every loop's would be about 0.3 s of CPU more a point): the stability test reads the poles of
    both and the outer loops' margins, the feed-forward test hands them on as the study does (it takes the
    outer loops' margins; test_the_study_takes_every_loop_in_the_sampled_loop... the inner ones)."""
    return {name: analyze(op, H, time_bases=("continuous", "discrete"), every_loop=()) for name, op in ops.items()}


# ---- operating points ----------------------------------------------------------------

def test_every_operating_point_is_an_equilibrium_of_the_closed_loop(ops):
    for op in ops.values():
        xdot = np.array(QUADROTOR.functions["ode"](0.0, np.concatenate([op.x, op.omega]), op.plant_u,
                                                   op.plant_p)).ravel()
        np.testing.assert_allclose(xdot[3:], 0.0, atol=1e-10, err_msg=op.name)  # v, Euler angles, rates steady
        np.testing.assert_allclose(xdot[:3], op.x[3:6], atol=1e-12)  # moving at the trimmed velocity
        # the PD outputs v* at e*, with de/dt = 0
        np.testing.assert_allclose(op.position.kp * op.position_error, op.v_ref, rtol=1e-12, atol=1e-14)


def test_plant_trim_and_closed_loop_trim_give_the_same_rotor_speeds(ops):
    for op in ops.values():
        x, omega = trim_plant(op.x[3:6], op.wind, psi=op.x[8])
        np.testing.assert_allclose(omega, op.omega, rtol=1e-9, err_msg=op.name)
        np.testing.assert_allclose(x[6:8], op.x[6:8], atol=1e-10)


def test_hover_trim_is_the_hover_rotor_speed_and_level(ops):
    op = ops["hover"]
    np.testing.assert_allclose(op.omega, hover_rotor_speed(), rtol=1e-12)
    np.testing.assert_allclose(op.x[6:12], 0.0, atol=1e-12)
    np.testing.assert_allclose(op.v_ref, 0.0, atol=1e-12)


def test_the_default_points_keep_their_names_in_no_wind():
    """``--wind 0``: the third point is still ``forward_wind`` (its figures and
    rows were written over the second's when both were named ``forward``)."""
    points = default_operating_points(wind_speed=0.0)
    assert [p.name for p in points] == ["hover", "forward", "forward_wind"]
    assert not points[2].wind.any() and "no wind" in points[2].description


def test_without_drag_forward_flight_needs_no_velocity_error_and_lags_v_over_kp():
    """No drag: level flight needs no force, so v* = V and the PD lags V/kp."""
    op = forward_flight(2.5, plant_parameters=NO_DRAG)
    np.testing.assert_allclose(op.x[6:8], 0.0, atol=1e-10)
    np.testing.assert_allclose(op.v_ref, [2.5, 0, 0], atol=1e-10)
    np.testing.assert_allclose(op.position_error, [1.0, 0, 0], atol=1e-10)


def test_forward_flight_trim_balances_the_drag_with_the_p_velocity_loop(ops):
    """m k_v (v* - V) = (k_lin + k_quad V) V (docs/controller.md, 1.056 m)."""
    op = ops["forward"]
    drag = (DEFAULTS["k_drag_lin"] + DEFAULTS["k_drag_quad"] * 2.5) * 2.5
    v_ref = 2.5 + drag / (DEFAULTS["m"] * GeometricParams().k_v)
    assert op.v_ref[0] == pytest.approx(v_ref, rel=1e-6)
    assert op.position_error[0] == pytest.approx(v_ref / 2.5, rel=1e-6)
    assert op.x[7] < 0  # nose down (pitch negative) to fly north in NED


# ---- linearization -------------------------------------------------------------------

def test_hover_linearization_is_the_known_double_integrator_chain(ops):
    """Hand-derived A and B at hover (NED, z down, thrust along -z_B)."""
    lin = linearize_plant(ops["hover"])
    A, B = lin.A, lin.B
    m, g, b, l, d = (DEFAULTS[k] for k in ("m", "g", "b", "l", "d"))
    Ix, Iy, Iz, k_lin = DEFAULTS["Ix"], DEFAULTS["Iy"], DEFAULTS["Iz"], DEFAULTS["k_drag_lin"]
    w = hover_rotor_speed()
    expected = np.zeros((12, 12))
    for p, v in (("x", "u"), ("y", "v"), ("z", "w"), ("phi", "p"), ("theta", "q"), ("psi", "r")):
        expected[I[p], I[v]] = 1.0
    expected[I["u"], I["theta"]] = -g  # pitch up (theta > 0) tilts the thrust backwards
    expected[I["v"], I["phi"]] = g
    for v in ("u", "v", "w"):
        expected[I[v], I[v]] = -k_lin / m  # the quadratic drag has zero slope at rest
    np.testing.assert_allclose(A, expected, atol=1e-6)
    dT = 2 * b * w  # dT/dOmega_i
    expected_B = np.zeros((12, 7))
    expected_B[I["w"], :4] = -dT / m
    expected_B[I["p"], :4] = [0, -dT * l / Ix, 0, dT * l / Ix]
    expected_B[I["q"], :4] = [dT * l / Iy, 0, -dT * l / Iy, 0]
    expected_B[I["r"], :4] = np.array([-1, 1, -1, 1]) * 2 * d * w / Iz
    expected_B[[I["u"], I["v"], I["w"]], [4, 5, 6]] = k_lin / m  # wind drags the vehicle along
    np.testing.assert_allclose(B, expected_B, rtol=1e-9, atol=1e-6)


@pytest.mark.parametrize("version", [2, 3])
def test_fmu_directional_derivatives_agree_with_the_casadi_jacobian(version, ops):
    """Model Exchange fmiXGetDirectionalDerivative(der(x), [x, u]) at each
    point (hover, forward flight), FMI 2.0 and 3.0, through the engine's
    linearizer."""
    fmu = cached_fmu(QUADROTOR, version)
    for op in ops.values():
        a, f = linearize_plant(op), linearize_plant_fmu(fmu, op)
        np.testing.assert_allclose(f.A, a.A, rtol=1e-10, atol=1e-10, err_msg=op.name)
        np.testing.assert_allclose(f.B, a.B, rtol=1e-10, atol=1e-12, err_msg=op.name)


def test_plant_fmu_central_differences_agree_with_the_casadi_jacobian(quadrotor_fmu2, ops):
    """The linearizer's fallback on the same FMU: central differences, names
    and units from the modelDescription, and an error estimate that bounds
    the actual error's order."""
    from cosim.linearize.linearization import linearize_fmu

    op = ops["forward_wind"]
    start = dict(zip((v.name for v in QUADROTOR.states), np.concatenate([op.x, op.omega])))
    lin = linearize_fmu(quadrotor_fmu2, start=start, inputs=dict(zip(INPUT_NAMES, op.plant_u)),
                        parameters=dict(op.plant_parameters or {}), method="differences")
    assert lin.method == "central differences"
    a = linearize_plant(op)
    n = len(STATE_NAMES)
    scale = max(np.max(np.abs(a.A)), np.max(np.abs(a.B)))
    assert np.max(np.abs(lin.A[:n, :n] - a.A)) <= 1e-6 * scale
    assert np.max(np.abs(lin.B[:n, :] - a.B)) <= 1e-6 * scale
    assert lin.units["u"] == "m/s" and lin.units["Omega_1"] == "rad/s"


def test_fmu_linearization_honours_plant_parameters(quadrotor_fmu2):
    op = hover(plant_parameters={"m": 2.0, **NO_DRAG})
    f = linearize_plant_fmu(quadrotor_fmu2, op)
    assert f.A[I["u"], I["u"]] == 0.0
    assert f.B[I["w"], 0] == pytest.approx(-2 * DEFAULTS["b"] * op.omega[0] / 2.0, rel=1e-12)


def test_pd_jacobian_is_kp_kd_and_the_composition_is_the_masters_function(ops):
    """The two linearized laws composed = the Jacobian of the parametric
    step of "pd" with its parameters bound, the function the master runs."""
    for op in ops.values():
        c = linearize_controller(op)
        np.testing.assert_allclose(c.K_e, 2.5 * np.eye(3), rtol=1e-15)
        np.testing.assert_allclose(c.K_edot, 0.005 * np.eye(3), rtol=1e-15)
        step = linearize_controller_step(op)
        scale = np.abs(step["x"]).max()
        e_of_x = np.hstack([-c.K_e, -c.K_edot, np.zeros((3, 6))])  # e = p* - p, e_dot = p*_dot - v
        np.testing.assert_allclose(c.K_x + c.K_r @ e_of_x, step["x"], atol=1e-12 * scale)
        np.testing.assert_allclose(c.K_r @ c.K_e, step["p_ref"], atol=1e-12 * scale)
        np.testing.assert_allclose(c.K_r @ c.K_edot, step["p_ref_dot"], atol=1e-12 * scale)


def test_velocity_controller_gain_at_hover_is_the_known_thrust_and_tilt_gain(ops):
    """d Omega / d v*_z: a desired climb (v*_z < 0) speeds all rotors up by
    m k_v / (4 dT/dOmega); d Omega_1 / d v*_x from the tilt command."""
    c = linearize_controller(ops["hover"])
    m, b, k_v = DEFAULTS["m"], DEFAULTS["b"], GeometricParams().k_v
    w = hover_rotor_speed()
    np.testing.assert_allclose(c.K_r[:, 2], -m * k_v / (4 * 2 * b * w), rtol=1e-9)
    assert c.K_r[0, 0] < 0 < c.K_r[2, 0]  # v*_x > 0: pitch nose down, rotor 1 (front) slows
    assert np.all(c.K_x[:, 0:3] == 0.0)  # the velocity controller does not read the position


def test_zoh_sampled_plant_is_the_linearization_of_the_fmu_step():
    """c2d(A, B, 'zoh') = the Jacobian of what the FMU does over one
    communication step (10 internal RK4 steps of 1 ms, inputs held)."""
    op = forward_flight(2.5, 3.0)
    f = QUADROTOR.functions["step"]
    x = ca.SX.sym("x", 12)
    u = ca.SX.sym("u", 7)
    xn = ca.vertcat(x, op.omega)  # the rotor states, unused at tau_m = 0
    for k in range(10):
        xn = f(k * 1e-3, xn, u, op.plant_p, 1e-3)
    xn = xn[:12]
    jac = ca.Function("step_jacobian", [x, u], [ca.jacobian(xn, x), ca.jacobian(xn, u)])
    Ad, Bd = (np.array(m) for m in jac(op.x, op.plant_u))
    sampled = LoopModel(op, dt=H).plant
    np.testing.assert_allclose(sampled.A, Ad, atol=1e-9)
    np.testing.assert_allclose(sampled.B, Bd, atol=1e-9 * np.abs(Bd).max())


def test_finite_difference_rate_rule_is_refused():
    with pytest.raises(ValueError, match="desired_rate"):
        hover(geometric=GeometricParams(desired_rate="finite_difference"))


# ---- loops -------------------------------------------------------------------------------

def test_loop_model_refuses_a_delay_in_continuous_time_and_bad_arguments(ops):
    with pytest.raises(ValueError, match="discrete"):
        LoopModel(ops["hover"], dt=None, delay_steps=1)
    with pytest.raises(ValueError, match="non-negative"):
        LoopModel(ops["hover"], dt=H, delay_steps=-1)
    with pytest.raises(ValueError, match="axis"):
        LoopModel(ops["hover"]).outer_loop("w")
    with pytest.raises(ValueError, match="rotor"):
        LoopModel(ops["hover"]).rotor_loop(5)


def test_one_step_delay_block_delays_by_one_sample(ops):
    import control as ct

    hold = LoopModel(ops["hover"], dt=H, delay_steps=2).hold
    resp = ct.forced_response(hold, np.arange(5) * H, np.vstack([[1, 0, 0, 0, 0]] * 4))
    np.testing.assert_array_equal(resp.outputs[0], [0, 0, 1, 0, 0])


def test_closing_the_broken_outer_loop_gives_the_closed_loop_poles(ops):
    """feedback(L, 1) of the x loop (other loops closed inside L) has the
    poles of the whole closed loop, up to the modes L cannot see."""
    import control as ct

    model = LoopModel(ops["forward_wind"], dt=H)
    closed = np.sort_complex(model.closed_loop().poles())
    via_l = ct.feedback(model.outer_loop("x"), 1).poles()
    for p in closed:
        assert np.min(np.abs(via_l - p)) < 1e-6


def test_closed_loop_state_matrix_is_affine_in_the_pd_gains(ops):
    op = ops["forward_wind"]
    A0, Akp, Akd = affine_closed_loop(op, dt=H)
    for kp, kd in ((0.7, 0.3), (6.0, -0.4), (2.5, 0.005)):
        direct = LoopModel(op, dt=H, kp=kp, kd=kd).closed_loop().A
        np.testing.assert_allclose(A0 + kp * Akp + kd * Akd, direct, atol=1e-9)


# ---- analyses ------------------------------------------------------------------------

def test_paper_gains_are_stable_with_margins_at_every_operating_point(analyses):
    for op_name, res in analyses.items():
        for key in ("continuous", "discrete"):
            assert res.poles[key].stable, (op_name, key)
            assert res.poles[key].least_damping > 0.55
        outer = [m for m in res.margins["discrete"] if m.loop.startswith("outer")]
        assert all(3.5 < m.gain_margin for m in outer)
        assert all(60.0 < m.phase_margin < 70.0 for m in outer)


def test_hover_closed_loop_has_the_documented_slowest_pair(ops):
    """docs/controller.md: slowest 3.6 rad/s (zeta 0.74), least damped 0.57."""
    p = closed_loop_poles(LoopModel(ops["hover"], dt=H).closed_loop())
    assert p.slowest == pytest.approx(3.58, abs=0.01)
    assert p.least_damping == pytest.approx(0.575, abs=0.005)


def test_critical_gain_factor_equals_the_outer_loop_gain_margin(ops):
    """Eigenvalues (bisection) and python-control's margins agree: at hover
    x and y are decoupled and equal, z has the larger margin."""
    op = ops["hover"]
    for dt, delay in ((None, 0), (H, 0), (H, 1)):
        gm = loop_margins(LoopModel(op, dt, delay).outer_loop("x")).gain_margin
        assert critical_gain_factor(op, dt, delay) == pytest.approx(gm, rel=1e-4)


def test_margins_on_the_frequency_response_match_the_polynomial_route(ops):
    import control as ct

    L = LoopModel(ops["hover"]).outer_loop("x")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gm, pm, sm, *_ = ct.stability_margins(ct.minreal(ct.tf(L), tol=1e-7, verbose=False))
    m = loop_margins(L)
    assert m.gain_margin == pytest.approx(gm, rel=1e-6)
    assert m.phase_margin == pytest.approx(pm, rel=1e-6)
    assert m.stability_margin == pytest.approx(sm, rel=1e-6)


def test_batched_frequency_response_is_python_controls_to_the_bit(ops):
    """One batched solve gives what ``StateSpace.__call__`` gives one frequency at a time."""
    import control as ct

    from quadrotor_paper.stability.analysis import frequency_response

    w = np.logspace(-3, 2.4, 200)
    for L in (LoopModel(ops["forward_wind"], H, 1).outer_loop("y"), LoopModel(ops["hover"]).rotor_loop(2)):
        x = np.exp(1j * w * L.dt) if L.isdtime(strict=True) else 1j * w
        assert np.array_equal(frequency_response(L, w), L(x, squeeze=False))
    tf = ct.tf([2.5 * H], [1, -1], H)  # not a state-space system: python-control evaluates it
    assert np.array_equal(frequency_response(tf, w), tf(np.exp(1j * w * H), squeeze=False))


def test_margins_with_the_spline_evaluated_at_once_are_python_controls_to_the_bit(ops, monkeypatch):
    """``loop_margins`` evaluates python-control's interpolating spline at
    every frequency in one ``splev`` call: its margins and crossovers are
    those of python-control's own per-frequency loop to the bit, in every
    time base and on loops with several crossovers (rotor, velocity); and
    python-control's ``FRD.eval`` is its own again afterwards."""
    import contextlib

    from control import frdata

    from quadrotor_paper.stability import analysis

    own = frdata.FRD.eval
    loops = [L for dt, delay in ((None, 0), (H, 0), (H, 1))
             for model in [LoopModel(ops["forward_wind"], dt, delay)]
             for L in (model.outer_loop("y"), model.velocity_loop("z"), model.rotor_loop(3))]
    at_once = np.array([astuple(loop_margins(L))[1:] for L in loops])
    assert frdata.FRD.eval is own
    monkeypatch.setattr(analysis, "_spline_evaluated_at_once", contextlib.nullcontext)
    one_by_one = np.array([astuple(loop_margins(L))[1:] for L in loops])
    np.testing.assert_array_equal(at_once, one_by_one)  # NaN where python-control finds no crossover


def test_the_study_takes_every_loop_in_the_sampled_loop_and_the_outer_loops_elsewhere(ops):
    res = analyze(ops["hover"], H, every_loop=("discrete",))
    assert [m.loop for m in res.margins["discrete"]] == list(res.models["discrete"].loops())
    assert [m.loop for m in res.margins["continuous"]] == ["outer x", "outer y", "outer z"]
    full = analyze(ops["hover"], H, time_bases=("continuous",))
    np.testing.assert_array_equal([astuple(m) for m in full.margins["continuous"][:3]],
                                  [astuple(m) for m in res.margins["continuous"]])  # to the bit


def test_margins_known_answers_for_the_ideal_outer_loop():
    """Perfect velocity loop: L = kp/s has PM 90 deg, no phase crossover; its
    ZOH version L = kp h/(z - 1) crosses -180 deg at z = -1 with GM 2/(kp h)."""
    import control as ct

    kp = 2.5
    m = loop_margins(ct.tf([kp], [1, 0]))
    assert m.phase_margin == pytest.approx(90.0, abs=1e-3) and math.isinf(m.gain_margin)
    assert m.w_gain_crossover == pytest.approx(kp, rel=1e-4)
    md = loop_margins(ct.tf([kp * H], [1, -1], H))
    assert md.gain_margin == pytest.approx(2 / (kp * H), rel=1e-3)
    assert md.phase_margin == pytest.approx(90.0 - math.degrees(kp * H / 2), abs=0.01)


def test_gain_sweep_maps_the_paper_point_inside_and_the_boundary_where_the_margin_says(ops):
    op = ops["hover"]
    kp = np.linspace(0.5, 20.0, 40)
    kd = np.array([-1.2, -0.5, 0.005, 3.0, 7.5])
    sw = gain_sweep(op, kp, kd, dt=H)
    assert sw.is_stable(2.5, 0.005)
    assert not sw.stable[0].any()  # kd < -1: the D term cancels the velocity loop
    assert not sw.stable[-1].any()  # kd too large: the velocity loop's gain k_v (1 + kd) is too high
    assert sw.stable[3].sum() > sw.stable[2].sum()  # some kd widens the kp range
    c = critical_gain_factor(op, H)
    step = kp[1] - kp[0]
    assert c * 2.5 - step <= sw.kp_limit(0.005) <= c * 2.5 + step


def test_ramp_lag_is_v_over_kp_for_the_type_1_loop():
    """Known answer without drag: 1.000 m at 2.5 m/s; with the linear drag of
    hover, V/kp (1 + k_lin/(m k_v)); the trim adds the quadratic drag."""
    ideal = ramp_error(hover(plant_parameters=NO_DRAG), speed=2.5, dt=H)
    assert ideal.linear_discrete == pytest.approx(1.0, abs=1e-6)
    assert ideal.linear_continuous == pytest.approx(1.0, abs=1e-6)
    assert ideal.trim == pytest.approx(1.0, abs=1e-9)
    r = ramp_error(hover(), speed=2.5, dt=H)
    factor = 1 + DEFAULTS["k_drag_lin"] / (DEFAULTS["m"] * GeometricParams().k_v)
    assert r.linear_discrete == pytest.approx(factor, abs=1e-5)
    assert r.trim == pytest.approx(1.0561, abs=1e-4)
    lag = ramp_error(hover(position=PositionParams(kp=5.0)), speed=2.5, dt=H)
    assert lag.linear_continuous == pytest.approx(factor / 2, abs=1e-5)


def test_discrete_gain_margin_at_the_nyquist_frequency_is_confirmed_by_the_poles(ops):
    """The rotor loops of the sampled inner loop cross -180 deg at z = -1
    (python-control alone reports no crossover there): scaling the loop by
    0.98 GM keeps every pole in the closed unit disc, by 1.02 GM does not."""
    import control as ct

    L = LoopModel(ops["hover"], dt=H).rotor_loop(1)
    m = loop_margins(L)
    assert m.w_phase_crossover == pytest.approx(math.pi / H)
    assert 5.0 < m.gain_margin < 10.0
    assert np.abs(ct.feedback(0.98 * m.gain_margin * L, 1).poles()).max() <= 1.0 + 1e-9
    assert np.abs(ct.feedback(1.02 * m.gain_margin * L, 1).poles()).max() > 1.001


def test_feed_forward_leaves_poles_and_margins_and_removes_the_v_over_kp_ramp_lag(ops, analyses):
    """v* = PD + ff dp*/dt reads the reference only: the closed-loop A and the
    broken loops are the paper's PD's for every ff; the linear ramp lag falls
    from V/kp (1 + k_lin/(m k_v)) to the drag's share alone, V k_lin/(m k_v kp)
    (no drag: exactly 0); the circle error to the centripetal and drag part."""
    from quadrotor_paper.stability import feedforward_comparison, linearize_controller

    assert np.array_equal(linearize_controller(ops["forward"].with_feedforward(0.7)).K_ff, 0.7 * np.eye(3))
    for name, op in ops.items():
        A = {ff: LoopModel(op, H, feedforward=ff).closed_loop().A for ff in (0.0, 1.0)}
        np.testing.assert_array_equal(A[0.0], A[1.0])
    paper, ff = feedforward_comparison(list(ops.values()), H, 2.5)
    assert paper.outer_gain_margin == ff.outer_gain_margin and paper.outer_phase_margin == ff.outer_phase_margin
    # the paper's gain alone: the case the analyses stand in for (the feed-forward's is compared above)
    reused = feedforward_comparison(list(ops.values()), H, 2.5, (0.0,), analyses=list(analyses.values()))[0]
    for field in ("stable", "spectral_radius", "outer_gain_margin", "outer_phase_margin", "ramp", "circle"):
        assert getattr(reused, field) == getattr(paper, field), field
    drag_share = 2.5 * DEFAULTS["k_drag_lin"] / (DEFAULTS["m"] * GeometricParams().k_v * 2.5)
    assert ff.ramp.ideal == 0.0 and paper.ramp.ideal == pytest.approx(1.0)
    assert ff.ramp.linear_discrete == pytest.approx(drag_share, abs=1e-5)
    assert ff.ramp.linear_discrete < 0.05 * paper.ramp.linear_discrete
    assert ff.ramp.trim == pytest.approx(0.0561, abs=1e-4)  # the quadratic drag too: D(V)/(m k_v kp)
    assert ff.circle.rms < 0.1 * paper.circle.rms
    no_drag = ramp_error(hover(plant_parameters=NO_DRAG, position=PositionParams(feedforward=1.0)), speed=2.5, dt=H)
    assert abs(no_drag.linear_discrete) < 1e-9 and abs(no_drag.trim) < 1e-9
    with pytest.raises(ValueError, match="feedforward"):
        ops["hover"].with_feedforward(1.5)
