"""``calibrate`` on a sensed log of an X frame with rotor aerodynamics in a
constant wind, written as another vehicle's log (ENU world, FLU body, the
attitude a quaternion with its scalar last, the rotors by position; issue
42's "Done when", cheap form: one seed, a short log, few names; the 20-seed
coverage of every parameter is ``benchmarks/calibration_coverage.py
--aero``): the rotor coefficients recovered within their 95 % intervals with
white residuals, and the same log fitted with the aerodynamics left out
warns ``residuals-not-white`` first and exits 1 under ``--strict``."""
from __future__ import annotations

import json

import numpy as np
import pytest

from quadrotor_paper.synthetic_log import HIDDEN_X_AERO, WIND, fly_sensed_log, sensed_column_map, sensed_map_toml

AERO = ("k_rotor_drag", "k_inflow", "k_translational_lift")
DURATION = 2.0  # s: 200 rows at the mission's 10 ms step


@pytest.fixture(scope="module")
def x_aero_log(tmp_path_factory):
    return fly_sensed_log(tmp_path_factory.mktemp("x_aero"), seed=1, duration=DURATION, hidden=HIDDEN_X_AERO)


def _fixed(fit) -> dict:
    return {k: v for k, v in HIDDEN_X_AERO.items() if k not in fit} | {"z_0": -15.0}


def test_the_log_is_enu_flu_with_a_quaternion_and_reads_back_as_the_plants_states(x_aero_log):
    """The log holds no NED/FRD column: its map's conversion (frames.py) gives
    back the sensors' NED/FRD states and the commands the plant received."""
    from cosim.calibration import read_log
    from cosim.calibration.frames import convert

    column_map = sensed_column_map(HIDDEN_X_AERO)
    assert (column_map.world, column_map.body, column_map.attitude.scalar) == ("ENU", "FLU", "last")
    converted, plant_map = convert(read_log(x_aero_log, column_map), column_map, HIDDEN_X_AERO.__getitem__)
    flight = read_log(x_aero_log.parent / "flight" / "results.csv")
    for variable, column in plant_map.columns.items():
        ours = np.asarray(converted.columns[column.column], dtype=float)
        if variable.startswith("Omega_r_"):  # the ESCs' telemetry: the plant's rotor speeds with their noise
            noise = ours - np.asarray(flight.columns[f"Quadrotor.{variable}"])
            assert 1.5 < noise.std() < 4.5 and abs(noise.mean()) < 1.0, variable
            continue
        theirs = flight.columns[f"Quadrotor.{variable}" if variable.startswith("Omega") else f"Sensors.{variable}_m"]
        assert ours == pytest.approx(np.asarray(theirs), abs=1e-12), variable


def test_the_x_frame_rotor_coefficients_are_recovered_within_their_intervals(x_aero_log):
    from cosim.calibration import CalibrationSettings, calibrate
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model

    fit = (*AERO, "wind_x", "wind_y")
    fmu = built_fmu("Quadrotor", 2, lambda: model("Quadrotor"))
    cal = calibrate(x_aero_log, fmu, CalibrationSettings(
        fit=list(fit), guess={"k_rotor_drag": 1e-4, "k_inflow": 1e-4, "k_translational_lift": 0.005},
        fix=_fixed(fit), segment=DURATION, holdout=0.0), sensed_column_map(HIDDEN_X_AERO))
    assert cal.converged
    truth = {**HIDDEN_X_AERO, **WIND}
    for j, name in enumerate(fit):
        lo, hi = cal.stats.ci95[j]
        assert lo <= truth[name] <= hi, (name, cal.fit.theta[j], lo, hi)
        assert hi - lo < 0.5 * abs(truth[name]), name  # an interval that says something
    # the model is right: no output's residuals fail the whiteness test, the intervals the classical ones
    assert cal.diagnostics == [] and cal.stats.covariance == "classical", cal.diagnostics


def test_the_same_log_without_the_rotor_aerodynamics_warns_first_and_strict_exits_1(x_aero_log, tmp_path, capsys):
    """The aerodynamics left out (k_* fixed at 0), the thrust coefficient
    fitted, through the command line as a user runs it: the velocity
    residuals are far from white (lag-1 autocorrelation far above white
    noise's 3 / sqrt(n)), the report opens with ``residuals-not-white``,
    calibration.json lists it, and ``--strict`` exits 1 after writing."""
    from quadrotor_paper.cli import main

    columns = tmp_path / "log.toml"
    columns.write_text(sensed_map_toml(HIDDEN_X_AERO))
    fixed = _fixed(("b",)) | dict.fromkeys(AERO, 0.0)
    out = tmp_path / "cal"
    code = main(["calibrate", str(x_aero_log), "--fmu", "Quadrotor", "--columns", str(columns), "--fit", "b",
                 *(f"--fix={k}={v!r}" for k, v in fixed.items()), "--segment", str(DURATION),
                 "--out", str(out), "--quiet", "--no-plots", "--strict"])
    err = capsys.readouterr().err
    assert code == 1, err
    doc = json.loads((out / "calibration.json").read_text())
    report = (out / "report.md").read_text()
    assert report.split("## Warnings\n\n")[1].startswith("* **residuals-not-white**: residuals of ")
    kinds = [w["kind"] for w in doc["warnings"]]
    assert kinds[0] == "residuals-not-white" and doc["covariance"] == "robust", kinds
    flagged = {w["subject"] for w in doc["warnings"] if w["kind"] == "residuals-not-white"}
    assert {"u", "v", "w"} <= flagged, flagged
    n = int(DURATION / 0.01)
    lag1 = [doc["residuals"][v]["lag1_autocorrelation"] for v in ("u", "v", "w")]
    assert min(lag1) > 0.5 > 3 / np.sqrt(n), lag1
    assert "warning: residuals-not-white" in err and "--strict" in err
