"""Every registered controller variant through the same checks, discovered
from the registry, so a new variant is checked without a new test."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_models.models.quadrotor import DEFAULTS, hover_rotor_speed
from fnn_controller import FnnInit, PositionParams, QuadrotorController
from fnn_controller.variants import variant, variant_names
from test_geometric import H, plant_fmu  # noqa: F401  (fixture)
from test_position import fly

HOVER = np.array([0, 0, -15.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])


@pytest.fixture(params=variant_names())
def name(request):
    return request.param


def _axis_states(ctrl: QuadrotorController) -> np.ndarray:
    v = variant(ctrl.variant)
    return ctrl.state[:3 * v.axis_state_size].reshape(3, v.axis_state_size)


def test_outputs_are_finite_and_states_stay_in_their_box_over_random_states(name):
    rng = np.random.default_rng(7)
    ctrl = QuadrotorController(name)
    ctrl.reset(3)
    low, high = variant(name).axis_state_bounds(PositionParams())
    for _ in range(400):
        x = np.concatenate([rng.uniform(-20, 20, 3) + HOVER[:3], rng.uniform(-8, 8, 3),
                            rng.uniform(-0.6, 0.6, 3), rng.uniform(-2, 2, 3)])
        omega = ctrl.step(rng.uniform(-20, 20, 3) + HOVER[:3], rng.uniform(-5, 5, 3), x, rng.uniform(-np.pi, np.pi))
        assert np.all(np.isfinite(omega)) and np.all((omega >= 0) & (omega <= DEFAULTS["Omega_max"]))
        for key in ("v_ref", "tau_c", "tau_n", "wrench"):
            assert np.all(np.isfinite(ctrl.outputs[key])), key
        states = _axis_states(ctrl)
        assert np.all((states >= low) & (states <= high))


def test_hover_is_an_equilibrium(name):
    """At the set point, at rest: the PD is silent, the desired velocity is
    (all but) zero -- f_ij(0) <= 1e-3 m/s bounds what an untrained FNN may add
    -- and the thrust carries the weight. With f_ij(0) = 0 (f_high = 0) no
    variant adds anything there, and every one holds the hover speed on
    every rotor."""
    ctrl = QuadrotorController(name)
    ctrl.reset(0)
    ctrl.step(HOVER[:3], np.zeros(3), HOVER)
    np.testing.assert_allclose(ctrl.outputs["tau_c"], 0.0, atol=1e-12)
    assert np.all(np.abs(ctrl.outputs["v_ref"]) <= PositionParams().init.f_high + 1e-12)
    # T = m (k_v e_v + g) . z_B (eq. 18): |e_v| <= f_high moves it by at most k_v f_high / g = 5e-4
    assert ctrl.outputs["wrench"][0] == pytest.approx(DEFAULTS["m"] * DEFAULTS["g"], rel=1e-3)

    silent = QuadrotorController(name, PositionParams(init=FnnInit(f_high=0.0)))
    silent.reset(0)
    omega = silent.step(HOVER[:3], np.zeros(3), HOVER)
    np.testing.assert_array_equal(silent.outputs["tau_n"], 0.0)
    np.testing.assert_array_equal(silent.outputs["v_ref"], 0.0)
    np.testing.assert_allclose(silent.outputs["wrench"], [DEFAULTS["m"] * DEFAULTS["g"], 0.0, 0.0, 0.0],
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(omega, hover_rotor_speed(), rtol=1e-12)


def test_the_closed_loop_with_the_plant_fmu_recovers_from_a_tilt(plant_fmu, name):
    """From 20 degrees of roll: within 4 s the tilt is below half of it for
    good (LM keeps a relay limit cycle of about 7.5 degrees at rest, see
    docs/controller.md) and the vehicle is back near the set point."""
    log = fly(plant_fmu, name, lambda t: HOVER[:3], lambda t: np.zeros(3), 6.0, phi=0.35, theta=-0.25)
    late = log["t"] >= 4.0
    assert np.all(np.isfinite(log["x"]))
    assert np.all(np.abs(log["x"][late, 6:8]) < 0.175)  # rad
    assert np.all(np.linalg.norm(log["x"][late, 0:3] - HOVER[:3], axis=1) < 0.5)  # m
