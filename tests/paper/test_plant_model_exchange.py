"""Our plant flown as Model Exchange: the master integrates the Quadrotor
FMU's derivatives with CVODE (its Co-Simulation form steps RK4 at the
communication step), in the closed loop of the paper's circles mission.
The whole 50 s mission and its cost beside Co-Simulation:
``benchmarks/model_exchange.py``."""
from __future__ import annotations

import numpy as np
import pytest

from quadrotor_paper.cli import main

DURATION = "10.0"  # s of the circles mission: the climb into the first circle, the learning at work


def positions(out) -> np.ndarray:
    header = (out / "results.csv").read_text().split("\n", 1)[0].split(",")
    rows = np.loadtxt(out / "results.csv", delimiter=",", skiprows=1)
    return rows[:, [header.index(f"Quadrotor.{k}") for k in "xyz"]]


@pytest.mark.parametrize("version", ["2", "3"])
def test_circles_with_the_plant_as_model_exchange_lands_on_the_co_simulation_run(tmp_path, version):
    common = ["--no-plots", "--quiet", "--set", f"simulation.duration={DURATION}",
              "--set", f"fmus.Quadrotor.fmi_version={version}"]
    assert main(["run", "circles", "--out", str(tmp_path / "cs"), *common]) == 0
    assert main(["run", "circles", "--out", str(tmp_path / "me"), *common,
                 "--set", "fmus.Quadrotor.interface=ModelExchange",
                 "--set", "fmus.Quadrotor.solver.relative_tolerance=1e-8"]) == 0
    cs, me = positions(tmp_path / "cs"), positions(tmp_path / "me")
    assert np.ptp(cs[:, 2]) > 0.5  # it flew: the climb of the first circle
    rmse = np.sqrt(np.mean(np.sum((cs - me) ** 2, axis=1)))
    assert rmse < 1e-4
    assert not np.array_equal(cs, me)  # two integrators, not one run read twice
