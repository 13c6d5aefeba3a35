"""A PX4 log to a calibrated plant that the paper's controllers fly (issue 42
items 3 and 7, docs/calibration.md "PX4's quadrotor X" and "From a PX4 log to
the paper's controllers"): the built-in maps put PX4's motors on the plant's
rotors by position and spin, the calibrated parameter set reaches the plant
and the controller's mixer in a run, and the walkthrough's commands work on a
ULog of a synthetic X flight."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from quadrotor_paper.cli import main

# PX4's quadrotor X (airframe 4001: CA_ROTOR0..3 at (+,+), (-,-), (+,-), (-,+) in FRD, CA_ROTORi_KM > 0 for
# the first two: counter-clockwise seen from above)
PX4_X = {"positions": ["front-right", "rear-left", "front-left", "rear-right"], "spins": ["ccw", "ccw", "cw", "cw"]}
PX4_ARM_ANGLE = -math.pi / 4  # the plant's arm angle that puts its rotors where PX4's are, of the same spin


@pytest.mark.parametrize("name", ["px4", "px4-pwm"])
def test_the_built_in_maps_state_px4s_x_and_the_plants_spins(name):
    from cosim.calibration import read_column_map
    from cosim.calibration.frames import matching_first_angles
    from fmu_models.models.rotor import SPIN
    from quadrotor_paper.calibrate_cli import _column_map_file

    rotors = read_column_map(_column_map_file(name)).rotors
    assert {"positions": rotors.positions, "spins": rotors.spins} == PX4_X
    # the plant's spin as its yaw reaction's sign about z_B down: +1 is a counter-clockwise rotor seen from above
    assert rotors.variable_spins == ["ccw" if s > 0 else "cw" for s in SPIN]
    assert matching_first_angles(rotors)[0] == PX4_ARM_ANGLE


def test_a_calibrated_parameter_set_reaches_the_plant_and_the_mixer_in_a_run(tmp_path, monkeypatch):
    """A parameter set as ``calibrate`` writes it (its writer, the plant's units),
    an X at PX4's arm angle with rotor aerodynamics, flown by ``fnn-cosim run
    circles --set fmus.Quadrotor.parameter_set=...``: after the run, the plant
    FMU holds every value of the set, and the controller FMU's nominal vehicle
    the arm angle (its mixer an X)."""
    from cosim.calibration.outputs import write_parameter_set
    from fmu_models.catalog import model
    from quadrotor_paper import experiments

    units = {v.name: v.unit for v in model("Quadrotor").variables}
    values = {"arm_angle": PX4_ARM_ANGLE, "b": 7.0e-6, "Ix": 0.035, "d": 1.9e-7, "k_rotor_drag": 2.0e-4,
              "k_inflow": 3.0e-4, "k_translational_lift": 0.01}
    ssv = write_parameter_set({k: (v, units[k]) for k, v in values.items()}, tmp_path / "parameters.ssv", "cal")
    held = {}
    run_once = experiments.run_once

    def run_and_read(scenario, out, master=None, **kw):  # the command's own run, then what its FMUs hold
        result = run_once(scenario, out, master=master, **kw)
        held["plant"] = master.components["Quadrotor"].get_reals(list(values))
        held["vehicle"] = master.components["controller"].get_reals(["vehicle.arm_angle", "vehicle.b", "vehicle.d"])
        return result

    monkeypatch.setattr(experiments, "run_once", run_and_read)
    code = main(["run", "circles", "--set", f"fmus.Quadrotor.parameter_set={ssv}", "--set", "simulation.duration=0.05",
                 "--out", str(tmp_path / "twin"), "--quiet", "--no-plots"])
    assert code == 0
    assert held["plant"] == values  # every value of the set, to the bit
    assert held["vehicle"] == {"vehicle.arm_angle": values["arm_angle"], "vehicle.b": values["b"],
                               "vehicle.d": values["d"]}
