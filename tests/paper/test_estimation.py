"""Flying on an estimate (issue 20, docs/estimation.md): the estimation
metrics' laws on known answers, and ``circles_estimated`` with every part an
FMU in an SSP archive, flown by libcosim as by our master."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

from cosim.scenario.definition import load_scenario
from cosim.scenario.assembly import build_master
from cosim.ssp.archive import SSD_NAME, load_ssp, ssd_schema_errors
from quadrotor_paper.experiments import estimation_signals, lean_signals, study_metric_names
from quadrotor_paper.metrics import nees, settled, wrap_angle

POSITION = ["Quadrotor.x", "Quadrotor.y", "Quadrotor.z"]
TOLERANCE = 1e-9  # m


def test_nees_is_the_error_weighted_by_the_inverse_covariance():
    P = np.array([[4.0, 1.0], [1.0, 2.0]])
    e = np.array([[1.0, 2.0], [0.0, 0.0], [3.0, -1.0]])
    expected = [float(x @ np.linalg.inv(P) @ x) for x in e]
    np.testing.assert_allclose(nees(e, np.stack([P] * 3)), expected, rtol=1e-14)
    assert np.isnan(nees(e[:1], np.ones((1, 2, 2)))[0])  # singular: NaN
    # a component held, not estimated (variance 0: no vertical wind state): left out when its error is 0
    held = np.zeros((3, 3, 3))
    held[:, :2, :2] = P
    np.testing.assert_allclose(nees(np.c_[e, np.zeros(3)], held), expected, rtol=1e-14)
    assert nees(np.array([[1.0, 2.0, 0.1]]), held[:1])[0] == np.inf  # certain of a wrong value
    assert np.isnan(nees(e[:1], np.zeros((1, 2, 2)))[0])  # nothing estimated
    # a consistent filter's NEES averages its degrees of freedom
    rng = np.random.default_rng(0)
    L = np.linalg.cholesky(P)
    assert abs(np.mean(nees(rng.normal(size=(20000, 2)) @ L.T, np.stack([P] * 20000))) - 2.0) < 0.05


def test_settled_waits_after_the_start_and_after_each_change():
    t = np.arange(0, 20.0, 0.5)
    wind = np.where(t < 8.0, 3.0, -3.0)
    mask = settled(t, wind, 3.0)
    np.testing.assert_array_equal(t[mask], t[((t >= 3.0) & (t < 8.0)) | (t >= 11.0)])
    np.testing.assert_allclose(wrap_angle(np.array([0.1, 2 * np.pi + 0.1, -np.pi - 0.1])),
                               [0.1, 0.1, np.pi - 0.1], atol=1e-12)


def test_the_estimated_scenarios_name_their_estimator_and_record_what_it_needs():
    for name in ("circles_estimated", "figure8_lab_estimated"):
        scenario = load_scenario(name)
        assert "nees_wind" in study_metric_names(scenario)
        assert set(estimation_signals(scenario)) <= set(scenario.record)
        assert set(estimation_signals(scenario)) <= set(lean_signals(scenario))
    assert "nees_wind" not in study_metric_names(load_scenario("circles"))
    # the motion-capture attitude's refusals and restarts are study columns where the filter fuses it (the lab's),
    # only there
    for count in ("outliers_attitude", "resets_attitude"):
        assert count in study_metric_names(load_scenario("figure8_lab_estimated"))
        assert count not in study_metric_names(load_scenario("circles_estimated"))
        assert f"Estimator.{count}" in estimation_signals(load_scenario("figure8_lab_estimated"))


@pytest.mark.parametrize("name, parts", [
    ("circles_estimated", ("IMU", "GNSS", "Estimator", "controller", "reference")),
    ("figure8_lab_estimated", ("IMU", "Mocap", "Estimator", "Ground", "WiFi", "Onboard", "reference")),
])
def test_the_estimated_missions_as_fmus_fly_in_libcosim_as_in_our_master(tmp_path, name, parts):
    """``fnn-cosim export-ssp``: the plant, the gust, the sensors, the
    Estimator and the controller, every one an FMU. libcosim and our master
    in libcosim's ('exchange') ordering agree to 1e-9 m over 10 s, the
    sensors' noise included (the seeds travel in the archive)."""
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed: libcosim cannot be run")
    from libcosim_runner import run_libcosim
    from quadrotor_paper.cli import main

    path = tmp_path / f"{name}.ssp"
    assert main(["export-ssp", name, "--set", "simulation.duration=10.0", "--out", str(path)]) == 0
    assert ssd_schema_errors(zipfile.ZipFile(path).read(SSD_NAME)) == []
    assert {f"resources/{c}.fmu" for c in parts} <= set(zipfile.ZipFile(path).namelist())
    signals = POSITION + ["Estimator.x", "Estimator.wind_x", "IMU.acc_x"]
    lc = run_libcosim(path, signals)
    scenario = load_ssp(path, overrides={"simulation.ordering": "exchange", "record.signals": signals})
    with build_master(scenario) as master:
        ours = master.run(scenario.duration, seed=scenario.seed)
    assert ours.status == "ok" and lc.data.shape == ours.data.shape == (1001, len(signals) + 1)
    for signal in POSITION + ["Estimator.x"]:
        assert np.max(np.abs(lc[signal] - ours[signal])) <= TOLERANCE, signal
    for signal in signals[4:]:
        assert np.allclose(lc[signal], ours[signal], rtol=0, atol=1e-9), signal
    assert np.std(np.diff(ours["IMU.acc_x"])) > 0.01  # the IMU's noise is in the loop
    assert np.max(np.abs(ours["Quadrotor.x"])) > 0.5  # it flew


def test_a_variant_row_flies_its_variant_on_a_scenario_cut_at_v_star():
    """Table 3's rows on the laboratory's scenarios (no [controller]; the
    ground controller an outer-loop FMU) set that FMU's model, so
    ``fnn-cosim table3 --scenario figure8_lab_estimated`` compares variants."""
    from cosim.scenario import registry

    for name in ("figure8_lab", "figure8_lab_estimated"):
        raw = load_scenario(name).raw
        assert registry.cases()["pd+it2-lm"].applied_to(raw) == {"fmus.Ground.model": "PositionControllerPDIT2LM"}
    assert registry.cases()["pd"].applied_to(load_scenario("circles_estimated").raw) == {"controller.variant": "pd"}


def test_a_run_on_the_estimate_reports_the_filter_and_a_bad_estimator_is_one_line(tmp_path, capsys):
    from quadrotor_paper.cli import main

    assert main(["run", "circles_estimated", "--set", "simulation.duration=8.0", "--out", str(tmp_path / "r"),
                 "--quiet", "--no-plots"]) == 0
    assert "- estimate: NEES position " in capsys.readouterr().out
    assert main(["run", "circles", "--set", 'metrics.estimator="Nope"', "--out", str(tmp_path / "b"),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == "fnn-cosim: error: metrics.estimator = 'Nope': no such FMU in [fmus]; FMUs: Quadrotor, " \
                          "WindGust" and "Traceback" not in err
