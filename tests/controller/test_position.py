"""The position controller (eqs. 19, 26) and the whole controller step:
known answers, the fast buffer path against plain CasADi calls, input
guards, derivatives for linear analysis, and closed loops with the plant
FMU (hover, the PD's ramp lag, the FNN removing it, per-step cost)."""
from __future__ import annotations


import casadi as ca
import numpy as np
import pytest

from fmu_models.models.quadrotor import DEFAULTS, hover_rotor_speed
from fnn_controller import (STATE_SIZE, GeometricParams, PositionParams, QuadrotorController, VehicleParams,
                            bound_step_function, initial_state, parametric_step_function,
                            position_controller_function, velocity_controller_function)
from fnn_controller.fast import FastFunction
from fnn_controller.geometric import initial_velocity_state
from fnn_controller.parametric import parameter_vector
from fnn_controller.position import initial_fnn_state
from fnn_controller.step import Y_SLICES
from fnn_controller.variants import variant as lookup, variant_names
from fnn_controller.variants.pd import PD
from test_geometric import H, PlantFmu, plant_fmu  # noqa: F401  (fixture)

KP, KD = PositionParams().kp, PositionParams().kd
HOVER = np.array([0, 0, -15.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])


def test_pd_variant_is_eq_19_and_leaves_the_state_alone():
    f = position_controller_function(PD)
    state = initial_fnn_state(PD, 0)
    v_ref, state_next, tau_c, tau_n = (np.array(v).ravel() for v in f([1.0, -2.0, 0.5], [0.3, 4.0, -1.0], state))
    expected = KP * np.array([1.0, -2.0, 0.5]) + KD * np.array([0.3, 4.0, -1.0])
    np.testing.assert_allclose(v_ref, expected, rtol=1e-15)
    np.testing.assert_array_equal(tau_c, v_ref)
    np.testing.assert_array_equal(tau_n, 0.0)
    np.testing.assert_array_equal(state_next, state)


@pytest.mark.parametrize("variant", ["pd+smc", "pd+lm"])
def test_fnn_variants_subtract_tau_n_eq_26(variant):
    f = position_controller_function(lookup(variant))
    v_ref, _, tau_c, tau_n = (np.array(v).ravel() for v in f([1.0, -2.0, 0.5], [0.3, 4.0, -1.0],
                                                              initial_fnn_state(lookup(variant), 0)))
    np.testing.assert_allclose(v_ref, tau_c - tau_n, rtol=1e-15)
    assert np.all((tau_n >= 0) & (tau_n <= 1e-3))  # weighted average of f_ij(0) in [0, 0.001]


def test_unknown_variant_is_refused_where_its_name_enters():
    with pytest.raises(ValueError, match="pd\\+lm"):
        lookup("lm")
    with pytest.raises(ValueError, match="pd\\+lm"):
        QuadrotorController("lm")


def test_linearization_of_the_pd_position_controller_is_kp_kd():
    f = position_controller_function(PD)
    jac = f.jacobian()
    e, e_dot = ca.DM.zeros(3), ca.DM.zeros(3)
    out = jac(e=e, e_dot=e_dot, fnn_state=initial_fnn_state(PD, 0), out_v_ref=0, out_fnn_state_next=0,
              out_tau_c=0, out_tau_n=0)
    np.testing.assert_allclose(np.array(out["jac_v_ref_e"]), KP * np.eye(3), rtol=1e-15)
    np.testing.assert_allclose(np.array(out["jac_v_ref_e_dot"]), KD * np.eye(3), rtol=1e-15)


def test_velocity_controller_jacobian_at_hover_is_finite():
    f = velocity_controller_function(GeometricParams())
    args = dict(v_ref=np.zeros(3), v=np.zeros(3), euler=np.zeros(3), omega_b=np.zeros(3), psi_ref=0.0,
                vel_state=initial_velocity_state())
    sym = {name: ca.SX.sym(name, f.sparsity_in(i)) for i, name in enumerate(f.name_in())}
    omega = f.call(sym)["Omega"]
    for name in ("v_ref", "v", "euler", "omega_b"):
        jac = ca.Function("j", list(sym.values()), [ca.jacobian(omega, sym[name])])(*args.values())
        assert np.all(np.isfinite(np.array(jac))), name
    # d Omega / d v_ref is nonzero along z only at hover (thrust), by symmetry
    jac_v = np.array(ca.Function("j", list(sym.values()), [ca.jacobian(omega, sym["v_ref"])])(*args.values()))
    assert np.all(jac_v[:, 2] < 0)  # asking to go down (+z) lowers every rotor speed


# ---------------------------------------------------------- fast path, guards

def _random_inputs(rng):
    x = HOVER + rng.normal(0, [2, 2, 2, 1, 1, 1, 0.2, 0.2, 0.5, 1, 1, 1])
    return rng.normal(0, 3, 3), rng.normal(0, 2, 3), x, float(rng.normal(0, 0.3))


@pytest.mark.parametrize("variant", variant_names())
def test_fast_buffer_path_gives_identical_results_to_a_plain_casadi_call(variant):
    """QuadrotorController (the parametric step through its buffers, p
    filled once) against plain calls of the fixed-gains function (the same
    function, p bound by an MX call): bit for bit, 300 steps."""
    rng = np.random.default_rng(11)
    ctrl = QuadrotorController(variant)
    ctrl.reset(seed=5)
    f = bound_step_function(variant)
    state = initial_state(lookup(variant), 5)
    for _ in range(300):
        p_ref, p_ref_dot, x, psi_ref = _random_inputs(rng)
        omega = ctrl.step(p_ref, p_ref_dot, x, psi_ref).copy()
        plain = f(p_ref=p_ref, p_ref_dot=p_ref_dot, x=x, psi_ref=psi_ref, state=state)
        y = np.array(plain["y"]).ravel()
        np.testing.assert_array_equal(omega, y[Y_SLICES["Omega"]])
        for name in ("v_ref", "tau_c", "tau_n", "wrench"):
            np.testing.assert_array_equal(ctrl.outputs[name], y[Y_SLICES[name]])
        state = np.array(plain["state_next"]).ravel()
        np.testing.assert_array_equal(ctrl.state, state)


NON_DEFAULT = (PositionParams(kp=1.7, kd=0.02, feedforward=0.5, accel_feedforward=0.25, gamma_lm=(1.2, 1.3, 1.4),
                              gamma_smc=(1.0, 1.1, 1.2), phi=(0.1, 0.1, 0.2)),
               GeometricParams(k_v=4.0, k_R=(300.0, 310.0, 50.0), desired_rate="finite_difference",
                               vehicle=VehicleParams(m=1.3, Ix=0.05)))


@pytest.mark.parametrize("variant", variant_names())
def test_fixed_gains_are_the_parametric_function_with_its_parameters_bound(variant):
    """bound_step_function(variant, position, geometric) is the one
    parametric function with p = parameter_vector(...) (and the structural
    choice desired_rate): the same numbers to the bit, which differ from
    the defaults' (so the values do reach the laws)."""
    position, geometric = NON_DEFAULT
    rng = np.random.default_rng(12)
    state = initial_state(lookup(variant), 2, position)
    parametric = parametric_step_function(variant, PositionParams(), GeometricParams(desired_rate="finite_difference"))
    p = parameter_vector(variant, position, geometric)
    bound, default = bound_step_function(variant, position, geometric), bound_step_function(variant)
    for _ in range(50):
        p_ref, p_ref_dot, x, psi_ref = _random_inputs(rng)
        args = dict(p_ref=p_ref, p_ref_dot=p_ref_dot, x=x, psi_ref=psi_ref, state=state, p_ref_ddot=rng.normal(size=3))
        mine, reference = bound(**args), parametric(**args, p=p)
        for name in ("y", "state_next", "check"):
            np.testing.assert_array_equal(np.array(mine[name]), np.array(reference[name]), err_msg=name)
        assert not np.array_equal(np.array(mine["y"]), np.array(default(**args)["y"]))
        state = np.array(mine["state_next"]).ravel()


def test_reset_reproduces_a_run_and_seeds_differ():
    def run(seed):
        rng = np.random.default_rng(0)
        ctrl = QuadrotorController("pd+smc")
        ctrl.reset(seed)
        return np.array([ctrl.step(*_random_inputs(rng)).copy() for _ in range(50)]), ctrl.state

    (a, sa), (b, sb), (c, _) = run(1), run(1), run(2)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(sa, sb)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("name, index, value, expected", [
    ("x", 7, float("nan"), "x\\[7\\] \\(theta\\) = nan"),
    ("p_ref", 2, float("inf"), "p_ref\\[2\\] = inf"),
    ("p_ref_dot", 0, float("-inf"), "p_ref_dot\\[0\\] = -inf"),
    ("psi_ref", 0, float("nan"), "psi_ref\\[0\\] = nan"),
])
def test_non_finite_input_raises_naming_it_and_changes_nothing(name, index, value, expected):
    ctrl = QuadrotorController("pd+lm")
    ctrl.reset(seed=3)
    good = dict(p_ref=np.array([1.0, 0, -15]), p_ref_dot=np.zeros(3), x=HOVER.copy(), psi_ref=0.0)
    omega = ctrl.step(**good)
    omega_before, outputs_before, state_before = omega.copy(), {k: v.copy() for k, v in ctrl.outputs.items()}, \
        ctrl.state
    bad = {k: (np.array(v, dtype=float) if k != "psi_ref" else v) for k, v in good.items()}
    if name == "psi_ref":
        bad["psi_ref"] = value
    else:
        bad[name][index] = value
    with pytest.raises(ValueError, match=expected):
        ctrl.step(**bad)
    np.testing.assert_array_equal(ctrl.state, state_before)
    np.testing.assert_array_equal(omega, omega_before)  # the returned array is untouched
    for key, array in ctrl.outputs.items():
        np.testing.assert_array_equal(array, outputs_before[key])
    # and the controller carries on
    assert np.all(np.isfinite(ctrl.step(**good)))


def test_step_before_reset_and_bad_state_are_refused():
    ctrl = QuadrotorController("pd")
    with pytest.raises(RuntimeError, match="reset"):
        ctrl.step(np.zeros(3), np.zeros(3), HOVER)
    with pytest.raises(ValueError):
        ctrl.state = np.full(STATE_SIZE, np.nan)


def test_fast_function_refuses_a_state_pair_of_different_sizes():
    with pytest.raises(ValueError, match="differ"):
        FastFunction(position_controller_function(PD), state=("e", "fnn_state_next"))


# --------------------------------------------------- closed loop with the FMU

def fly(plant_fmu, variant, p_ref, p_ref_dot, t_end, seed=0, wind=(0, 0, 0), **start):
    return fly_with(plant_fmu, variant, PositionParams(), p_ref, p_ref_dot, t_end, seed, wind, **start)


def fly_with(plant_fmu, variant, position, p_ref, p_ref_dot, t_end, seed=0, wind=(0, 0, 0), p_ref_ddot=None,
             **start):
    start.setdefault("z", -15.0)
    plant = PlantFmu(plant_fmu, **start)
    plant.set_wind(wind)
    ctrl = QuadrotorController(variant, position)
    ctrl.reset(seed)
    n = int(round(t_end / H))
    xs, tau_c, tau_n = np.zeros((n + 1, 12)), np.zeros((n, 3)), np.zeros((n, 3))
    x = plant.state()
    xs[0] = x
    for k in range(n):
        t = k * H  # time from the step counter
        omega = ctrl.step(p_ref(t), p_ref_dot(t), x, 0.0, (0.0, 0.0, 0.0) if p_ref_ddot is None else p_ref_ddot(t))
        tau_c[k], tau_n[k] = ctrl.outputs["tau_c"], ctrl.outputs["tau_n"]
        plant.step(omega)
        x = plant.state()
        xs[k + 1] = x
    plant.close()
    return {"t": np.arange(n + 1) * H, "x": xs, "tau_c": tau_c, "tau_n": tau_n}


@pytest.mark.parametrize("variant, position_tol, attitude_tol", [
    ("pd", 1e-9, 1e-9), ("pd+smc", 0.002, 0.002), ("pd+lm", 0.15, 0.2)])
def test_hover_at_the_set_point_is_held(plant_fmu, variant, position_tol, attitude_tol):
    """The LM law moves tau_n at the fixed rate gamma W^T W / (delta + W^T W)
    times sgn(tau_c), with no adaptive rate to decay: at rest this integral
    relay keeps a limit cycle (measured +-9 cm, 7.5 degrees). SMC's alpha
    decays (eq. 38) and the PD has nothing to learn."""
    log = fly(plant_fmu, variant, lambda t: (0.0, 0.0, -15.0), lambda t: (0.0, 0.0, 0.0), 10.0)
    assert np.all(np.abs(log["x"][:, 0:3] - [0, 0, -15.0]) < position_tol)
    assert np.all(np.abs(log["x"][:, 6:9]) < attitude_tol)


def _ramp(speed):
    return (lambda t: (speed * t, 0.0, -15.0)), (lambda t: (speed, 0.0, 0.0))


def test_pd_lags_a_ramp_by_the_known_amount(plant_fmu):
    """No velocity feed-forward: at steady state v* = kp e carries the whole
    speed, plus what the P velocity loop needs against drag."""
    log = fly(plant_fmu, "pd", *_ramp(2.5), 12.0)
    e_x = 2.5 * log["t"] - log["x"][:, 0]
    drag = (DEFAULTS["k_drag_lin"] + DEFAULTS["k_drag_quad"] * 2.5) * 2.5
    v_ref = 2.5 + drag / (DEFAULTS["m"] * GeometricParams().k_v)
    assert e_x[-1] == pytest.approx(v_ref / KP, abs=2e-3)  # 1.056 m
    assert abs(e_x[-1] - 1.0) < 0.1  # the paper's "about 1 m"


@pytest.mark.parametrize("variant", ["pd+smc", "pd+lm"])
def test_fnn_learns_the_missing_feed_forward_and_takes_over(plant_fmu, variant):
    log = fly(plant_fmu, variant, *_ramp(2.5), 30.0, seed=1)
    e_x = 2.5 * log["t"] - log["x"][:, 0]
    late = log["t"][:-1] >= 20.0
    assert np.abs(e_x[1:][late]).max() < 0.15  # vs 1.056 m for the PD alone
    share = np.abs(log["tau_n"][late, 0]) / (np.abs(log["tau_c"][late, 0]) + np.abs(log["tau_n"][late, 0]))
    assert share.mean() > 0.9
    assert np.all(np.isfinite(log["x"]))


def test_mission_length_closed_loop_with_the_fmu_holds_hover(plant_fmu):
    """5000 steps (50 s) of controller + plant FMU through the fast paths the
    master uses: PD+LM-FNN holds the hover it starts in. (Its cost is printed
    by benchmarks/controller_speed.py, never asserted here.)"""
    plant = PlantFmu(plant_fmu, z=-15.0)
    ctrl = QuadrotorController("pd+lm")
    ctrl.reset(0)
    p_ref, p_ref_dot = np.array([0.0, 0.0, -15.0]), np.zeros(3)
    x = plant.state()
    fmu, vr_in, vr_out = plant.fmu, plant._vr_omega, plant._vr_state
    for k in range(5000):
        omega = ctrl.step(p_ref, p_ref_dot, x)
        fmu.setReal(vr_in, omega.tolist())
        fmu.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)
        x = fmu.getReal(vr_out)
    plant.close()
    assert np.all(np.isfinite(x))
    assert np.linalg.norm(np.array(x[0:3]) - p_ref) < 0.2  # m; LM holds a small oscillation at hover


def test_velocity_feed_forward_removes_the_ramp_lag_of_the_pd(plant_fmu):
    """With the reference velocity fed forward (gain 1) the P loop need not
    lag V/kp behind a ramp (1.056 m for the PD alone). What is left is the
    velocity loop's steady error against the drag, D(V) / (m k_v), turned into
    position by kp: (0.2 V + 0.04 V^2) / (1.07 * 5 * 2.5) = 0.056 m at 2.5 m/s."""
    position = PositionParams(feedforward=1.0)
    log = fly_with(plant_fmu, "pd", position, *_ramp(2.5), 12.0)
    e_x = 2.5 * log["t"] - log["x"][:, 0]
    drag = DEFAULTS["k_drag_lin"] * 2.5 + DEFAULTS["k_drag_quad"] * 2.5 ** 2
    assert e_x[-1] == pytest.approx(drag / (DEFAULTS["m"] * GeometricParams().k_v * KP), rel=0.02)


def _papers_law(variant, p_ref, p_ref_dot, x, psi_ref, state):
    """The paper's step composed by hand from the two law functions, built
    with numbers: an option's gain that is the number 0 leaves its term out
    of the expressions (eq. 26 as printed; eq. 13 without a*)."""
    v = lookup(variant)
    n = 3 * v.axis_state_size
    v_ref, fnn_next, tau_c, tau_n = position_controller_function(v)(p_ref - x[0:3], p_ref_dot - x[3:6], state[:n])
    omega, vel_next, wrench, _, _ = velocity_controller_function()(v_ref, x[3:6], x[6:9], x[9:12], psi_ref,
                                                                   state[n:])
    y = np.concatenate([np.array(a).ravel() for a in (omega, v_ref, tau_c, tau_n, wrench)])
    return y, np.concatenate([np.array(fnn_next).ravel(), np.array(vel_next).ravel()])


def _step_inputs(seed, variant="pd+lm"):
    rng = np.random.default_rng(seed)
    return (rng.normal(size=3), rng.normal(size=3), HOVER + rng.normal(size=12), 0.3,
            initial_state(lookup(variant), 0), rng.normal(size=3))


def test_feed_forward_zero_is_the_papers_law_bit_for_bit():
    """The step function a run evaluates keeps the option's term (its gain
    is a parameter); at 0 it gives the paper's law to the bit."""
    args = _step_inputs(5)
    y_zero, next_zero, _ = bound_step_function("pd+lm", PositionParams(feedforward=0.0))(*args)
    y, state_next = _papers_law("pd+lm", *args[:5])
    np.testing.assert_array_equal(np.array(y_zero).ravel(), y)
    np.testing.assert_array_equal(np.array(next_zero).ravel(), state_next)
    with_ff = np.array(bound_step_function("pd+lm", PositionParams(feedforward=1.0))(*args)[0]).ravel()
    assert not np.array_equal(with_ff[Y_SLICES["v_ref"]], y[Y_SLICES["v_ref"]])  # v_ref moved by dp*/dt


def test_acceleration_feed_forward_zero_is_the_papers_law_bit_for_bit():
    args = _step_inputs(6)  # a nonzero d2p*/dt2 that the gain 0 must ignore
    y_zero, next_zero, _ = bound_step_function("pd+lm", PositionParams(accel_feedforward=0.0))(*args)
    y, state_next = _papers_law("pd+lm", *args[:5])
    np.testing.assert_array_equal(np.array(y_zero).ravel(), y)
    np.testing.assert_array_equal(np.array(next_zero).ravel(), state_next)
    with_aff = np.array(bound_step_function("pd+lm", PositionParams(accel_feedforward=1.0))(*args)[0]).ravel()
    v_ref, wrench = Y_SLICES["v_ref"], Y_SLICES["wrench"]
    assert np.array_equal(with_aff[v_ref], y[v_ref])  # v* is the position loop's, unchanged
    assert not np.array_equal(with_aff[wrench], y[wrench])  # the wrench follows the force


def test_acceleration_feed_forward_tilts_the_desired_force_toward_a_ref():
    """At hover (v = v* = 0), a* = (1, 0, 0) m/s^2 asks for F = (-m, 0, m g):
    the thrust -F points north, so m v_dot = -F + m g e3 = m a*."""
    from fnn_controller.geometric import desired_force

    m, g = DEFAULTS["m"], DEFAULTS["g"]
    force = np.array(desired_force(ca.DM.zeros(3), ca.DM.zeros(3), GeometricParams(), ca.DM([1.0, 0.0, 0.0])))
    np.testing.assert_allclose(force.ravel(), [-m, 0.0, m * g], rtol=1e-15)


def _circle(radius, speed):
    w = speed / radius
    return ((lambda t: (radius * np.sin(w * t), radius - radius * np.cos(w * t), -15.0)),
            (lambda t: (speed * np.cos(w * t), speed * np.sin(w * t), 0.0)),
            (lambda t: (-speed * w * np.sin(w * t), speed * w * np.cos(w * t), 0.0)))


def test_acceleration_feed_forward_removes_the_centripetal_lag_on_a_circle(plant_fmu):
    """PD with velocity feed-forward on a 10 m circle at 2.5 m/s: without the
    acceleration the velocity loop needs e_v = a / k_v to turn, which the P
    position loop turns into a radial error a / (k_v kp) = 0.625 / 12.5 =
    0.05 m (linear loop: e'' + k_v e' + k_v kp e = a*, the circle's 0.25
    rad/s far below the loop's 3.5 rad/s): the error p* - p points inward
    with a*, the vehicle flies outside. Fed forward, the radial error falls
    below 1 cm; the along-track error against the drag (0.056 m) stays."""
    p_ref, p_ref_dot, p_ref_ddot = _circle(10.0, 2.5)

    def radial_error(accel):
        position = PositionParams(feedforward=1.0, accel_feedforward=accel)
        log = fly_with(plant_fmu, "pd", position, p_ref, p_ref_dot, 20.0, p_ref_ddot=p_ref_ddot,
                       x=0.0, y=0.0, u=2.5)
        last = log["t"] >= 10.0
        distance = np.hypot(log["x"][last, 0], log["x"][last, 1] - 10.0)
        return np.mean(distance - 10.0)  # > 0: outside the circle

    without, with_accel = radial_error(0.0), radial_error(1.0)
    assert without == pytest.approx(0.625 / (GeometricParams().k_v * KP), rel=0.15)
    assert abs(with_accel) < 0.01, with_accel
