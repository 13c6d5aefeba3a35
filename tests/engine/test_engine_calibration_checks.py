"""The calibration's warnings (cosim.calibration.diagnostics), the robust
covariance and ``--strict`` (docs/calibration.md, "Warnings"): a log of the
model itself with white noise warns of nothing; a log the model cannot
explain, an estimate at its bound, a misspelt column each warn, first in
report.md, on stderr, and in calibration.json."""
from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from cosim.calibration import CalibrationSettings, calibrate
from cosim.calibration.diagnostics import JACOBIAN_ERROR, _jacobian
from cosim.calibration.statistics import statistics, whiteness

REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"
pytestmark = pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {REFERENCE}")
DAHLQUIST = REFERENCE / "fmi2" / "Dahlquist.fmu"
VAN_DER_POL = REFERENCE / "fmi2" / "VanDerPol.fmu"
SIGMA = 0.005


@pytest.fixture(scope="module")
def dahlquist_run():
    """Dahlquist's solution (k = 1, x(0) = 1: x = exp(-t)) over 3 s at
    0.01 s: what the model's equations give, fitted through its Model
    Exchange interface (the default for a foreign FMU: its Co-Simulation is
    an explicit Euler step that a whiteness test rightly tells apart)."""
    t = np.round(np.arange(301) * 0.01, 12)
    return np.rec.fromarrays([t, np.exp(-t)], names=["time", "x"])


def _log(path: Path, t, columns: dict) -> Path:
    np.savetxt(path, np.column_stack([t, *columns.values()]), delimiter=",", header=",".join(["time", *columns]),
               comments="")
    return path


def _cli(*args) -> int:
    from quadrotor_paper.cli import main

    return main(list(map(str, args)))


def _run(tmp_path, log, fmu, *args):
    out = tmp_path / "out"
    code = _cli("calibrate", log, "--fmu", fmu, "--out", out, "--quiet", "--no-plots", "--strict", *args)
    return code, out, json.loads((out / "calibration.json").read_text()), (out / "report.md").read_text()


def test_a_log_of_the_model_itself_with_white_noise_warns_of_nothing_and_strict_exits_0(tmp_path, dahlquist_run,
                                                                                         capsys):
    r = dahlquist_run
    noisy = r["x"] + SIGMA * np.random.default_rng(0).standard_normal(r.size)
    code, out, doc, report = _run(tmp_path, _log(tmp_path / "log.csv", r["time"], {"x": noisy}), DAHLQUIST,
                                  "--fit", "k", "--guess", "k=0.5")
    assert code == 0, capsys.readouterr().err
    assert doc["warnings"] == [] and doc["covariance"] == "classical"
    assert report.split("## Warnings\n\nNo warnings.\n")[0] == "# Calibration\n\n"  # the report opens with them
    assert doc["residuals"]["x"]["ljung_box"]["p_value"] > 0.01
    assert "warning:" not in capsys.readouterr().err


def test_a_missing_term_warns_residuals_not_white_first_and_strict_exits_1_after_writing(tmp_path, dahlquist_run,
                                                                                          capsys):
    # the log holds an oscillation the first-order model lacks (2 % of the start value, 4x the noise)
    r = dahlquist_run
    x = r["x"] + 0.02 * np.sin(4 * r["time"]) + SIGMA * np.random.default_rng(0).standard_normal(r.size)
    code, out, doc, report = _run(tmp_path, _log(tmp_path / "log.csv", r["time"], {"x": x}), DAHLQUIST,
                                  "--fit", "k", "--guess", "k=0.5")
    assert code == 1
    assert {p.name for p in out.iterdir()} >= {"calibration.json", "parameters.ssv", "calibration.toml", "report.md"}
    first = report.split("## Warnings\n\n")[1].splitlines()[0]
    assert first.startswith("* **residuals-not-white**: residuals of x are not white: Ljung-Box Q = ")
    assert re.search(r", p (= [0-9.e+-]+|< 1e-300) < 0\.01 ", first)
    assert doc["residuals"]["x"]["ljung_box"]["p_value"] < 1e-6
    assert [w["kind"] for w in doc["warnings"]] == ["residuals-not-white"] and doc["warnings"][0]["subject"] == "x"
    # the intervals are the sandwich's, the classical one kept beside
    k = doc["parameters"]["k"]
    assert doc["covariance"] == "robust" and k["std"] == k["std_robust"] != k["std_classical"]
    err = capsys.readouterr().err
    assert "warning: residuals-not-white: residuals of x are not white" in err and "--strict" in err


def test_an_estimate_driven_to_its_bound_is_at_bound_with_its_value_not_unidentifiable(tmp_path, dahlquist_run,
                                                                                        capsys):
    r = dahlquist_run
    noisy = r["x"] + SIGMA * np.random.default_rng(1).standard_normal(r.size)
    settings = tmp_path / "settings.toml"
    settings.write_text("[bounds]\nk = [1.5, 3.0]\n")  # the truth, 1, is outside
    code, out, doc, report = _run(tmp_path, _log(tmp_path / "log.csv", r["time"], {"x": noisy}), DAHLQUIST,
                                  "--fit", "k", "--guess", "k=2", "--settings", settings)
    k = doc["parameters"]["k"]
    assert k["value"] == pytest.approx(1.5, rel=1e-6) and k["at_bound"] == 1.5
    assert k["identifiable"] is None and k["std"] is None and k["ci95"] is None
    assert "| k | 1.5 (at bound) |" in report and "not identifiable" not in report
    assert "at-bound" in [w["kind"] for w in doc["warnings"]] and code == 1
    printed = capsys.readouterr()
    assert "k = 1.5" in printed.out and "(at bound" in printed.out and "not identifiable" not in printed.out
    assert "warning: at-bound: k = 1.5 is at its lower bound 1.5" in printed.err
    assert "k = 1.5" in (out / "calibration.toml").read_text()  # the best value within the bounds, kept


def test_statistics_classify_a_vanishing_column_at_its_bound_as_at_bound():
    # b's column vanishes (no effect at b = 0, its lower bound): at bound first, the others' statistics without it
    rng = np.random.default_rng(0)
    J = np.column_stack([np.ones(200), np.zeros(200)])
    st = statistics(["a", "b"], np.array([1.0, 0.0]), J, rng.standard_normal(200), [None], 0, 1e-7,
                    np.array([-np.inf, 0.0]), np.array([np.inf, 1.0]))
    assert list(st.at_bound) == [False, True] and st.identifiable.all()
    assert np.isnan(st.std[1]) and np.isnan(st.ci95[1]).all()
    assert st.std[0] == pytest.approx(1 / np.sqrt(200), rel=0.1)


def test_a_misspelt_output_column_is_named_with_the_nearest_variables_other_components_are_not(tmp_path):
    from fmpy import simulate_fmu

    r = simulate_fmu(str(VAN_DER_POL), stop_time=2.0, output_interval=0.01)
    # controller.x1: another component's column named as one of the FMU's variables (a connection's source);
    # vdp.mu: a parameter recorded, a variable of the FMU (vdp names the most of them: the instance)
    columns = {"vdp.x0": r["x0"], "vdp.x_1": r["x1"], "vdp.mu": np.ones(r.size), "controller.x1": r["x1"],
               "controller.u": r["x1"], "battery": r["x1"]}
    cal = calibrate(_log(tmp_path / "log.csv", r["time"], columns), VAN_DER_POL,
                    CalibrationSettings(fit=["mu"], guess={"mu": 1.2}))
    assert cal.problem.outputs == ["x0"]  # fitted on the other column
    unmatched = [d for d in cal.diagnostics if d.kind == "unmatched-column"]
    assert [d.subject for d in unmatched] == ["vdp.x_1"]
    assert "nearest: x1" in unmatched[0].message


def test_a_held_out_part_the_model_cannot_predict_warns_with_its_numbers(tmp_path, dahlquist_run):
    # k = 1 for 2 s, then 3 (the FMU's own runs: Dahlquist is linear, x(2) times a run from 1): the fitted first
    # part cannot predict the last second
    from fmpy import simulate_fmu

    t, x1 = dahlquist_run["time"], dahlquist_run["x"]
    x3 = simulate_fmu(str(DAHLQUIST), stop_time=1.0, output_interval=0.01, start_values={"k": 3.0})["x"]
    x = np.concatenate([x1[t < 2 - 1e-9], x1[np.argmin(abs(t - 2))] * x3])
    x = x + SIGMA * np.random.default_rng(2).standard_normal(t.size)
    cal = calibrate(_log(tmp_path / "log.csv", t, {"x": x}), DAHLQUIST,
                    CalibrationSettings(fit=["k"], guess={"k": 0.5}, holdout=1.0))
    held = [d for d in cal.diagnostics if d.kind == "held-out-error"]
    assert len(held) == 1 and held[0].subject == "x"
    rms = cal.prediction["rms"][0]
    assert rms > 3 * cal.fit.sigma[0] and f"RMS {rms:.4g}" in held[0].message


def test_a_jacobian_error_large_against_its_entries_warns():
    fit = SimpleNamespace(method="central differences", jacobian=np.full((10, 1), 2.0), error_estimate=0.0)
    assert _jacobian(SimpleNamespace(fit=fit)) == []
    fit.error_estimate = 1e-8
    assert _jacobian(SimpleNamespace(fit=fit)) == []
    fit.error_estimate = 2 * JACOBIAN_ERROR * 2.0
    (d,) = _jacobian(SimpleNamespace(fit=fit))
    assert d.kind == "jacobian-error" and "0.04" in d.message


def test_ljung_box_is_the_textbook_statistic_and_counts_no_lag_across_segments():
    rng = np.random.default_rng(3)
    e = rng.standard_normal(300)
    c = e - e.mean()
    r = np.array([c[:-k] @ c[k:] for k in range(1, 6)]) / (c @ c)
    q = 300 * 302 * np.sum(r ** 2 / (300 - np.arange(1, 6)))
    assert whiteness([e], 5)["q"] == pytest.approx(q, rel=1e-12)
    # two white segments with a jump between them: white within each, not across the boundary
    a, b = rng.standard_normal(200) - 3, rng.standard_normal(200) + 3
    a, b = a - a.mean() - 3, b - b.mean() + 3
    assert whiteness([a, b], 10)["p_value"] < 1e-6  # about the whole mean: each segment's offset is in every lag
    assert whiteness([a + 3, b - 3], 10)["p_value"] > 0.01
    assert whiteness([np.concatenate([a + 3, b - 3])], 10)["q"] != whiteness([a + 3, b - 3], 10)["q"]


def test_the_robust_standard_error_grows_by_the_ar1_factor():
    # a mean measured through AR(1) noise, rho = 0.5: its variance is (1 + rho) / (1 - rho) = 3 times the white
    # noise formula's; Newey-West with Bartlett weights and Andrews' bandwidth (~13 rows here) sees most of it:
    # the kernel-weighted sum of rho^|l| is 2.7 of 3 (sqrt: 0.95 of the factor), and one estimate scatters by
    # ~10 % (its variance ~ S/n): 20 seeds' mean ratio within 8 % of sqrt(3)
    rho, n = 0.5, 2000
    ratios = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        w = rng.standard_normal(n)
        e = np.empty(n)
        e[0] = w[0] / np.sqrt(1 - rho ** 2)
        for i in range(1, n):
            e[i] = rho * e[i - 1] + w[i]
        e = (e - e.mean()) / e.std()  # weighted residuals at the optimum of the mean
        st = statistics(["m"], np.array([1.0]), np.ones((n, 1)), e, [None], 0, 1e-7, n_outputs=1,
                        segment_rows=[n // 2, n // 2])
        ratios.append(st.std_robust[0] / st.std_classical[0])
    assert np.mean(ratios) == pytest.approx(np.sqrt((1 + rho) / (1 - rho)), rel=0.08)


def test_a_noise_free_log_the_model_meets_to_round_off_does_not_warn():
    # the published output is the FMU's own run: residuals of 1e-16, correlated round-off, no misfit
    cal = calibrate(REFERENCE / "results" / "Dahlquist_out.csv", DAHLQUIST,
                    CalibrationSettings(fit=["k"], guess={"k": 0.5}, interface="CoSimulation"))
    assert cal.residuals["x"]["rms"] < 1e-12 and cal.diagnostics == []
    assert cal.stats.covariance == "classical"


def test_a_column_map_entry_that_feeds_no_input_output_or_state_warns(tmp_path):
    from cosim.calibration import read_column_map

    src = np.loadtxt(REFERENCE / "results" / "Dahlquist_out.csv", delimiter=",", skiprows=1)
    log = _log(tmp_path / "log.csv", src[:, 0], {"x": src[:, 1], "gain": np.ones(len(src))})
    (tmp_path / "map.toml").write_text('[columns]\nx = "x"\nk = "gain"\n')  # k: a parameter, not an output
    cal = calibrate(log, DAHLQUIST, CalibrationSettings(fit=["k"], guess={"k": 0.5}),
                    read_column_map(tmp_path / "map.toml"))
    (d,) = cal.diagnostics
    assert d.kind == "unmatched-column" and d.subject == "gain" and "mapped to k, a parameter" in d.message
