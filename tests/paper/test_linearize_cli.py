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


def test_the_example_script_of_the_docs_runs(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["linearize_fmus.py", str(tmp_path)])
    runpy.run_path(str(ROOT / "docs" / "examples" / "linearize_fmus.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "plant: directional derivatives 16 states" in out
    assert (tmp_path / "controller.json").exists() and (tmp_path / "plant_bode_Omega_1_z.png").exists()
