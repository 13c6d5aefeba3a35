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
    from cosim.calibration import _component
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model

    for fmu, interface in ((VAN_DER_POL, "ModelExchange"),
                           (built_fmu("Quadrotor", 2, lambda: model("Quadrotor")), "CoSimulation")):
        comp = _component(fmu, CalibrationSettings(fit=["mu"]), None)
        try:
            assert comp.interface == interface
        finally:
            comp.close()
