"""The engine's calibrator (cosim.calibration) on the Reference FMUs: known
answers from their published outputs and from data of our own, the
statistics, and every bad input refused in one line (docs/calibration.md)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cosim.calibration import CalibrationSettings, calibrate
from cosim.errors import ScenarioError

REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"
pytestmark = pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {REFERENCE}")
RESULTS = REFERENCE / "results"


@pytest.mark.parametrize("version", [2, 3])
def test_van_der_pol_mu_from_its_published_output_from_a_guess_50_percent_off(version):
    # the published file is the FMU's own Co-Simulation (forward Euler at 0.01 s): the fit through it meets it to
    # round-off ("auto" would take Model Exchange, the accurate solver, 5 % off this Euler log: the test below)
    settings = CalibrationSettings(fit=["mu"], guess={"mu": 1.5}, segment=5.0, interface="CoSimulation",
                                   **({"stop": 10.0} if version == 3 else {}))
    cal = calibrate(RESULTS / "VanDerPol_out.csv", REFERENCE / f"fmi{version}" / "VanDerPol.fmu", settings)
    assert cal.converged
    assert cal.problem.fmu.interface == "CoSimulation"
    assert cal.fit.method.startswith("forward sensitivities")  # VanDerPol provides directional derivatives
    assert abs(cal.fit.theta[0] - 1.0) < 1e-6
    assert cal.stats.identifiable[0]


def test_dahlquist_k_from_its_published_output_by_differences_from_a_guess_50_percent_off():
    # the log is the FMU's own Co-Simulation (forward Euler): fitted through it ("auto" takes Model Exchange)
    cal = calibrate(RESULTS / "Dahlquist_out.csv", REFERENCE / "fmi2" / "Dahlquist.fmu",
                    CalibrationSettings(fit=["k"], guess={"k": 0.5}, interface="CoSimulation"))
    assert cal.converged
    assert cal.fit.method == "central differences"  # Dahlquist provides no directional derivatives
    assert abs(cal.fit.theta[0] - 1.0) < 1e-6
    assert cal.fit.error_estimate < 1e-6


def _van_der_pol_data(tmp_path, mu, sigma, seed, stop=10.0):
    from fmpy import simulate_fmu

    r = simulate_fmu(str(REFERENCE / "fmi2" / "VanDerPol.fmu"), stop_time=stop, output_interval=0.01,
                     start_values={"mu": mu})
    rng = np.random.default_rng(seed)
    path = tmp_path / f"vdp_{seed}.csv"
    x0 = r["x0"] + sigma * rng.standard_normal(r.size)
    x1 = r["x1"] + sigma * rng.standard_normal(r.size)
    np.savetxt(path, np.column_stack([r["time"], x0, x1]), delimiter=",", header="time,x0,x1", comments="")
    return path


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_van_der_pol_mu_from_noisy_data_of_our_own_inside_its_interval(tmp_path, seed):
    # 6 s of data: two segments of 2.5 s fitted (each with its estimated start) and the last second held
    # out, where 10 s fitted three and held out the fourth, for about half the fit's CPU (1.0-2.1 s a seed
    # on a busy machine); each seed's interval covers the truth, 0.0034-0.0035 wide (0.0029-0.0031 with 10 s)
    truth = 0.7
    path = _van_der_pol_data(tmp_path, truth, 0.01, seed, stop=6.0)
    cal = calibrate(path, REFERENCE / "fmi2" / "VanDerPol.fmu",
                    CalibrationSettings(fit=["mu"], guess={"mu": 1.05}, initial_states="estimated", segment=2.5,
                                        interface="CoSimulation"))  # fmpy's data: the FMU's Co-Simulation
    assert cal.converged
    lo, hi = cal.stats.ci95[0]
    assert lo < truth < hi
    assert 0 < cal.stats.std[0] < 0.05
    # the noise level estimated from the residuals is the one put in
    assert cal.residuals["x0"]["sigma"] == pytest.approx(0.01, rel=0.15)
    assert cal.diagnostics == []  # the model's own log with white noise: nothing to warn of


def test_a_parameter_without_effect_is_reported_not_identifiable_never_as_a_number(tmp_path):
    # Dahlquist from x(0) = 0: x stays 0 whatever k is; the data cannot determine k
    path = tmp_path / "zero.csv"
    t = np.arange(0, 2.01, 0.1)
    np.savetxt(path, np.column_stack([t, np.zeros_like(t)]), delimiter=",", header="time,x", comments="")
    cal = calibrate(path, REFERENCE / "fmi2" / "Dahlquist.fmu", CalibrationSettings(fit=["k"], guess={"k": 0.5}))
    assert not cal.stats.identifiable[0]
    assert np.isnan(cal.stats.std[0])
    assert cal.estimates() == {"k": None}


def _cli(*args):
    from quadrotor_paper.cli import main

    return main(list(map(str, args)))


def _refused(capsys, *args) -> str:
    """The one line ``fnn-cosim ARGS`` writes on stderr when it refuses its input with exit code 2."""
    code = _cli(*args)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    return err


def test_the_command_writes_its_four_files(tmp_path, capsys):
    out = tmp_path / "out"
    code = _cli("calibrate", RESULTS / "VanDerPol_out.csv", "--fmu", REFERENCE / "fmi2" / "VanDerPol.fmu",
                "--fit", "mu", "--guess", "mu=0.5", "--segment", "5", "--interface", "CoSimulation",  # its own log
                "--out", out, "--quiet")
    assert code == 0
    doc = json.loads((out / "calibration.json").read_text())
    mu = doc["parameters"]["mu"]
    assert abs(mu["value"] - 1.0) < 1e-6 and mu["identifiable"] and mu["ci95"][0] <= mu["value"] <= mu["ci95"][1]
    assert doc["converged"] and set(doc["residuals"]) == {"x0", "x1"}
    assert "mu = " in (out / "calibration.toml").read_text()
    from cosim.ssp.archive import ssd_schema_errors
    from lxml import etree

    assert ssd_schema_errors(out / "parameters.ssv") == []  # SSP 1.0's SystemStructureParameterValues.xsd

    ssv = etree.parse(str(out / "parameters.ssv")).getroot()
    assert etree.QName(ssv).localname == "ParameterSet"
    assert float(ssv.find(".//{*}Real").get("value")) == pytest.approx(1.0, rel=1e-6)
    report = (out / "report.md").read_text()
    assert "| mu |" in report and (out / "estimates.png").is_file() and (out / "prediction.png").is_file()


def test_a_fit_that_does_not_converge_keeps_its_report_and_exits_1(tmp_path, capsys):
    settings = tmp_path / "settings.toml"
    settings.write_text("max_iterations = 1\n")
    out = tmp_path / "out"
    code = _cli("calibrate", RESULTS / "VanDerPol_out.csv", "--fmu", REFERENCE / "fmi2" / "VanDerPol.fmu",
                "--fit", "mu", "--guess", "mu=1.5", "--settings", settings, "--out", out, "--quiet", "--no-plots")
    assert code == 1
    assert "NOT CONVERGED" in (out / "report.md").read_text()
    assert json.loads((out / "calibration.json").read_text())["converged"] is False


def _bad_log(tmp_path, rows, header="time,x"):
    path = tmp_path / "bad.csv"
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("rows, says", [
    (["0,1", "0.1,nan", "0.2,0.8"], "row 2, column x: nan is not a finite number"),
    (["0,1", "0.1,0.9", "0.1,0.8"], "row 3, column time: t = 0.1 repeats the row before"),
    (["0,1", "0.2,0.9", "0.1,0.8"], "row 3, column time: t = 0.1 goes back"),
    (["0,1", "0.1,0.9", "0.2,0.8", "0.7,0.5", "0.8,0.4"], "row 4, column time: a gap of 0.5 s"),
])
def test_a_bad_log_is_one_line_naming_row_and_column_exit_2(tmp_path, capsys, rows, says):
    assert says in _refused(capsys, "calibrate", _bad_log(tmp_path, rows), "--fmu", REFERENCE / "fmi2" / "Dahlquist.fmu",
                            "--fit", "k", "--out", tmp_path / "out", "--quiet")


@pytest.mark.parametrize("args, says", [
    (["--fit", "kk"], "--fit kk: Dahlquist.fmu has no such parameter"),
    (["--fit", "k", "--fix", "k=2"], "--fit k: it is fixed"),
    (["--fit", "x"], "--fit x: a continuous output of Dahlquist.fmu"),
    (["--fit", "k", "--columns", "MAP:columns.x = 'missing'"], "no column 'missing'"),
    (["--fit", "k", "--columns", "MAP:columns.y = 'x'"], "'y' is not a variable of Dahlquist.fmu"),
])
def test_bad_names_units_and_maps_are_one_line_exit_2(tmp_path, capsys, args, says):
    args = list(args)
    for i, a in enumerate(args):
        if a.startswith("MAP:"):
            path = tmp_path / "map.toml"
            path.write_text(a[4:] + "\n")
            args[i] = path
    path = tmp_path / "ok.csv"
    t = np.arange(0, 1.01, 0.1)
    np.savetxt(path, np.column_stack([t, np.exp(-t)]), delimiter=",", header="time,x", comments="")
    assert says in _refused(capsys, "calibrate", path, "--fmu", REFERENCE / "fmi2" / "Dahlquist.fmu", *args, "--out",
                            tmp_path / "o", "--quiet")


def test_a_column_map_renames_a_column(tmp_path):
    path = tmp_path / "ok.csv"
    t = np.arange(0, 5.01, 0.1)
    np.savetxt(path, np.column_stack([t, 0.9 ** (t / 0.1)]), delimiter=",", header="time,xx", comments="")
    from cosim.calibration import ColumnMap

    cmap = ColumnMap.from_document({"columns": {"x": "xx"}}, "map")
    # 0.9^n: the Co-Simulation's forward Euler at 0.1 s with k = 1
    cal = calibrate(path, REFERENCE / "fmi2" / "Dahlquist.fmu",
                    CalibrationSettings(fit=["k"], guess={"k": 2.0}, interface="CoSimulation"), cmap)
    assert abs(cal.fit.theta[0] - 1.0) < 1e-6


def test_a_parquet_log_is_read_with_its_units(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    r = np.loadtxt(RESULTS / "Dahlquist_out.csv", delimiter=",", skiprows=1)
    table = pa.table({"time": r[:, 0], "x": r[:, 1]})
    pq.write_table(table, tmp_path / "log.parquet")
    cal = calibrate(tmp_path / "log.parquet", REFERENCE / "fmi2" / "Dahlquist.fmu",
                    CalibrationSettings(fit=["k"], guess={"k": 1.5}, interface="CoSimulation"))  # its own log
    assert abs(cal.fit.theta[0] - 1.0) < 1e-6


def test_a_settings_file_with_an_unknown_key_is_one_line_naming_file_and_key(tmp_path, capsys):
    settings = tmp_path / "s.toml"
    settings.write_text("segmnt = 2.0\n")
    err = _refused(capsys, "calibrate", RESULTS / "Dahlquist_out.csv", "--fmu", REFERENCE / "fmi2" / "Dahlquist.fmu",
                   "--fit", "k", "--settings", settings, "--out", tmp_path / "o", "--quiet")
    assert f"calibration settings {settings}: segmnt: unknown key" in err


def test_a_ulog_without_pyulog_or_without_a_topic_is_one_line(tmp_path, capsys):
    log = tmp_path / "flight.ulg"
    log.write_bytes(b"ULog\x01\x12\x35\x01")
    err = _refused(capsys, "calibrate", log, "--fmu", REFERENCE / "fmi2" / "Dahlquist.fmu", "--fit", "k", "--out",
                   tmp_path / "o", "--quiet")
    try:
        import pyulog  # noqa: F401
        expected = "a ULog needs a column map (--columns) naming its 'topic'"
    except ImportError:
        expected = "reading a PX4 ULog needs pyulog"
    assert expected in err


def test_the_casadi_way_asked_of_a_foreign_fmu_is_one_line_exit_2(tmp_path, capsys):
    # the CasADi way needs the model's own definition: an FMU not generated by a registered model has none
    settings = tmp_path / "settings.toml"
    settings.write_text("jacobian = 'casadi'\ninterface = 'CoSimulation'\n")
    err = _refused(capsys, "calibrate", RESULTS / "Dahlquist_out.csv", "--fmu", REFERENCE / "fmi2" / "Dahlquist.fmu",
                   "--fit", "k", "--settings", settings, "--out", tmp_path / "o", "--quiet")
    assert "jacobian = 'casadi': Dahlquist.fmu: not a model whose CasADi definition" in err


def test_a_ulog_is_read_through_pyulog_its_topic_the_instants_only_the_topics_named(tmp_path):
    pytest.importorskip("pyulog")
    from cosim.calibration import ColumnMap, read_log
    from tests.ulog_writer import write_ulog

    t_us = np.arange(0, 5_000_001, 100_000)  # 10 Hz, microseconds
    x = 0.9 ** (t_us / 100_000)  # Dahlquist at k = 1, its forward Euler at 0.1 s
    slow = np.arange(0, 5_000_001, 500_000)  # another topic at 2 Hz, which the map does not name: not read
    path = write_ulog(tmp_path / "flight.ulg", {"state": (t_us, {"x": x}), "battery": (slow, {"volts": 12 - slow / 1e6})})
    cmap = ColumnMap.from_document({"time": "timestamp", "time_unit": "us", "topic": "state",
                                    "columns": {"x": "state.x"}}, "map")
    log = read_log(path, cmap)
    assert log.times == pytest.approx(t_us / 1e6, abs=1e-12)
    assert "battery.volts" not in log.columns  # resampling: tests/engine/test_engine_calibration_logs.py
    cal = calibrate(path, REFERENCE / "fmi2" / "Dahlquist.fmu",
                    CalibrationSettings(fit=["k"], guess={"k": 2.0}, interface="CoSimulation"), cmap)  # Euler's
    assert abs(cal.fit.theta[0] - 1.0) < 1e-6


# ---- Model Exchange-only FMUs: the master's solver makes the trajectories (docs/calibration.md) ----------------

def _without(version: int, elements: tuple[str, ...], path: Path) -> Path:
    """The Reference VanDerPol with the interface ``elements`` taken out of its
    modelDescription.xml (the binary unchanged): an FMU as a modelling tool
    exports it, Model Exchange first."""
    import zipfile

    from lxml import etree

    with zipfile.ZipFile(REFERENCE / f"fmi{version}" / "VanDerPol.fmu") as zin, \
            zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                root = etree.fromstring(data)
                for name in elements:
                    root.remove(root.find(name))
                data = etree.tostring(root, xml_declaration=True, encoding="UTF-8")
            zout.writestr(item, data)
    return path


ME_MU = 0.7  # the log's mu, the FMU's default 1


@pytest.fixture(scope="module", params=[2, 3])
def me_only_log(request, tmp_path_factory):
    """``(version, the ME-only VanDerPol, a noisy log of it)``: 10 s at 0.1 s
    from fmpy's own Model Exchange run (CVode at 1e-10) at ``mu = 0.7``,
    Gaussian noise 0.01 on both outputs (seeded)."""
    from fmpy import simulate_fmu

    folder = tmp_path_factory.mktemp(f"me{request.param}")
    fmu = _without(request.param, ("CoSimulation",), folder / "VanDerPol.fmu")
    r = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10, stop_time=10.0,
                     output_interval=0.1, start_values={"mu": ME_MU})
    rng = np.random.default_rng(7)
    noisy = [r[n] + 0.01 * rng.standard_normal(r.size) for n in ("x0", "x1")]
    log = folder / "log.csv"
    np.savetxt(log, np.column_stack([r["time"], *noisy]), delimiter=",", header="time,x0,x1", comments="")
    return request.param, fmu, log


def test_a_model_exchange_only_fmu_is_calibrated_through_the_masters_solver(me_only_log, tmp_path, capsys):
    version, fmu, log = me_only_log
    settings = tmp_path / "settings.toml"
    # the logged states are noisy: every segment's start estimated; a log of 0.1 s rows: Jacobians at every row
    # (their Magnus step over 4 rows, the default's first iterations, converges in 26 simulations against 16)
    settings.write_text("initial_states = 'estimated'\njacobian_stride = 1\n")
    out = tmp_path / "out"
    assert _cli("calibrate", log, "--fmu", fmu, "--fit", "mu", "--guess", "mu=1.05", "--segment", "5", "--settings",
                settings, "--out", out, "--quiet", "--no-plots") == 0
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["interface"] == "ModelExchange" and doc["solver"]["relative_tolerance"] == 1e-8
    assert doc["jacobian"] == "forward sensitivities (directional derivatives)"
    mu = doc["parameters"]["mu"]
    assert abs(mu["value"] - ME_MU) < 0.01 * ME_MU
    assert mu["ci95"][0] < ME_MU < mu["ci95"][1]
    assert doc["residuals"]["x0"]["sigma"] == pytest.approx(0.01, rel=0.2)  # the noise put in, estimated
    assert doc["warnings"] == [] and doc["covariance"] == "classical"  # white noise on the model's own run


def test_an_fmu_with_both_interfaces_is_calibrated_in_model_exchange_when_asked():
    # the published output is the FMU's Co-Simulation (forward Euler at 0.01 s); the master's solver with
    # Euler at the same step reproduces it, so the fit meets it as closely (3 s of it: one segment)
    settings = CalibrationSettings(fit=["mu"], guess={"mu": 1.5}, stop=3.0, interface="ModelExchange",
                                   solver={"method": "euler", "step": 0.01})
    cal = calibrate(RESULTS / "VanDerPol_out.csv", REFERENCE / "fmi2" / "VanDerPol.fmu", settings)
    assert cal.problem.fmu.interface == "ModelExchange" and cal.converged
    assert abs(cal.fit.theta[0] - 1.0) < 1e-6


@pytest.mark.parametrize("removed, args, says", [
    (("CoSimulation",), ["--interface", "CoSimulation"],
     "interface = 'CoSimulation': the FMU has no Co-Simulation interface (it has Model Exchange only)"),
    ((), ["--interface", "ME"], "interface = 'ME': expected one of auto, CoSimulation, ModelExchange"),
    (("CoSimulation", "ModelExchange"), [], "the FMU has neither Co-Simulation nor Model Exchange"),
    ((), ["--interface", "CoSimulation", "--settings", "solver.relative_tolerance = 1e-9"],
     "solver: VanDerPol.fmu runs in Co-Simulation here"),
    (("CoSimulation",), ["--settings", "solver.relative_tolerance = 2"], "solver.relative_tolerance = 2: must be below 1"),
])
def test_an_interface_the_fmu_lacks_or_a_bad_choice_is_one_line_exit_2(tmp_path, capsys, removed, args, says):
    fmu = _without(2, removed, tmp_path / "VanDerPol.fmu")
    args = list(args)
    if "--settings" in args:
        settings = tmp_path / "settings.toml"
        settings.write_text(args[-1] + "\n")
        args[-1] = settings
    assert says in _refused(capsys, "calibrate", RESULTS / "VanDerPol_out.csv", "--fmu", fmu, "--fit", "mu", *args,
                            "--out", tmp_path / "o", "--quiet")


@pytest.mark.parametrize("me_only_log", [2], indirect=True)
@pytest.mark.parametrize("failure", ["solver", "not finite"])
def test_a_trial_point_the_solver_cannot_simulate_is_rejected_not_a_crash(me_only_log, monkeypatch, failure):
    # the fit's first step from mu = 1.05 overshoots to 0.62; say the model cannot be simulated below 0.65: CVODE
    # fails there (the component's FmuCallError, as a Model Exchange integration failure is), or the FMU returns
    # NaN; the solver rejects those trial points (its trust region shrinks) and reaches the estimate
    from cosim.calibration.model import LogModel
    from cosim.errors import FmuCallError

    _, fmu, log = me_only_log
    simulate, tried = LogModel.simulate, []

    def failing(self, theta, seg, x0):
        tr = simulate(self, theta, seg, x0)
        if theta[0] < 0.65:
            tried.append(float(theta[0]))
            if failure == "solver":
                raise FmuCallError("calibrated", fmu, "Model Exchange integration (cvode) failed (CVode error)")
            tr.outputs[-1] = np.nan
        return tr

    monkeypatch.setattr(LogModel, "simulate", failing)
    settings = CalibrationSettings(fit=["mu"], guess={"mu": 1.05}, initial_states="estimated", segment=5.0,
                                   jacobian_stride=1, noise={"x0": 0.01, "x1": 0.01})
    cal = calibrate(log, fmu, settings)
    assert tried and cal.converged
    assert abs(cal.fit.theta[0] - ME_MU) < 0.01 * ME_MU
    # a first guess there: nothing to fall back on, the FMU's error in one line naming the guess (not scipy's
    # ValueError); bad input (exit 2): the guess is the user's to change (issue 42)
    with pytest.raises(ScenarioError, match="the first guess mu = 0.5: VanDerPol.fmu cannot simulate it: " + (
            "Model Exchange integration" if failure == "solver" else r"at t = 4\.9000 s: the trajectory is not finite")):
        calibrate(log, fmu, settings.model_copy(update={"guess": {"mu": 0.5}}))


@pytest.mark.parametrize("me_only_log", [2], indirect=True)
def test_differences_give_the_continuity_rows_of_each_segments_own_start(me_only_log):
    # the differences move one estimated state in every segment at once (a segment's outputs depend on its own
    # start only); a continuity residual W (x_end(k) - x_start(k + 1)) / scale depends on two of them: each
    # column gets its own part (x_start's exactly), as the forward sensitivities give it
    from cosim.calibration import read_log
    from cosim.calibration.model import LogModel
    from cosim.calibration.problem import bind_problem
    from cosim.calibration.segments import split
    from cosim.calibration.solve import _Problem
    from cosim.fmi.fmu import FmuComponent

    _, fmu, log = me_only_log
    settings = CalibrationSettings(fit=["mu"], initial_states="estimated", stop=3.0)
    comp = FmuComponent("calibrated", fmu)
    model = LogModel(bind_problem(comp, read_log(log).window(None, 3.0), settings, states=comp.state_names))
    try:
        segments, _ = split(model.times, 1.5, 0)
        x0 = np.array([[2.0, 0.0], [0.9, -1.6]])
        estimated, sigma, z = np.ones(2, bool), np.array([0.01, 0.01]), np.array([0.7, 2.0, 0.0, 0.9, -1.6])
        J = {how: _Problem(model, segments, estimated, x0, sigma, how, None).jacobian(z).toarray()
             for how in ("differences", "derivatives")}
    finally:
        model.close()
        comp.close()
    rows = slice(-2, None)  # the continuity between the two segments
    assert J["differences"][rows, 3:] == pytest.approx(-1e3 / np.array([2.0, 1.6]) * np.eye(2))
    np.testing.assert_allclose(J["differences"][rows, :3], J["derivatives"][rows, :3], rtol=2e-2, atol=1.0)
