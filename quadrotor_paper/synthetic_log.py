"""A synthetic flight log of the plant with hidden parameters, flown by the project.

The circles mission (closed loop: controller, plant, a constant wind: the
gust's reversals moved past the end) flown with the plant's parameters
changed to ``hidden`` (:data:`HIDDEN`; :data:`HIDDEN_X_AERO`: an X frame with
rotor aerodynamics, the controller's mixer an X too as it reads the plant's), recording what a vehicle's log holds: the 12 rigid-body
states, the commanded rotor speeds and the measured ones. It is what
``fnn-cosim calibrate`` is tested and benchmarked on (docs/calibration.md):
the parameters are hidden from the calibration, which must find them.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import math

__all__ = ["HIDDEN", "HIDDEN_X_AERO", "WIND", "LOGGED", "SENSED", "LOG_MOTORS", "ESC_NOISE", "SENSED_MAP",
           "fly_synthetic_log", "fly_sensed_log", "sensed_map_toml", "sensed_column_map"]

# the vehicle the log is flown with: Table 1's with five values changed (and a motor lag)
HIDDEN = {"b": 7.0e-6, "Ix": 0.035, "Iy": 0.045, "k_drag_lin": 0.25, "tau_m": 0.03}
# issue 42's "Done when": an X frame with the rotor aerodynamics, every parameter fitted there off its default.
# The rotor coefficients are of RotorPy's hummingbird's order scaled to this vehicle's rotor speed (about 630
# rad/s): the four rotors' H-force 4 k_rotor_drag Omega about 0.5 N per m/s, as large as the body drag.
HIDDEN_X_AERO = {**HIDDEN, "arm_angle": math.pi / 4, "d": 1.9e-7, "Iz": 0.024, "k_drag_quad": 0.05,
                 "k_rotor_drag": 2.0e-4, "k_inflow": 3.0e-4, "k_translational_lift": 0.01}
_STATES = ("x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")
# the wind of every log: circles' gust, 3 m/s along [-1, -1, 0] (world, NED), held
WIND = {"wind_x": -3.0 / 2 ** 0.5, "wind_y": -3.0 / 2 ** 0.5, "wind_z": 0.0}
LOGGED = tuple(f"Quadrotor.{n}" for n in _STATES) + tuple(f"Quadrotor.Omega_{i}" for i in range(1, 5)) + \
    tuple(f"Quadrotor.Omega_r_{i}" for i in range(1, 5))


def fly_synthetic_log(out: str | Path, duration: float = 10.0, hidden: Mapping[str, float] | None = None,
                      scenario: str = "circles", extra: Mapping[str, object] | None = None,
                      record: tuple[str, ...] = LOGGED) -> Path:
    """Fly the log into the folder ``out``; returns its ``results.csv``.
    ``extra``: more overrides of the scenario (dotted keys)."""
    from cosim.files import output_folder
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master

    from .experiments import run_once

    hidden = HIDDEN if hidden is None else hidden
    overrides = {"simulation.duration": float(duration), "wind.switch_times": [1e6, 2e6],
                 "record.signals": list(dict.fromkeys(list(record) + [  # and what the mission's metrics read
                     "Quadrotor.x", "Quadrotor.y", "Quadrotor.z", "reference.x", "reference.y", "reference.z"]))}
    overrides |= {f"fmus.Quadrotor.parameters.{k}": float(v) for k, v in hidden.items()}
    overrides |= dict(extra or {})
    sc = load_scenario(scenario, overrides)
    out = output_folder(out)
    with build_master(sc) as master:
        result, _ = run_once(sc, out, master=master)
    if result.status != "ok":
        raise RuntimeError(f"the synthetic flight {result.status}: {result.error}")
    return out / "results.csv"


# A log as a vehicle's sensors give it: the measured states of circles_sensors' Measurement12 (motion-capture
# position and attitude, velocity and gyro noise), the rotor commands the plant received and the rotor speeds.
SENSED = tuple(f"Sensors.{s}_m" for s in _STATES) + LOGGED[12:]
# The log's motors in its own order, by position: PX4's numbering of its quadrotor X (1 front-right, 2 rear-left,
# 3 front-left, 4 rear-right) and of its quadrotor plus (1 right, 2 left, 3 front, 4 rear); the plant's rotor i
# sits at arm_angle + (i - 1) pi/2 from the nose (docs/plant-model.md): an X at pi/4, a plus at 0. Positions only:
# each motor turns as the plant's rotor there does (the map states no spins).
LOG_MOTORS = {"X": ("front-right", "rear-left", "front-left", "rear-right"), "plus": ("right", "left", "front", "rear")}
ESC_NOISE = 3.0  # rad/s: the ESCs' rotor-speed telemetry, white, about 0.5 % of the hover speed (630 rad/s)
# the ESC noise's own stream of the seed (the Measurement12 noise is the scenario's stream 1, the FNN's 0)
_ESC_STREAM = 2
# The column map of the log :func:`fly_sensed_log` writes, as a user writes one (docs/calibration.md,
# "Frames"): ENU world, FLU body, the attitude a quaternion with its scalar last (x, y, z, w: ROS's order),
# the rotor commands by position; the ESCs' speeds are the FMU rotors' at those places (Omega_r_i below).
SENSED_MAP = """\
world = "ENU"
body = "FLU"
mirror_check = false   # the mirrors' two refits would double every fit of the coverage study; frames.py's tests check them

[columns]
x = "pos_x"
y = "pos_y"
z = "pos_z"
u = "vel_x"
v = "vel_y"
w = "vel_z"
p = "gyro_x"
q = "gyro_y"
r = "gyro_z"
{speeds}

[frames]
world = [["x", "y", "z"], ["u", "v", "w"]]
body = [["p", "q", "r"]]
euler = ["phi", "theta", "psi"]

[attitude]
quaternion = ["q_x", "q_y", "q_z", "q_w"]
scalar = "last"

[rotors]
columns = ["motor_1", "motor_2", "motor_3", "motor_4"]
positions = [{positions}]
variables = ["Omega_1", "Omega_2", "Omega_3", "Omega_4"]
first_angle = "arm_angle"
"""


def _layout(arm_angle: float) -> tuple[tuple[str, ...], list[int]]:
    """The log's motor positions (:data:`LOG_MOTORS`) of the airframe
    ``arm_angle`` (rad) and the plant's rotor (1-4) at each."""
    from cosim.calibration.columns import POSITIONS

    angles = [math.degrees(arm_angle + i * math.pi / 2) % 360.0 for i in range(4)]

    def gap(a, b):
        return abs((a - b + 180.0) % 360.0 - 180.0)

    for motors in LOG_MOTORS.values():
        rotors = [min(range(4), key=lambda i: gap(angles[i], POSITIONS[m])) + 1 for m in motors]
        if all(gap(angles[i - 1], POSITIONS[m]) < 1e-6 for i, m in zip(rotors, motors)):
            return motors, rotors
    raise ValueError(f"arm_angle = {arm_angle}: the plant is neither an X nor a plus ({list(LOG_MOTORS)})")


def fly_sensed_log(out: str | Path, seed: int, duration: float = 10.0,
                   hidden: Mapping[str, float] | None = None) -> Path:
    """:func:`fly_synthetic_log` in ``circles_sensors`` (its noise drawn from
    ``seed``), written as another vehicle's log would be: ``log.csv`` in
    ``out`` (returned), read with :func:`sensed_column_map`.

    The states are Measurement12's (motion capture: 2 mm position, 0.005 rad
    on each Euler angle; velocity 0.02 m/s; gyro 0.01 rad/s; white), written
    in an ENU world and an FLU body: position and velocity ``(y, x, -z)`` of
    the plant's NED ones, body rates ``(p, -q, -r)``, and the attitude as the
    quaternion ``(x, y, z, w)`` of the FLU-to-ENU rotation ``W R B`` (``R =
    Rz(psi) Ry(theta) Rx(phi)`` of the measured angles, paper eq. 8; ``W``
    swaps north and east and negates down, ``B = diag(1, -1, -1)``; its sign
    kept continuous). The rotor commands the plant received, exact (the
    flight controller's own), and the rotor speeds with :data:`ESC_NOISE`
    (the ESCs' telemetry), both in the log's motor order :data:`LOG_MOTORS`.
    Written here with the rotation matrices spelt out, not with
    :mod:`cosim.calibration.frames`, which reads it back: a sign wrong there
    is not cancelled by the same sign here."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from cosim.calibration import read_log

    hidden = HIDDEN if hidden is None else hidden
    out = Path(out)
    flown = fly_synthetic_log(out / "flight", duration, hidden=hidden, scenario="circles_sensors", record=SENSED,
                              extra={"simulation.seed": seed})
    log = read_log(flown)
    m = {s: np.asarray(log.columns[f"Sensors.{s}_m"], dtype=float) for s in _STATES}
    R_ned_frd = Rotation.from_euler("ZYX", np.column_stack([m["psi"], m["theta"], m["phi"]])).as_matrix()
    W = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # NED <-> ENU (its own inverse)
    B = np.diag([1.0, -1.0, -1.0])  # FRD <-> FLU (its own inverse)
    q = Rotation.from_matrix(W @ R_ned_frd @ B).as_quat()  # scalar last
    q *= np.where(np.cumsum(np.r_[0, np.einsum("ij,ij->i", q[1:], q[:-1]) < 0]) % 2 == 1, -1.0, 1.0)[:, None]
    columns = {"time": log.times, "pos_x": m["y"], "pos_y": m["x"], "pos_z": -m["z"],
               "vel_x": m["v"], "vel_y": m["u"], "vel_z": -m["w"],
               "q_x": q[:, 0], "q_y": q[:, 1], "q_z": q[:, 2], "q_w": q[:, 3],
               "gyro_x": m["p"], "gyro_y": -m["q"], "gyro_z": -m["r"]}
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_ESC_STREAM,)))
    _, rotors = _layout(float(hidden.get("arm_angle", 0.0)))
    for k, i in enumerate(rotors, start=1):
        columns[f"motor_{k}"] = np.asarray(log.columns[f"Quadrotor.Omega_{i}"], dtype=float)
    for k, i in enumerate(rotors, start=1):
        speed = np.asarray(log.columns[f"Quadrotor.Omega_r_{i}"], dtype=float)
        columns[f"esc_speed_{k}"] = speed + ESC_NOISE * rng.standard_normal(speed.size)
    path = out / "log.csv"
    np.savetxt(path, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns),
               comments="", fmt="%.17g")
    return path


def sensed_map_toml(hidden: Mapping[str, float] | None = None) -> str:
    """:data:`SENSED_MAP` for a :func:`fly_sensed_log` log of the plant
    ``hidden`` (its ``arm_angle``): the log's motors at their positions, its
    ESCs' speed columns named for the plant's rotors there."""
    motors, rotors = _layout(float((HIDDEN if hidden is None else hidden).get("arm_angle", 0.0)))
    speeds = "\n".join(f'Omega_r_{i} = "esc_speed_{k}"' for k, i in sorted(enumerate(rotors, start=1),
                                                                          key=lambda ki: ki[1]))
    return SENSED_MAP.format(speeds=speeds, positions=", ".join(f'"{m}"' for m in motors))


def sensed_column_map(hidden: Mapping[str, float] | None = None):
    """The column map of a :func:`fly_sensed_log` log of the plant ``hidden`` (:func:`sensed_map_toml`)."""
    import tomllib

    from cosim.calibration import ColumnMap

    return ColumnMap.from_document(tomllib.loads(sensed_map_toml(hidden)), "sensed log")
