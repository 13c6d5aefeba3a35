"""The calibrator where trial points, first guesses and logs go wrong, and
its defaults on noisy logs (issue 42, items 4 and 5; docs/calibration.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.calibration import CalibrationSettings, calibrate

REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"
pytestmark = pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {REFERENCE}")
VAN_DER_POL = REFERENCE / "fmi2" / "VanDerPol.fmu"
PUBLISHED = REFERENCE / "results" / "VanDerPol_out.csv"


def test_a_trial_point_whose_simulation_is_not_finite_is_rejected_and_the_fit_converges(monkeypatch):
    # VanDerPol's Co-Simulation is forward Euler at 0.01 s: above mu ~ 44 its trajectory overflows (mu x^2 h > 2);
    # from mu = 40 on the published log (mu = 1, exact: its logged states start the segments) the solver's first
    # trial points go there
    from cosim.calibration import solve

    rejected = []
    failed = solve._Problem._failed
    monkeypatch.setattr(solve._Problem, "_failed", lambda self, s: rejected.append(s) or failed(self, s))
    cal = calibrate(PUBLISHED, VAN_DER_POL, CalibrationSettings(fit=["mu"], guess={"mu": 40.0}, segment=5.0,
                                                                interface="CoSimulation", stop=10.0,
                                                                initial_states="recorded"))
    assert rejected  # the solver did step where the FMU cannot go
    assert cal.converged and np.isfinite(cal.fit.cost) and np.isfinite(cal.fit.theta).all()
    assert np.isfinite(cal.stats.std).all()


def test_a_first_guess_whose_simulation_is_not_finite_is_one_line_naming_it_exit_2(tmp_path, capsys):
    # the case: VanDerPol's Co-Simulation (forward Euler) overflows at t = 1.91 s from mu = -5
    from quadrotor_paper.cli import main

    code = main(["calibrate", str(PUBLISHED), "--fmu", str(VAN_DER_POL), "--fit", "mu", "--guess", "mu=-5",
                 "--interface", "CoSimulation",
                 "--no-plots", "--quiet", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and "internal error" not in err
    assert "the first guess mu = -5" in err and "VanDerPol.fmu" in err and "not finite" in err


def test_auto_takes_model_exchange_for_a_foreign_fmu_with_both_and_co_simulation_for_ours():
    # a foreign FMU's Co-Simulation is often a crude fixed step (VanDerPol's forward Euler: mu 4.5 % low on an
    # accurate log); ours is its CasADi definition's RK4 steps, which the CasADi way reproduces exactly
    from cosim.calibration.pipeline import _component
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model

    for fmu, interface in ((VAN_DER_POL, "ModelExchange"),
                           (built_fmu("Quadrotor", 2, lambda: model("Quadrotor")), "CoSimulation")):
        comp = _component(fmu, CalibrationSettings(fit=["mu"]), None)
        try:
            assert comp.interface == interface
        finally:
            comp.close()


def test_the_defaults_on_a_noisy_log_cover_the_truth(tmp_path):
    # the defaults (issue 42): initial states estimated (the logged ones are noisy) and, VanDerPol having both
    # interfaces, Model Exchange by CVODE; the log an accurate solution (fmpy's CVODE at 1e-10) with noise 0.01
    from fmpy import simulate_fmu

    assert CalibrationSettings().initial_states == "estimated" and CalibrationSettings().interface == "auto"
    truth = 0.7
    r = simulate_fmu(str(VAN_DER_POL), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10,
                     stop_time=4.0, output_interval=0.05, start_values={"mu": truth})
    noise = 0.01 * np.random.default_rng(1).standard_normal((r.size, 2))
    path = tmp_path / "noisy.csv"
    np.savetxt(path, np.column_stack([r["time"], r["x0"] + noise[:, 0], r["x1"] + noise[:, 1]]), delimiter=",",
               header="time,x0,x1", comments="")
    cal = calibrate(path, VAN_DER_POL, CalibrationSettings(fit=["mu"], guess={"mu": 1.0}, segment=2.0, holdout=0.0))
    assert cal.problem.fmu.interface == "ModelExchange" and cal.converged
    assert cal.fit.estimated.all()  # every state of every segment estimated
    lo, hi = cal.stats.ci95[0]
    assert lo < truth < hi and hi - lo < 0.1


def test_model_exchange_refuses_a_trial_point_that_escapes_at_once_and_the_fit_goes_on(tmp_path, capfd, monkeypatch):
    # the published log played backwards is VanDerPol at mu = -1 on its unstable limit cycle (x(-t) solves the
    # equation with -mu): a trial point off it escapes to infinity within the segment; CVODE needs steps below
    # its smallest (100 units in the last place of t) and fails there at once, the trial point is rejected,
    # the fit goes on; SUNDIALS prints nothing (no steps at t + h == t)
    from cosim.calibration.model import LogModel
    from cosim.errors import FmuCallError
    from quadrotor_paper.cli import main

    data = np.genfromtxt(PUBLISHED, delimiter=",", names=True)
    log = tmp_path / "backwards.csv"
    np.savetxt(log, np.column_stack([data["time"], data["x0"][::-1], -data["x1"][::-1]]), delimiter=",",
               header="time,x0,x1", comments="", fmt="%.17g")
    refused = []
    simulate = LogModel.simulate

    def spy(self, *args):
        try:
            return simulate(self, *args)
        except FmuCallError as exc:
            refused.append(str(exc))
            raise

    monkeypatch.setattr(LogModel, "simulate", spy)
    settings = tmp_path / "settings.toml"
    settings.write_text("stop = 4.0\nholdout = 0.0\ninitial_states = \"recorded\"\n")
    code = main(["calibrate", str(log), "--fmu", str(VAN_DER_POL), "--fit", "mu", "--guess", "mu=-0.6", "--segment",
                 "2", "--settings", str(settings), "--no-plots", "--quiet", "--out", str(tmp_path / "out")])
    err = capfd.readouterr().err
    assert code in (0, 1) and "internal error" not in err
    assert refused and all("CVODE failed" in r and "|h| = hmin" in r for r in refused)
    assert "[WARNING]" not in err and "t + h = t" not in err  # SUNDIALS's own stderr


def test_an_overflowing_jacobian_is_not_finite_for_the_solver_s_fallback_not_an_overflow_error():
    # the random-start benchmark's plant in Model Exchange (seed 0, run 30): the right-hand side's differences
    # overflowed at a trial point; the Magnus step's scaling took log2(inf) and ended in an internal error
    from cosim.calibration.sensitivity import expm_batch

    M = np.zeros((2, 2, 2))
    M[1, 0, 1] = np.inf
    assert np.isnan(expm_batch(M)).all()
    np.testing.assert_array_equal(expm_batch(np.zeros((1, 2, 2))), np.eye(2)[None])
