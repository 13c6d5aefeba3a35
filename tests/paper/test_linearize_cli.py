"""``fnn-cosim linearize`` and the example script of docs/stability.md."""
from __future__ import annotations

import json
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest

from quadrotor_paper.cli import main
from quadrotor_paper.stability import hover, linearize_plant
from quadrotor_paper.stability.operating_points import STATE_NAMES

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("fmi", ["2", "3"])
def test_linearize_the_plant_at_hover_writes_the_casadi_jacobian(tmp_path, capsys, fmi):
    op = hover()
    omega = op.omega
    argv = ["linearize", "Quadrotor", "--fmi", fmi, "--out", str(tmp_path), "--bode", "Omega_1:z"]
    argv += [f"--start={n}={float(v)!r}" for n, v in zip(STATE_NAMES, op.x)]
    argv += [f"--start=Omega_r_{i + 1}={float(w)!r}" for i, w in enumerate(omega)]
    argv += [f"--input=Omega_{i + 1}={float(w)!r}" for i, w in enumerate(omega)]
    assert main(argv) == 0
    assert "directional derivatives" in capsys.readouterr().out
    saved = np.load(tmp_path / "Quadrotor.npz")
    states = list(saved["states"])
    rows = [states.index(n) for n in STATE_NAMES]
    np.testing.assert_allclose(saved["A"][np.ix_(rows, rows)], linearize_plant(op).A, rtol=1e-10, atol=1e-10)
    document = json.loads((tmp_path / "Quadrotor.json").read_text())
    assert document["time"] == "continuous" and document["method"] == "directional derivatives"
    assert {"name": "w", "unit": "m/s"} in document["states"]
    assert (tmp_path / "Quadrotor_bode_Omega_1_z.png").stat().st_size > 0


def test_linearize_a_controller_gives_its_discrete_step(tmp_path, capsys):
    assert main(["linearize", "ControllerPD", "--input", "z_ref=-1", "--input", "z=-1", "--out", str(tmp_path)]) == 0
    assert "discrete, dt = 0.01 s" in capsys.readouterr().out
    document = json.loads((tmp_path / "ControllerPD.json").read_text())
    assert document["time"] == "discrete" and document["dt"] == 0.01


@pytest.mark.parametrize("argv, words", [
    (["linearize", "Quadrotor", "--input", "nope=1"], "input 'nope': the FMU has no such variable"),
    (["linearize", "Quadrotor", "--parameter", "m=nan"], "--parameter 'm=nan'"),
    (["linearize", "Quadrotor", "--start", "Omega_1=1"], "start value 'Omega_1': not a continuous state"),
    (["linearize", "Quadrotor", "--bode", "Omega_1:nope"], "'nope' is not an output"),
    (["linearize", "NoSuchModel"], "no such FMU file, and no model of that name"),
    (["linearize", "WindGust", "--interface", "cs"], "declares no sample period"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, words):
    assert main(argv + ["--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1


@pytest.mark.parametrize("argv, words", [
    (["linearize", "Quadrotor", "--scenario", "circles", "--time", "1.005"], "--time 1.005: expected a communication point"),
    (["linearize", "Quadrotor", "--scenario", "circles", "--time", "60"], "--time 60.0: expected a communication point"),
    (["linearize", "Plant", "--scenario", "circles", "--time", "1"], "no FMU instance of that name in circles"),
    (["linearize", "Quadrotor", "--time", "1"], "--time: give the run's scenario with --scenario"),
    (["linearize", "Quadrotor", "--scenario", "circles", "--time", "1", "--parameter", "m=1"], "--parameter: with "),
])
def test_bad_scenario_times_and_instances_are_one_line_and_exit_2(tmp_path, capsys, argv, words):
    assert main(argv + ["--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1


def test_linearize_an_instance_of_a_run_at_time_t_is_the_snapshots_linearization(tmp_path, capsys):
    """``--scenario S --time T``: the controller FMU at its state, inputs and
    parameters at T of the run, the same map as linearize_fmu on the
    master's snapshot; the plant at its state then (z of the run, not z_0)."""
    from cosim.linearize.linearization import linearize_fmu
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master

    sets = ["--set", "simulation.duration=3.0", "--set", "controller.variant=pd+lm"]
    assert main(["linearize", "controller", "--scenario", "circles", "--time", "2.5", "--out", str(tmp_path / "c")]
                + sets) == 0
    assert main(["linearize", "Quadrotor", "--scenario", "circles", "--time", "2.5", "--out", str(tmp_path / "p")]
                + sets) == 0
    assert "85 states" in capsys.readouterr().out
    scenario = load_scenario("circles", {"simulation.duration": 3.0, "controller.variant": "pd+lm"})
    with build_master(scenario) as master:
        snap = master.run(3.0, snapshots=[2.5]).snapshots[0]
        path = master.components["controller"].path
    lin = linearize_fmu(path, inputs=snap.inputs_of("controller"), parameters=snap.parameters["controller"],
                        fmu_state=snap.states["controller"], t=2.5)
    saved = np.load(tmp_path / "c" / "ControllerPDLM.npz")
    np.testing.assert_array_equal(saved["A"], lin.A)
    np.testing.assert_array_equal(saved["D"], lin.D)
    plant = json.loads((tmp_path / "p" / "Quadrotor.json").read_text())
    assert plant["operating_point"]["z"] == pytest.approx(snap.outputs["Quadrotor.z"], abs=1e-12)
    assert plant["operating_point"]["z"] != pytest.approx(-15.0, abs=1e-3)  # not the z_0 it started from


def test_the_example_script_of_the_docs_runs(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["linearize_fmus.py", str(tmp_path)])
    runpy.run_path(str(ROOT / "docs" / "examples" / "linearize_fmus.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "plant: directional derivatives 16 states" in out
    assert (tmp_path / "controller.json").exists() and (tmp_path / "plant_bode_Omega_1_z.png").exists()
