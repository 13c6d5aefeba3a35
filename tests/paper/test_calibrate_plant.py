"""``fnn-cosim calibrate`` on the plant: a synthetic flight log flown by the
project with hidden parameters (quadrotor_paper.synthetic_log), noise-free:
every identifiable parameter recovered to 1e-6 relative, a parameter without
excitation reported not identifiable (docs/calibration.md)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from quadrotor_paper.cli import main
from quadrotor_paper.synthetic_log import HIDDEN, fly_synthetic_log


@pytest.fixture(scope="module")
def flight_log(tmp_path_factory):
    return fly_synthetic_log(tmp_path_factory.mktemp("flight"), duration=4.0)


def _calibrate(tmp_path, log, *args):
    # no figures: drawing the plant's 16 outputs took more CPU than the fit (their drawing is the command's
    # test's, tests/engine/test_engine_calibration.py)
    # the flight log is exact (the plant's own output, no noise): segments start from its states, as
    # initial_states = "recorded" does (the default, "estimated", is for noisy logs: 6x this file's CPU)
    out = tmp_path / "out"
    settings = tmp_path / "recorded.toml"
    settings.write_text('initial_states = "recorded"\n')
    code = main(["calibrate", str(log), *map(str, args), "--segment", "2", "--out", str(out), "--quiet",
                 "--no-plots", "--settings", str(settings)])
    return code, out


def test_the_hidden_parameters_and_the_wind_recovered_to_1e_6_from_guesses_far_off(tmp_path, flight_log, capsys):
    code, out = _calibrate(tmp_path, flight_log, "--fmu", "Quadrotor", "--fit", "b,Ix,k_drag_lin,tau_m,wind_x,wind_y",
                           "--fix", f"Iy={HIDDEN['Iy']}", "--guess", "b=5e-6", "--guess", "Ix=0.025",
                           "--guess", "k_drag_lin=0.15", "--guess", "tau_m=0.02")
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "calibration.json").read_text())
    p = doc["parameters"]
    for name in ("b", "Ix", "k_drag_lin", "tau_m"):
        assert p[name]["identifiable"]
        assert p[name]["value"] == pytest.approx(HIDDEN[name], rel=1e-6), name
    wind = -3.0 / 2 ** 0.5  # circles' gust: 3 m/s along [-1, -1, 0], held (its reversals moved past the end)
    assert p["wind_x"]["value"] == pytest.approx(wind, rel=1e-6)
    assert p["wind_y"]["value"] == pytest.approx(wind, rel=1e-6)
    assert "b = " in (out / "calibration.toml").read_text()
    assert 'name="Ix"' in (out / "parameters.ssv").read_text()
    assert not list(out.glob("*.png")) and "](" not in (out / "report.md").read_text()  # --no-plots


def test_the_casadi_way_and_the_fmu_way_give_the_same_estimates(flight_log):
    # the plant's own CasADi definition (compiled segments, exact sensitivities) against the FMU's
    # directional derivatives, on the same problem: the same optimum, the same intervals
    from cosim.calibration import CalibrationSettings, calibrate
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model

    fmu = built_fmu("Quadrotor", 2, lambda: model("Quadrotor"))
    fixed = {k: v for k, v in HIDDEN.items() if k not in ("b", "Ix")}
    cals = {way: calibrate(flight_log, fmu, CalibrationSettings(
        fit=["b", "Ix", "wind_x", "wind_y"], guess={"b": 6e-6, "Ix": 0.03}, fix=fixed, segment=1.0, holdout=0.0,
        stop=3.0, jacobian=way, initial_states="recorded")) for way in ("casadi", "derivatives")}
    assert cals["casadi"].fit.method.startswith("forward sensitivities (CasADi")
    assert cals["derivatives"].fit.method == "forward sensitivities (directional derivatives)"
    a, b = cals["casadi"].fit.theta, cals["derivatives"].fit.theta
    assert a == pytest.approx(b, rel=1e-10)
    assert a[0] == pytest.approx(HIDDEN["b"], rel=1e-9) and a[1] == pytest.approx(HIDDEN["Ix"], rel=1e-9)
    # the statistics from either Jacobian: the same standard errors per unit residual (F^-1's diagonal) to the
    # generic way's Magnus step (the log is exact: the residual variance itself is round-off, 1e-30 or 1e-24
    # as each way's last step left it)
    per_unit = {way: c.stats.std / np.sqrt(c.stats.residual_variance) for way, c in cals.items()}
    assert per_unit["casadi"] == pytest.approx(per_unit["derivatives"], rel=0.2)


def test_without_a_c_compiler_the_casadi_way_runs_in_casadis_virtual_machine(flight_log, tmp_path, monkeypatch):
    from cosim.calibration import CalibrationSettings, calibrate
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model

    monkeypatch.setenv("COSIM_CACHE", str(tmp_path / "empty-cache"))  # nothing compiled yet
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    fmu = built_fmu("Quadrotor", 2, lambda: model("Quadrotor"))
    fixed = {k: v for k, v in HIDDEN.items() if k != "Ix"}
    cal = calibrate(flight_log, fmu, CalibrationSettings(fit=["Ix", "wind_x", "wind_y"], guess={"Ix": 0.03},
                                                         fix=fixed, segment=0.5, holdout=0.0, stop=1.0,
                                                         jacobian_stride=1, initial_states="recorded"))
    assert cal.fit.method.endswith("run by CasADi's virtual machine")
    assert cal.fit.theta[0] == pytest.approx(HIDDEN["Ix"], rel=1e-9)
    assert not any((tmp_path / "empty-cache").glob("*.so"))


def test_a_parameter_the_flight_does_not_excite_is_not_identifiable(tmp_path, flight_log, capsys):
    # Omega_max only clips: a flight that never saturates a rotor says nothing about it
    fix = [a for k, v in HIDDEN.items() if k != "b" for a in ("--fix", f"{k}={v}")]
    code, out = _calibrate(tmp_path, flight_log, "--fmu", "Quadrotor", "--fit", "b,Omega_max,wind_x,wind_y", *fix,
                           "--guess", "Omega_max=950")
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "calibration.json").read_text())
    om = doc["parameters"]["Omega_max"]
    assert om == {**om, "identifiable": False, "value": None, "std": None, "ci95": None}
    assert doc["parameters"]["b"]["value"] == pytest.approx(HIDDEN["b"], rel=1e-6)
    assert "Omega_max: not identifiable" in capsys.readouterr().out
    assert "Omega_max" not in (out / "parameters.ssv").read_text()


def test_an_instance_of_a_scenario_driven_by_the_log(tmp_path, flight_log, capsys):
    # four fitted names, as the CasADi-and-FMU test's (every test's fits share one compiled library, whatever
    # they fit: docs/calibration.md, one direction a compiled call): fitting six in the four-name tests too
    # took 4.5 CPU-s more on every run (the FMU way's directional derivatives above all)
    fix = [a for k, v in HIDDEN.items() if k not in ("b", "Ix") for a in ("--fix", f"{k}={v}")]
    code, out = _calibrate(tmp_path, flight_log, "--scenario", "circles", "--fit", "b,Ix,wind_x,wind_y", *fix)
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["instance"] == "Quadrotor"
    assert doc["parameters"]["Ix"]["value"] == pytest.approx(HIDDEN["Ix"], rel=1e-6)


def test_a_column_in_a_unit_of_another_quantity_is_refused(tmp_path, flight_log, capsys):
    cmap = tmp_path / "map.toml"
    cmap.write_text("[columns]\nx = { column = 'Quadrotor.x', unit = 's' }\n")
    code, _ = _calibrate(tmp_path, flight_log, "--fmu", "Quadrotor", "--fit", "b", "--columns", cmap)
    err = capsys.readouterr().err.strip()
    assert code == 2 and "does not match x's unit 'm'" in err and len(err.splitlines()) == 1


def test_the_calibrated_parameter_set_flies_in_a_run_and_in_an_exported_archive(tmp_path, flight_log, capsys):
    from cosim.scenario.definition import load_scenario
    from cosim.ssp.archive import load_ssp

    # four fitted names (the segment libraries of the tests above); b stays fixed, to check it is carried
    fix = [a for k, v in HIDDEN.items() if k not in ("Ix", "tau_m") for a in ("--fix", f"{k}={v}")]
    code, out = _calibrate(tmp_path, flight_log, "--fmu", "Quadrotor", "--fit", "Ix,tau_m,wind_x,wind_y", *fix,
                           "--guess", "tau_m=0.02")
    assert code == 0, capsys.readouterr().err
    ssv = out / "parameters.ssv"
    scenario = load_scenario("circles", {"fmus.Quadrotor.parameter_set": str(ssv)})
    flown = scenario.fmus["Quadrotor"]["parameters"]
    assert flown["Ix"] == pytest.approx(HIDDEN["Ix"], rel=1e-6) and flown["b"] == HIDDEN["b"]
    assert flown["z_0"] == -15.0  # the scenario's own parameters win and stay
    assert main(["run", "circles", "--set", f"fmus.Quadrotor.parameter_set={ssv}", "--set", "simulation.duration=1",
                 "--out", str(tmp_path / "run"), "--quiet", "--no-plots"]) == 0
    archive = tmp_path / "c.ssp"
    assert main(["export-ssp", "circles", "--set", f"fmus.Quadrotor.parameter_set={ssv}", "--out", str(archive)]) == 0
    assert load_ssp(archive).fmus["Quadrotor"]["parameters"]["Ix"] == flown["Ix"]


def test_a_parameter_set_that_is_not_one_is_refused_in_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.ssv"
    bad.write_text("<nope/>")
    code = main(["run", "circles", "--set", f"fmus.Quadrotor.parameter_set={bad}", "--out", str(tmp_path / "r"),
                 "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "expected an ssv:ParameterSet" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("kind, good, bad", [
    ("settings", "fit = ['b']\njacobian = 'casadi'\nsegment = 2.0\n", "fit = ['b']\njacobian = 'magic'\n"),
    ("settings", "fit = ['b']\ninterface = 'ModelExchange'\n[solver]\nrelative_tolerance = 1e-9\n",
     "fit = ['b']\n[solver]\nrelative_tolerance = 2\n"),
    ("column-map", "time = 'timestamp'\n[columns]\nx = 'pos_n'\nOmega_1 = { column = 'rpm1', unit = 'rpm' }\n",
     "[columns]\nx = 3\n"),
])
def test_the_calibration_files_schemas_are_printed_and_agree_with_the_readers(tmp_path, capsys, kind, good, bad):
    import tomllib

    import jsonschema

    from cosim.calibration import read_column_map, read_settings
    from cosim.errors import ScenarioError

    assert main(["schema", kind]) == 0
    schema = json.loads(capsys.readouterr().out)
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    reader = read_settings if kind == "settings" else read_column_map
    for text, valid in ((good, True), (bad, False)):
        assert validator.is_valid(tomllib.loads(text)) is valid
        path = tmp_path / f"{kind}.toml"
        path.write_text(text)
        if valid:
            reader(path)
        else:
            with pytest.raises(ScenarioError):
                reader(path)



def test_the_steps_derivative_one_direction_a_call_is_all_directions_at_once_bit_for_bit(flight_log, tmp_path,
                                                                                          monkeypatch):
    # cosim.calibration.symbolic takes the model's step and outputs one direction a call, and its compiled
    # chunk DIRECTIONS a call, the last call padded (the C it compiles is the same whatever the directions; three
    # fitted names and the estimated states: one padded call): each direction the
    # same operations as CasADi's forward(nd) of all of them in one chunk, the same Jacobians to the bit
    # (CasADi's virtual machine here, on 0.1 s of the log)
    import numpy as np

    import cosim.calibration.symbolic as symbolic
    from cosim.calibration import CalibrationSettings, calibrate
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model

    monkeypatch.setenv("COSIM_CACHE", str(tmp_path / "empty-cache"))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    asked = []
    sensitivities = symbolic.SymbolicModel.sensitivities
    monkeypatch.setattr(symbolic.SymbolicModel, "sensitivities",
                        lambda self, *args, **kw: asked.append((self, args)) or sensitivities(self, *args, **kw))
    fixed = {k: v for k, v in HIDDEN.items() if k not in ("b", "Ix")}
    calibrate(flight_log, built_fmu("Quadrotor", 2, lambda: model("Quadrotor")), CalibrationSettings(
        fit=["b", "Ix", "wind_x"], guess={"b": 6e-6, "Ix": 0.03}, fix=fixed, segment=0.05, holdout=0.0, stop=0.1,
        jacobian="casadi", max_iterations=1, initial_states="recorded"))
    first, (theta, segments, x0, estimated) = asked[0]
    at_once = symbolic.SymbolicModel(first.model, first.definition)
    at_once._one_direction = lambda name: first.definition.functions[name]  # CasADi's forward(nd)
    at_once.directions = None  # every direction in one call of the chunk (first: DIRECTIONS a call, padded)
    assert first.directions == symbolic.DIRECTIONS > 1
    for coarse in (False, True):
        for a, b in zip(first.sensitivities(theta, segments, x0, estimated, coarse=coarse),
                        at_once.sensitivities(theta, segments, x0, estimated, coarse=coarse)):
            assert np.any(a[0]) and np.array_equal(a[0], b[0])
            assert a[1] is b[1] is None or np.array_equal(a[1], b[1])
