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

__all__ = ["HIDDEN", "HIDDEN_X_AERO", "WIND", "LOGGED", "SENSED", "fly_synthetic_log", "fly_sensed_log", "sensed_column_map"]

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
    from cosim.scenario import load_scenario
    from cosim.assembly import build_master

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


def fly_sensed_log(out: str | Path, seed: int, duration: float = 10.0,
                   hidden: Mapping[str, float] | None = None) -> Path:
    """:func:`fly_synthetic_log` in ``circles_sensors`` (its noise drawn from
    ``seed``), recording :data:`SENSED`; read it with :func:`sensed_column_map`."""
    return fly_synthetic_log(out, duration, hidden=hidden, scenario="circles_sensors", record=SENSED,
                             extra={"simulation.seed": seed})


def sensed_column_map():
    """The column map of a :func:`fly_sensed_log` log: the plant's states from the sensors' columns."""
    from cosim.calibration import ColumnMap

    columns = {s: f"Sensors.{s}_m" for s in _STATES}
    columns |= {c.split(".")[1]: c for c in LOGGED[12:]}
    return ColumnMap.from_document({"columns": columns}, "sensed log")
