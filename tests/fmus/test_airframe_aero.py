"""Airframes (arm_angle: plus, X) and rotor aerodynamics of the plant (docs/plant-model.md):
the plus frame bit for bit as before, the X frame's mixer and plant in agreement, and each
aerodynamic term against a hand-written numpy version of the equations."""
from __future__ import annotations

import math
from ctypes import POINTER, c_double

import numpy as np
import pytest

from cosim.linearize.linearization import linearize_fmu
from fmu_models.models.quadrotor import DEFAULTS, QUADROTOR, hover_rotor_speed
from fmu_models.models.rotor import rotor_speeds_squared, thrust_and_torques

X = math.pi / 4
HOVER = hover_rotor_speed()
PARAMETERS = [v.name for v in QUADROTOR.parameters]
STATES = [v.name for v in QUADROTOR.states]
INPUTS = [v.name for v in QUADROTOR.inputs]
OUTPUTS = [v.name for v in QUADROTOR.outputs]


def _bits(values) -> np.ndarray:
    return np.asarray(values, dtype=float).view(np.int64)


def test_the_plus_frame_is_the_old_rotor_model_bit_for_bit():
    """arm_angle = 0, as a number and as a CasADi symbol set to 0, gives the
    plus formulas of before to the last bit, forward and inverse."""
    import casadi as ca

    rng = np.random.default_rng(7)
    o = rng.uniform(0, 900, size=(200, 4)) ** 2
    b, d, l = DEFAULTS["b"], DEFAULTS["d"], DEFAULTS["l"]
    old = np.array([b * (o[:, 0] + o[:, 1] + o[:, 2] + o[:, 3]), b * l * (o[:, 3] - o[:, 1]),
                    b * l * (o[:, 0] - o[:, 2]), d * (-o[:, 0] + o[:, 1] - o[:, 2] + o[:, 3])])
    new = np.array([[float(v) for v in thrust_and_torques(row, b, d, l)] for row in o]).T
    assert np.array_equal(_bits(new), _bits(old))
    sym = ca.SX.sym("o", 4), ca.SX.sym("a")
    f = ca.Function("f", list(sym), [ca.vertcat(*thrust_and_torques(ca.vertsplit(sym[0]), b, d, l, sym[1]))])
    assert np.array_equal(_bits(np.hstack([f(row, 0.0).full() for row in o])), _bits(old))

    w = rng.normal(size=(200, 4)) * [10, 0.5, 0.5, 0.05]
    t, roll, pitch, yaw = w[:, 0] / (4 * b), w[:, 1] / (2 * b * l), w[:, 2] / (2 * b * l), w[:, 3] / (4 * d)
    old_inverse = np.array([t + pitch - yaw, t - roll + yaw, t - pitch - yaw, t + roll + yaw])
    inverse = np.array([[float(v) for v in rotor_speeds_squared(*row, b, d, l)] for row in w]).T
    assert np.array_equal(_bits(inverse), _bits(old_inverse))


def _ode(x, u, p):
    f = QUADROTOR.functions
    return np.asarray(f["ode"](0.0, x, u, p)).ravel(), np.asarray(f["out"](0.0, x, u, p)).ravel()


def _point(**parameters):
    p = np.array(QUADROTOR.parameter_values(**parameters))
    x = np.array([DEFAULTS[f"{n}_0"] for n in STATES[:12]] + [HOVER] * 4)
    u = np.array([HOVER] * 4 + [0.0] * 3)
    return x, u, p


def test_x_frame_hovers_on_equal_speeds_and_its_mixer_inverts_the_plant():
    """In the X frame equal rotor speeds make no roll or pitch torque (hover
    trim: equal speeds), and the rotor speeds the X mixer gives for a pure roll
    torque make exactly that torque in the plant (mixer and plant agree)."""
    b, d, l = DEFAULTS["b"], DEFAULTS["d"], DEFAULTS["l"]
    weight = DEFAULTS["m"] * DEFAULTS["g"]
    trim = rotor_speeds_squared(weight, 0.0, 0.0, 0.0, b, d, l, X)
    assert np.allclose(trim, HOVER**2, rtol=1e-15)
    x, u, p = _point(arm_angle=X)
    xdot, y = _ode(x, u, p)
    assert np.abs(xdot[:12]).max() < 1e-12 and np.abs(y[1:]).max() < 1e-12 and y[0] == pytest.approx(weight)

    wrench = (weight, 0.05, 0.0, 0.0)  # N, N m: a pure roll torque
    squares = np.array([float(s) for s in rotor_speeds_squared(*wrench, b, d, l, X)])
    # the X rolls with the rotor pairs on either side of x_B
    assert squares[0] == pytest.approx(squares[1], rel=1e-12) and squares[2] == pytest.approx(squares[3], rel=1e-12)
    u[:4] = np.sqrt(squares)
    _, y = _ode(x, u, p)
    assert y == pytest.approx(wrench, abs=1e-12)
    # rotor i at pi/4 + (i-1) pi/2: rotors 1 (front right) and 2 (back right) raised, with the right side up
    # a positive roll about x_B (y right, z down) needs the left side up: rotors 3 and 4 faster
    assert squares[2] > squares[0] and squares[3] > squares[1]


def _rotation(phi, theta, psi):
    c, s = np.cos, np.sin
    return np.array([
        [c(psi) * c(theta), c(psi) * s(phi) * s(theta) - c(phi) * s(psi), s(phi) * s(psi) + c(phi) * c(psi) * s(theta)],
        [c(theta) * s(psi), c(phi) * c(psi) + s(phi) * s(psi) * s(theta), c(phi) * s(psi) * s(theta) - c(psi) * s(phi)],
        [-s(theta), c(theta) * s(phi), c(phi) * c(theta)]])


def _reference(x, u, p):
    """The plant's translational and rotational accelerations written again in numpy
    (docs/plant-model.md: rotor positions, eqs. (4), (9)-(11), drag, the three rotor terms)."""
    P = dict(zip(PARAMETERS, p))
    vel, (phi, theta, psi), rates = x[3:6], x[6:9], x[9:12]
    speeds = np.clip(u[:4], 0, P["Omega_max"])  # tau_m = 0
    R = _rotation(phi, theta, psi)
    v_rel = vel - u[4:7]
    drag = -(P["k_drag_lin"] + P["k_drag_quad"] * np.sqrt(v_rel @ v_rel + 1e-12)) * v_rel
    force_b, moment_b = np.zeros(3), np.zeros(3)
    spin = np.array([-1, 1, -1, 1])
    for i, omega in enumerate(speeds):
        a = P["arm_angle"] + i * np.pi / 2
        r = P["l"] * np.array([np.cos(a), np.sin(a), 0.0])
        hub = R.T @ v_rel + np.cross(rates, r)
        thrust = P["b"] * omega**2 - P["k_inflow"] * omega * (-hub[2]) + P["k_translational_lift"] * (hub[0]**2 + hub[1]**2)
        f = np.array([-P["k_rotor_drag"] * omega * hub[0], -P["k_rotor_drag"] * omega * hub[1], -thrust])
        force_b += f
        moment_b += np.cross(r, f) + np.array([0, 0, P["d"] * spin[i] * omega**2])
    accel = (R @ force_b + drag) / P["m"] + np.array([0, 0, P["g"]])
    inertia = np.array([P["Ix"], P["Iy"], P["Iz"]])
    alpha = (moment_b - np.cross(rates, inertia * rates)) / inertia
    return accel, alpha, (-force_b[2], *moment_b)


@pytest.mark.parametrize("arm_angle", [0.0, X])
@pytest.mark.parametrize("term", ["k_rotor_drag", "k_inflow", "k_translational_lift", "all"])
def test_each_rotor_term_matches_a_numpy_reference(term, arm_angle):
    """One random state (tilted, turning, climbing, in wind): the plant's
    accelerations and reported thrust/torques with one aerodynamic term (or all)
    against the numpy reference, and the term's effect is no round-off."""
    rng = np.random.default_rng(3)
    coefficients = {"k_rotor_drag": 2e-4, "k_inflow": 3e-4, "k_translational_lift": 0.02}
    on = coefficients if term == "all" else {term: coefficients[term]}
    x, u, p = _point(arm_angle=arm_angle, **on)
    x[3:12] = rng.normal(size=9) * [4, 4, 2, 0.3, 0.3, 1, 2, 2, 2]
    u[:4] = HOVER + rng.normal(size=4) * 40
    u[4:] = rng.normal(size=3) * 3
    xdot, y = _ode(x, u, p)
    accel, alpha, wrench = _reference(x, u, p)
    assert xdot[3:6] == pytest.approx(accel, rel=1e-12, abs=1e-12)
    assert xdot[9:12] == pytest.approx(alpha, rel=1e-12, abs=1e-11)
    assert y == pytest.approx(wrench, rel=1e-12, abs=1e-13)
    _, _, p_off = _point(arm_angle=arm_angle)
    off, _ = _ode(x, u, p_off)
    assert np.abs(off[3:12] - xdot[3:12]).max() > 1e-3  # the term acts


def test_the_fmu_derivatives_carry_the_x_frame_and_its_aerodynamics(quadrotor_fmu2):
    """The built FMU (Model Exchange) at one random state agrees with the numpy
    reference: the exported C is the CasADi model's."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Model

    rng = np.random.default_rng(11)
    on = {"arm_angle": X, "k_rotor_drag": 2e-4, "k_inflow": 3e-4, "k_translational_lift": 0.02}
    x, u, p = _point(**on)
    x[3:12] = rng.normal(size=9) * [4, 4, 2, 0.3, 0.3, 1, 2, 2, 2]
    u[:4] = HOVER + rng.normal(size=4) * 40
    u[4:] = rng.normal(size=3) * 3
    md = read_model_description(str(quadrotor_fmu2))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extract(str(quadrotor_fmu2)),
                    modelIdentifier=md.modelExchange.modelIdentifier, instanceName="aero")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.setReal([vr[n] for n in on], list(on.values()))
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.newDiscreteStates()
        fmu.enterContinuousTimeMode()
        fmu.setReal([vr[n] for n in INPUTS], list(u))
        states, xdot = np.ascontiguousarray(x), np.zeros(len(x))
        fmu.setContinuousStates(states.ctypes.data_as(POINTER(c_double)), len(x))
        fmu.getDerivatives(xdot.ctypes.data_as(POINTER(c_double)), len(x))
        y = np.array(fmu.getReal([vr[n] for n in OUTPUTS]))
        fmu.terminate()
    finally:
        fmu.freeInstance()
    accel, alpha, wrench = _reference(x, u, p)
    assert xdot[3:6] == pytest.approx(accel, rel=1e-12, abs=1e-12)
    assert xdot[9:12] == pytest.approx(alpha, rel=1e-12, abs=1e-11)
    assert y == pytest.approx(wrench, rel=1e-12, abs=1e-13)


def test_rotor_drag_adds_its_damping_to_the_linearized_velocity_rows(quadrotor_fmu2):
    """At hover in still air the H-force of the four rotors, -k Omega_h v each,
    adds -4 k Omega_h / m to du/du and dv/dv (body drag off); the vertical row
    has none of it, the inflow term's -4 k_inflow Omega_h / m instead."""
    k, k_in, m = 2e-4, 3e-4, DEFAULTS["m"]
    lin = linearize_fmu(quadrotor_fmu2, parameters={"k_rotor_drag": k, "k_inflow": k_in, "arm_angle": X,
                                                    "k_drag_lin": 0.0, "k_drag_quad": 0.0},
                        start={"z": -15.0}, inputs={f"Omega_{i}": HOVER for i in range(1, 5)})
    A = lin.A
    i = {n: lin.system.state_labels.index(n) for n in ("u", "v", "w")}
    assert A[i["u"], i["u"]] == pytest.approx(-4 * k * HOVER / m, rel=1e-12)
    assert A[i["v"], i["v"]] == pytest.approx(-4 * k * HOVER / m, rel=1e-12)
    assert A[i["w"], i["w"]] == pytest.approx(-4 * k_in * HOVER / m, rel=1e-12)
    assert abs(A[i["u"], i["v"]]) < 1e-15


def test_the_stability_analysis_of_an_x_plant_flown_by_its_x_mixer_is_the_plus_ones(quadrotor_fmu2):
    """The stability analysis reads the plant FMU: in forward flight in wind, an
    X plant with the X mixer (the nominal vehicle's arm_angle) has the closed-loop
    poles of the plus plant with the plus mixer (the mixer gives the same
    wrench); the X plant with the plus mixer does not."""
    from fnn_controller import GeometricParams, VehicleParams
    from quadrotor_paper.stability.linearize import linearize_plant_fmu
    from quadrotor_paper.stability.loops import LoopModel
    from quadrotor_paper.stability.operating_points import forward_flight

    def poles(plant, vehicle):
        op = forward_flight(2.5, 3.0, plant_parameters=plant, geometric=GeometricParams(vehicle=vehicle))
        A = LoopModel(op, plant=linearize_plant_fmu(quadrotor_fmu2, op)).closed_loop().A
        return np.sort_complex(np.linalg.eigvals(A))

    plus = poles({}, VehicleParams())
    x = poles({"arm_angle": X}, VehicleParams(arm_angle=X))
    assert x == pytest.approx(plus, rel=1e-7, abs=1e-9)
    mismatched = poles({"arm_angle": X}, VehicleParams())
    assert np.abs(mismatched - plus).max() > 1e-2
