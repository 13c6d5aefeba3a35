"""Geometric SE(3) velocity controller (section 3.2): known answers at hover,
signs in the z-down convention, limits, and the closed loop with the plant
FMU (FMI 2.0 co-simulation through fmpy): recovery from a 30 degree tilt
and a velocity step, with and without a one-step input delay."""
from __future__ import annotations

import math
import shutil

import casadi as ca
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import DEFAULTS, QUADROTOR, STATE_NAMES, hover_rotor_speed
from fnn_controller.fast import FastFunction
from fnn_controller.geometric import (GeometricParams, hat, initial_velocity_state, vee, velocity_controller,
                                      velocity_controller_function)

H = 0.01  # s, communication step = controller step
M, G = DEFAULTS["m"], DEFAULTS["g"]


def evaluate(v_ref=(0, 0, 0), v=(0, 0, 0), euler=(0, 0, 0), omega_b=(0, 0, 0), psi_ref=0.0,
             params=GeometricParams(), vel_state=None):
    """The controller's expressions evaluated on numbers (DM in, DM out)."""
    vel_state = initial_velocity_state() if vel_state is None else vel_state
    out = velocity_controller(ca.DM(v_ref), ca.DM(v), ca.DM(euler), ca.DM(omega_b), ca.DM(psi_ref),
                              ca.DM(vel_state), params)
    return {k: np.array(ca.evalf(val)) for k, val in out.items()}


# --------------------------------------------------------------- known answers

@pytest.mark.parametrize("psi", [0.0, 0.7, -2.5])
def test_at_rest_at_the_set_point_e_R_is_zero_and_thrust_is_mg(psi):
    out = evaluate(euler=(0, 0, psi), psi_ref=psi)
    np.testing.assert_allclose(out["e_R"].ravel(), 0.0, atol=1e-15)
    np.testing.assert_allclose(out["e_omega"].ravel(), 0.0, atol=1e-15)
    T, tau = out["wrench"].ravel()[0], out["wrench"].ravel()[1:]
    assert T == pytest.approx(M * G, rel=1e-14)  # eq. 18 with the z-down sign: T = m g > 0
    np.testing.assert_allclose(tau, 0.0, atol=1e-14)
    np.testing.assert_allclose(out["Omega"].ravel(), hover_rotor_speed(), rtol=1e-14)
    # the desired third body axis points down (+e3), as the body z axis at hover
    np.testing.assert_allclose(out["R_ref"][:, 2], [0, 0, 1], atol=1e-15)


def test_printed_sign_of_eq_13_would_ask_for_upside_down_hover():
    # eq. 13 as printed: z_B* = (-k_v e_v - m g e3)/|.| = -e3 at rest; the plant's body z
    # axis at hover is R e3 = +e3, so the printed z_B* is 180 degrees off. We use +F/|F|.
    out = evaluate()
    printed = -(M * G * np.array([0, 0, 1.0])) / (M * G)
    assert out["R_ref"][:, 2] @ printed == pytest.approx(-1.0)


@pytest.mark.parametrize("phi", [0.05, -0.3, 1.0])
def test_attitude_error_of_a_roll_is_sin_phi_and_the_torque_restores(phi):
    out = evaluate(euler=(phi, 0, 0))
    # R* = I, R = exp(phi hat(e1)): e_R = 1/2 (R - R^T)^vee = sin(phi) e1 (eq. 16)
    np.testing.assert_allclose(out["e_R"].ravel(), [math.sin(phi), 0, 0], atol=1e-15)
    tau_phi = out["wrench"].ravel()[1]
    assert tau_phi == pytest.approx(-DEFAULTS["Ix"] * 400.0 * math.sin(phi), rel=1e-12)


def test_a_forward_velocity_error_pitches_up_to_brake():
    params = GeometricParams()
    out = evaluate(v=(1.0, 0, 0), params=params)
    z_ref = out["R_ref"][:, 2]
    # F = m k_v e_v + m g e3; thrust acts along -z_B*, i.e. backwards and up
    np.testing.assert_allclose(z_ref, np.array([params.k_v, 0, G]) / math.hypot(params.k_v, G), rtol=1e-14)
    assert out["wrench"].ravel()[2] > 0  # positive pitch torque: nose up (z down, y right)


def test_hat_and_vee_are_inverse_and_hat_is_the_cross_product():
    w, x = np.array([0.3, -1.2, 2.0]), np.array([-0.5, 0.4, 1.1])
    np.testing.assert_allclose(np.array(ca.evalf(hat(ca.DM(w)))) @ x, np.cross(w, x), rtol=1e-15)
    np.testing.assert_allclose(np.array(ca.evalf(vee(hat(ca.DM(w))))).ravel(), w, rtol=1e-15)


def test_tilt_limit_caps_the_desired_tilt_and_keeps_heading_defined():
    params = GeometricParams()
    for v in [(50.0, 0, 0), (-30.0, 40.0, 0), (0, 0, -80.0), (0, 0, 80.0), (20.0, 20.0, 20.0)]:
        out = evaluate(v=v, params=params)
        z_ref = out["R_ref"][:, 2]
        tilt = math.acos(z_ref[2])
        assert tilt <= params.tilt_max + 1e-12
        R_ref = out["R_ref"]
        np.testing.assert_allclose(R_ref.T @ R_ref, np.eye(3), atol=1e-14)  # eq. 15 in SO(3)
        assert np.linalg.det(R_ref) == pytest.approx(1.0)
    assert math.acos(evaluate(v=(50.0, 0, 0))["R_ref"][2, 2]) == pytest.approx(params.tilt_max)


@pytest.mark.parametrize("seed", range(5))
def test_rotor_speeds_are_finite_and_saturated_for_any_state(seed):
    rng = np.random.default_rng(seed)
    f = velocity_controller_function(GeometricParams())
    n = 2000
    args = [rng.normal(0, 20, (3, n)), rng.normal(0, 20, (3, n)), rng.uniform(-7, 7, (3, n)),
            rng.normal(0, 30, (3, n)), rng.uniform(-7, 7, (1, n)), np.tile(initial_velocity_state()[:, None], n)]
    out = f.map(n)(*args)
    omega = np.array(out[0])
    assert np.all(np.isfinite(omega)) and np.all(np.isfinite(np.array(out[2])))
    assert np.all((omega >= 0.0) & (omega <= DEFAULTS["Omega_max"]))


def test_finite_difference_rule_feeds_forward_the_rate_of_R_ref():
    params = GeometricParams(desired_rate="finite_difference")
    # previous R* = rotation about z_W by -0.01 rad, now R* = I: omega* = +1 rad/s about z
    c, s = math.cos(-0.01), math.sin(-0.01)
    r_prev = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    state = np.concatenate([r_prev.reshape(-1, order="F"), [1.0]])
    out = evaluate(params=params, vel_state=state)
    np.testing.assert_allclose(out["e_omega"].ravel(), [0, 0, -math.sin(0.01) / 0.01], rtol=1e-12, atol=1e-15)
    # not primed (first step after reset): no feed-forward
    state[9] = 0.0
    np.testing.assert_allclose(evaluate(params=params, vel_state=state)["e_omega"].ravel(), 0.0, atol=1e-15)


# ------------------------------------------------------ closed loop with the FMU

@pytest.fixture(scope="module")
def plant_fmu():
    path = cached_fmu(QUADROTOR, fmi_version=2)
    unzip_dir = extract(path)
    yield read_model_description(path), unzip_dir
    shutil.rmtree(unzip_dir, ignore_errors=True)


class PlantFmu:
    """The quadrotor FMU (FMI 2.0 co-simulation) stepped by a step counter."""

    def __init__(self, plant_fmu, **start):
        md, unzip_dir = plant_fmu
        vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip_dir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName="plant")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        if start:
            self.fmu.setReal([vr[f"{k}_0"] for k in start], [float(v) for v in start.values()])
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self._vr_state = [vr[n] for n in STATE_NAMES]
        self._vr_omega = [vr[f"Omega_{i}"] for i in range(1, 5)]
        self._vr_wind = [vr[f"wind_{a}"] for a in "xyz"]
        self.n = 0

    def state(self) -> np.ndarray:
        return np.array(self.fmu.getReal(self._vr_state))

    def set_wind(self, wind):
        self.fmu.setReal(self._vr_wind, [float(w) for w in wind])

    def step(self, omega) -> None:
        self.fmu.setReal(self._vr_omega, [float(o) for o in omega])
        self.fmu.doStep(currentCommunicationPoint=self.n * H, communicationStepSize=H)
        self.n += 1

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def fly_velocity(plant_fmu, v_ref, t_end, params=GeometricParams(), delay=False, **start):
    """Velocity controller + plant FMU, inner loop at 100 Hz (zero-order
    hold over H). ``delay``: the rotor speeds reach the plant one step late."""
    start.setdefault("z", -15.0)
    plant = PlantFmu(plant_fmu, **start)
    ctrl = FastFunction(velocity_controller_function(params), state=("vel_state", "vel_state_next"))
    ctrl.state[:] = initial_velocity_state()
    n = int(round(t_end / H))
    log = {"x": np.zeros((n + 1, 12)), "e_R": np.zeros((n, 3))}
    x = plant.state()
    log["x"][0] = x
    held = None
    for k in range(n):
        ctrl.inputs["v_ref"][:] = v_ref(k * H)
        ctrl.inputs["v"][:] = x[3:6]
        ctrl.inputs["euler"][:] = x[6:9]
        ctrl.inputs["omega_b"][:] = x[9:12]
        ctrl.evaluate()
        ctrl.commit()
        log["e_R"][k] = ctrl.outputs["e_R"]
        omega = ctrl.outputs["Omega"].copy()
        plant.step(held if (delay and held is not None) else omega)
        held = omega
        x = plant.state()
        log["x"][k + 1] = x
    plant.close()
    log["t"] = np.arange(n + 1) * H
    return log


def settling_time(t, y, final, tol):
    """First time after which |y - final| <= tol for good."""
    outside = np.flatnonzero(np.abs(y - final) > tol)
    return 0.0 if outside.size == 0 else t[min(outside[-1] + 1, len(t) - 1)]


def tilt_deg(x):
    return np.degrees(np.arccos(np.clip(np.cos(x[:, 6]) * np.cos(x[:, 7]), -1, 1)))


@pytest.mark.parametrize("delay", [False, True], ids=["no-delay", "one-step-delay"])
@pytest.mark.parametrize("desired_rate", ["zero", "finite_difference"])
def test_recovers_from_a_30_degree_tilt(plant_fmu, delay, desired_rate):
    params = GeometricParams(desired_rate=desired_rate)
    log = fly_velocity(plant_fmu, lambda t: (0, 0, 0), 4.0, params, delay, phi=math.radians(30))
    tilt = tilt_deg(log["x"])
    # measured: 0.53-0.77 s to stay within 1 degree
    assert settling_time(log["t"], tilt, 0.0, 1.0) < 1.0
    final = log["x"][-1]
    assert np.all(np.abs(final[3:6]) < 0.01)  # velocity back to rest
    assert np.all(np.abs(log["e_R"][-1]) < 1e-6)  # no steady-state attitude error
    assert abs(final[2] - (-15.0)) < 0.3  # little height lost (z down)


@pytest.mark.parametrize("delay", [False, True], ids=["no-delay", "one-step-delay"])
def test_recovers_from_a_combined_tilt_with_yaw_error_and_body_rates(plant_fmu, delay):
    log = fly_velocity(plant_fmu, lambda t: (0, 0, 0), 4.0, delay=delay, phi=math.radians(20),
                       theta=math.radians(-20), psi=0.5, p=1.0, q=-1.0, r=0.5)
    t = log["t"]
    assert settling_time(t, tilt_deg(log["x"]), 0.0, 1.0) < 1.2
    assert settling_time(t, log["x"][:, 8], 0.0, 0.01) < 1.5  # yaw back to psi* = 0
    assert np.all(np.abs(log["e_R"][-1]) < 1e-6)


def _steady_speed(v_ref, params=GeometricParams()):
    """Known answer: with the P velocity loop the drag of the plant,
    (k_drag_lin + k_drag_quad |u|) u, is balanced by m k_v (v_ref - u)."""
    k_lin, k_quad, kv = DEFAULTS["k_drag_lin"], DEFAULTS["k_drag_quad"], M * params.k_v
    return (-(k_lin + kv) + math.sqrt((k_lin + kv) ** 2 + 4 * k_quad * kv * v_ref)) / (2 * k_quad)


@pytest.mark.parametrize("delay", [False, True], ids=["no-delay", "one-step-delay"])
def test_tracks_a_velocity_step(plant_fmu, delay):
    log = fly_velocity(plant_fmu, lambda t: (1.0, 0, 0), 4.0, delay=delay)
    u, t = log["x"][:, 3], log["t"]
    u_ss = _steady_speed(1.0)
    assert u[-1] == pytest.approx(u_ss, abs=1e-4)
    # measured: 0.80 s (no delay) / 0.82 s (delay) into +-2 % of the final value
    assert settling_time(t, u, u_ss, 0.02) < 1.0
    assert u.max() < u_ss * (1.2 if delay else 1.1)  # overshoot 6 % / 14 %
    # no steady-state attitude error; the pitch is the one that balances the drag
    assert np.all(np.abs(log["e_R"][-1]) < 1e-6)
    theta_ss = math.atan(GeometricParams().k_v * (u_ss - 1.0) / G)
    assert log["x"][-1, 7] == pytest.approx(theta_ss, abs=1e-6)
    assert np.all(np.abs(log["x"][:, 5]) < 0.15)  # height held during the step (max 0.06 / 0.11 m/s)


def test_tracks_a_climb_step(plant_fmu):
    log = fly_velocity(plant_fmu, lambda t: (0, 0, -1.0), 3.0)
    w, t = log["x"][:, 5], log["t"]
    assert w[-1] == pytest.approx(-_steady_speed(1.0), abs=1e-4)
    assert settling_time(t, w, w[-1], 0.02) < 1.0
    assert np.all(np.abs(log["x"][:, 6:8]) < 1e-9)  # a vertical step does not tilt
