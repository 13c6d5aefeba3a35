"""The linear analysis checked against the nonlinear co-simulation (plant FMU
+ master), the learning laws' finite-time claims on recorded runs, and the
report / command."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from quadrotor_paper.stability import critical_gain_factor, hover
from quadrotor_paper.learning_claims import AxisClaims, Recording, _signals, evaluate_claims, recorded
from quadrotor_paper.stability.loops import LoopModel
from quadrotor_paper.stability.validation import Ramp, check_gains, check_step, growth_rate, position_step, ramp_lag
from fnn_controller import PositionParams
from fnn_controller.step import initial_state
from fnn_controller.variants import variant as lookup

H = 0.01
TOLERANCE = 0.01  # of the step: the stated agreement of linear model and co-simulation


def record_run(name: str, variant: str, scenario: str = "circles", overrides: dict | None = None) -> Recording:
    """Run ``scenario`` (shipped name or path, with dotted ``overrides``) with
    the controller ``variant`` and record what the claims need."""
    from cosim.scenario.definition import load_scenario
    from quadrotor_paper.experiments import run_once

    sc = load_scenario(scenario, {**(overrides or {}), "controller.variant": variant,
                                  "record.signals": _signals(variant)})
    result, _ = run_once(sc, keep=None)  # every row: the claims read the whole flight
    return replace(recorded(sc, result)["recorded"], name=name)


@pytest.fixture(scope="module")
def op():
    return hover()


@pytest.fixture(scope="module")
def fmu(quadrotor_fmu2):
    return quadrotor_fmu2


@pytest.fixture(scope="module")
def pd_ramp(op, fmu):
    """The paper's PD co-simulated behind a 2.5 m/s ramp for 15 s: (lag, run), read by its own test and
    compared with the feed-forward's."""
    return ramp_lag(op, 2.5, duration=15.0, fmu=fmu)


@pytest.mark.parametrize("kind, axis, size", [
    ("position", "x", 0.02), ("position", "y", 0.02), ("position", "z", 0.1),
    ("velocity", "x", 0.05), ("velocity", "y", 0.05), ("velocity", "z", 0.05)])
def test_small_steps_from_hover_match_the_linear_model(op, fmu, kind, axis, size):
    """Every sample of the compared quantity (3 axes) within 1 % of the step."""
    chk = check_step(op, kind, axis, size, fmu=fmu)
    assert chk.nonlinear.status == "ok"
    assert chk.relative < TOLERANCE, f"{kind} {axis}: {100 * chk.relative:.3f} % of the step"
    moved = chk.nonlinear.x[-1, "xyz".index(axis) + (0 if kind == "position" else 3)]
    assert abs(moved) > 0.9 * size  # the step happened (not two zero responses)


def test_the_master_adds_no_delay_the_delayed_model_fits_worse(op, fmu):
    """The ZOH loop without delay matches the co-simulation 10x better than
    the same loop with one step of delay on the rotor commands."""
    import control as ct

    step = (0.02, 0.0, 0.0)
    nl = position_step(op, step, 3.0, fmu=fmu)
    errors = {}
    for delay in (0, 1):
        sys = LoopModel(op, H, delay).closed_loop()
        t = nl.t
        u = np.zeros((sys.ninputs, t.size))
        u[0] = step[0]
        lin = ct.forced_response(sys, t, u).outputs[:12].T
        errors[delay] = np.abs(lin[:, 3] - nl.x[:, 3]).max()  # velocity u, the most sensitive
    assert errors[1] > 10 * errors[0]


def test_large_steps_leave_the_linear_range_rotor_saturation(op, fmu):
    """A 1 m step asks for more roll/pitch torque than the rotors give: the
    linear model no longer holds (documented limit of the analysis)."""
    chk = check_step(op, "position", "x", 1.0, fmu=fmu)
    assert chk.relative > 0.1


def test_unstable_gains_grow_in_the_co_simulation_and_stable_ones_decay(op, fmu):
    """Along the ray through the paper's gains: 0.85x the critical factor
    decays, 1.3x grows (at the rate of the dominant pole until the rotors
    saturate), exactly as the linear analysis says."""
    c = critical_gain_factor(op, H)
    stable = check_gains(op, 0.85 * c * 2.5, 0.85 * c * 0.005, fmu=fmu)
    unstable = check_gains(op, 1.3 * c * 2.5, 1.3 * c * 0.005, fmu=fmu)
    assert stable.linear_stable and not unstable.linear_stable
    assert stable.nonlinear_growth < -0.2 and stable.amplification < 0.2
    assert unstable.pole_growth > 0.3
    assert unstable.nonlinear_growth > 0.3 and unstable.amplification > 10


def test_just_past_the_boundary_the_co_simulation_grows_at_the_dominant_poles_rate(op, fmu):
    c = critical_gain_factor(op, H)
    g = check_gains(op, 1.07 * c * 2.5, 1.07 * c * 0.005, duration=8.0, fmu=fmu)
    assert not g.linear_stable
    assert g.nonlinear_growth == pytest.approx(g.pole_growth, abs=0.02)
    assert g.nonlinear_status == "ok"  # still small after 8 s: no saturation yet


def test_pd_ramp_lag_in_the_co_simulation_is_the_trimmed_e_star(pd_ramp):
    """The co-simulated lag behind a 2.5 m/s ramp equals e* of the forward
    flight trim (the nonlinear drag included) and is about V/kp = 1 m."""
    from quadrotor_paper.stability import forward_flight

    lag, run = pd_ramp
    assert run.status == "ok"
    assert lag == pytest.approx(forward_flight(2.5).position_error[0], abs=1e-4)
    assert lag == pytest.approx(2.5 / 2.5, abs=0.06)


def test_ramp_reference_follows_the_trajectory_contract():
    r = Ramp(speed=2.0, t_start=1.0, x0=1.0, z0=-5.0)
    p, v = r.reference(np.array([0.0, 1.0, 2.5]))
    np.testing.assert_allclose(p[:, 0], [1.0, 1.0, 4.0])
    np.testing.assert_allclose(p[:, 2], -5.0)
    np.testing.assert_allclose(v[:, 0], [0.0, 2.0, 2.0])
    assert p.shape == v.shape == (3, 3)


def test_growth_rate_of_a_known_exponential():
    t = np.arange(0, 10, H)
    for sigma in (-0.4, 0.0, 0.25):
        y = np.exp(sigma * t) * np.sin(7.0 * t)
        assert growth_rate(t, y) == pytest.approx(sigma, abs=1e-3)
    assert math.isnan(growth_rate(t[:50], t[:50]))


def test_kd_below_minus_one_runs_away_in_the_co_simulation_too(op, fmu):
    """kd < -1 cancels the velocity feedback (v* = ... - kd v): the analysis
    finds a fast unstable pair, and the co-simulated vehicle runs away."""
    g = check_gains(op, 2.5, -1.5, size=0.01, duration=6.0, fmu=fmu)
    assert not g.linear_stable and g.pole_growth > 1.0
    assert g.amplification > 10


# ---- finite-time claims -----------------------------------------------------------------

def _synthetic_run(variant, tau_c, tau, t):
    n = t.size
    states = np.tile(initial_state(lookup(variant), 0), (n, 1))
    zeros = np.zeros((n, 3))
    return Recording("synthetic", variant, t, zeros, zeros, tau_c, zeros, tau, states, PositionParams())


def test_claims_of_a_known_learning_error():
    """tau_c = 1 - t on x (reaches zero at t = 1 s), tau = 0.3 t: B = 0.3,
    SMC radius nu B, LM t_h = 4 |tau_c(0)| / gamma; tau_c = exp(-3 t)
    enters the radius for good at ln(1/radius)/3."""
    t = np.arange(0, 3.0 + H / 2, H)
    tc = np.zeros((t.size, 3))
    tc[:, 0] = 1.0 - t
    tau = np.zeros((t.size, 3))
    tau[:, 0] = 0.3 * t
    smc = evaluate_claims(_synthetic_run("pd+smc", tc, tau, t), 0)
    assert smc.B == pytest.approx(0.3) and smc.tau_c0 == 1.0
    assert smc.t_zero == pytest.approx(1.0, abs=H / 2)
    assert smc.radius_53 == pytest.approx(0.85 * 0.3)
    assert math.isnan(smc.t_enter_53)  # |1 - t| leaves the radius again after t = 1.255 s
    assert math.isnan(evaluate_claims(_synthetic_run("pd+lm", tc[:100], tau[:100], t[:100]), 0).max_after_t_h)
    decaying = tc.copy()
    decaying[:, 0] = np.exp(-3 * t)
    smc = evaluate_claims(_synthetic_run("pd+smc", decaying, tau, t), 0)
    assert smc.t_enter_53 == pytest.approx(math.log(1 / 0.255) / 3, abs=H)
    assert math.isnan(smc.t_zero)
    lm = evaluate_claims(_synthetic_run("pd+lm", tc, tau, t), 0)
    assert lm.t_h_70 == pytest.approx(4 * 1.0 / 1.5)
    assert lm.max_after_t_h == pytest.approx(2.0)  # |1 - t| at the end, t = 3 s
    assert lm.printed_condition and lm.needed_condition  # 1.5 >= 4 * 0.3
    assert lm.delta_is_wtw == 0.0  # W^T W <= 1 < alpha_bar_x = 1.1: delta is never W^T W
    assert 1.5 / 9 / (1.1 + 1 / 9) - 1e-12 <= lm.rate_min <= lm.rate_max <= 1.5 / 2.1 + 1e-12
    assert smc.alpha_star_in_box and smc.alpha_bound == 10.0  # alpha* = 2 B = 0.6 <= alpha_max
    steep = tau.copy()
    steep[:, 0] = 6.0 * t  # B = 6: alpha* >= 12 lies outside [0, 10]
    assert not evaluate_claims(_synthetic_run("pd+smc", tc, steep, t), 0).alpha_star_in_box
    assert not evaluate_claims(_synthetic_run("pd+it2-smc", tc, steep, t), 0).alpha_star_in_box
    with pytest.raises(ValueError, match="variant 'pd' has no learning law"):
        evaluate_claims(_synthetic_run("pd", tc, tau, t), 0)


@pytest.mark.parametrize("variant", ["pd+smc", "pd+it2-smc"])
def test_the_regressor_moves_per_step_second_order_away_from_the_floor(variant):
    """Eq. 45 / IT-12 say the normalized firing strengths do not move; the
    forward Euler step moves them at second order in dt alpha away from the
    width floor (halving alpha quarters the change) and at first order where
    the floor acts (halving alpha halves it)."""
    from quadrotor_paper.learning_claims import regressor_step_change

    away_1, floor_1 = regressor_step_change(variant, 0.2)
    away_2, floor_2 = regressor_step_change(variant, 0.1)
    assert away_1 / away_2 == pytest.approx(4.0, rel=0.05)
    assert floor_1 / floor_2 == pytest.approx(2.0, rel=0.05)
    assert 0 < away_1 < floor_1


def test_lm_terms_are_the_controllers_law():
    """delta (eq. 62) and the decrease rate (eq. 61) are evaluated from
    fnn_controller.learning: with alpha_bar below W^T W (>= 1/9), delta is
    W^T W and the rate is the proof's gamma/2; with alpha_bar above it, delta
    is alpha_bar and the rate gamma W^T W/(alpha_bar + W^T W)."""
    from quadrotor_paper.learning_claims import _law_terms

    t = np.arange(0, 1.0 + H / 2, H)
    zeros = np.zeros((t.size, 3))
    run = _synthetic_run("pd+lm", zeros, zeros, t)
    _, wtw, delta, rate = _law_terms(run, 0, 1.5, 1e-3)
    assert np.all(wtw >= 1 / 9 - 1e-12) and np.all(delta == wtw)
    assert rate == pytest.approx(0.75, rel=1e-12)
    _, wtw, delta, rate = _law_terms(run, 0, 1.5, 2.0)
    assert np.all(delta == 2.0)
    assert rate == pytest.approx(1.5 * wtw / (2.0 + wtw), rel=1e-12)


@pytest.mark.parametrize("variant", ["pd+lm", "pd+it2-lm"])
def test_lm_step_run_reaches_zero_inside_t_h_but_does_not_stay(fmu, variant):
    """A 1 m x step from hover under PD + LM (type-1, eqs. 61-62, or interval
    type-2, IT-10, IT-11): tau_c first reaches zero well inside eq. 70's t_h,
    then chatters (relay limit cycle) instead of staying on the manifold;
    eq. 66's gamma >= 4B (IT-15's too) fails on the run."""
    run = record_run("step", variant, "circles", {
        "trajectory": {"kind": "hover", "x": 1.0, "y": 0.0, "z": -15.0},
        "wind.speed": 0.0, "simulation.duration": 10.0})
    assert run.status == "ok" and run.states.shape == (run.t.size, 3 * lookup(variant).axis_state_size)
    c: AxisClaims = evaluate_claims(run, 0)
    assert c.tau_c0 == pytest.approx(2.5, rel=1e-9)  # kp e(0) = 2.5 x 1 m
    assert c.t_h_70 == pytest.approx(4 * 2.5 / 1.5)
    assert c.t_zero < c.t_h_70
    assert c.max_after_t_h > 0.05  # not on the sliding manifold after t_h
    assert c.printed_condition and not c.needed_condition
    assert c.delta_is_wtw == 0.0 and c.rate_max < 0.75  # below the gamma/2 of eq. 65
    assert 0 < c.regressor_step_max < 0.01  # the regressor moves, a little (IT-12 / eq. 45 say not at all)


def test_smc_step_run_converges_and_alpha_adapts(fmu):
    run = record_run("step", "pd+smc", "circles", {
        "trajectory": {"kind": "hover", "x": 1.0, "y": 0.0, "z": -15.0},
        "wind.speed": 0.0, "simulation.duration": 10.0})
    c = evaluate_claims(run, 0)
    assert c.final_band < 0.01 < c.tau_c0
    assert c.alpha_max > 100 * c.alpha_min  # eq. 38 moved alpha
    assert c.radius_53 > c.tau_c_max  # eq. 53's neighbourhood does not bind on this run


# ---- the report and the command ---------------------------------------------------------

# the figures the command's tests read (--figures): hover's four, drawn in its second process, one of each
# figure function, then one of each other kind and point, drawn by the command itself; the six others are
# about 4 s of CPU more
FIGURES = ("bode_outer_hover", "bode_inner_hover", "nyquist_outer_hover", "pzmap_hover", "pzmap_forward",
           "nyquist_outer_forward_wind", "gain_sweep")


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """``fnn-cosim stability --no-cosim --workers 2 --figures ...`` run once (its report and the figures
    the tests read, :data:`FIGURES`, about 7 s of CPU): its folder, what it printed, and the study it wrote
    (kept as ``run_stability_analysis`` returned it), for the command's test and for the test of the
    figures it drew in its second process. Its gain sweep on every fifth gain of the grid, ends included
    (26 x 20 closed loops, not 126 x 96: 1.6 s of CPU less); the tests read the report's sections and
    files, test_stability_linear the sweep itself."""
    import contextlib
    import io

    from quadrotor_paper.cli import main
    from quadrotor_paper.stability import study as study_module

    out = tmp_path_factory.mktemp("stability")
    studies = []
    original = study_module.run_stability_analysis

    def kept(*args, **kwargs):
        studies.append(original(*args, **kwargs))
        return studies[-1]

    with pytest.MonkeyPatch.context() as patch, contextlib.redirect_stdout(io.StringIO()) as printed:
        patch.setattr(study_module, "run_stability_analysis", kept)
        patch.setattr(study_module, "SWEEP_KP", study_module.SWEEP_KP[::5])  # StabilitySettings' defaults
        patch.setattr(study_module, "SWEEP_KD", study_module.SWEEP_KD[::5])
        assert main(["stability", "--out", str(out), "--no-cosim", "--workers", "2", "--figures", *FIGURES]) == 0
    assert studies[0].sweeps[0].measure.shape == (20, 26)  # the coarser grid reached the study
    return out, printed.getvalue(), studies[0]


def test_command_writes_the_report_and_figures(report):
    tmp_path, out, _ = report
    text = (tmp_path / "stability.md").read_text()
    for needle in ("## Closed-loop poles", "## Margins", "## Where stability stops", "## Ramp error",
                   "| hover | discrete h (co-sim) | **yes**", "| forward_wind | outer x |"):
        assert needle in text
    for name in ("gain_sweep", "bode_outer_hover", "nyquist_outer_forward_wind", "pzmap_forward"):
        png = tmp_path / f"{name}.png"
        assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the figures asked for, those alone, listed in the report's order
    assert sorted(p.stem for p in tmp_path.glob("*.png")) == sorted(FIGURES)
    listed = [line[3:-5] for line in text.split("## Figures", 1)[1].splitlines() if line.startswith("* `")]
    assert listed == list(FIGURES)
    # the default is the PD baseline: the learning laws' sections only with --along-flight, and a line saying so
    assert "## The learning loop along the flight" not in text and "## The learning laws' finite-time" not in text
    assert "`fnn-cosim stability --along-flight` adds them" in text
    assert not (tmp_path / "along_flight.csv").exists() and not (tmp_path / "along_flight.png").exists()
    assert "hover: stable" in out and "report:" in out and "fnn-cosim stability --along-flight" in out


def test_a_figure_the_report_does_not_have_is_refused_in_one_line(tmp_path, capsys):
    from quadrotor_paper.cli import main

    assert main(["stability", "--out", str(tmp_path), "--no-cosim", "--figures", "gain_sweep", "bode_hover"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fnn-cosim: error: --figures bode_hover: no such figure (the report's are bode_outer_hover, ")
    assert len(err.splitlines()) == 1 and not any(tmp_path.iterdir())


@pytest.mark.slow  # the whole report with its learning-law parts: ~20 s even on the smallest study
def test_along_flight_flag_writes_the_learning_laws_sections(tmp_path, capsys, monkeypatch):
    """``--along-flight`` adds the finite-time claims and the learning loop along the flight, its plan
    printed before it starts and a progress bar on stderr; the smallest study: the circles only, the PD
    and PD+LM, frozen once (every 40 s), one learning law's recorded runs."""
    from functools import partial
    from importlib import import_module

    from quadrotor_paper.cli import main
    from quadrotor_paper.learning_claims import default_runs

    # the modules (the package's name along_flight is the function of that module)
    af, study = (import_module(f"quadrotor_paper.stability.{m}") for m in ("along_flight", "study"))

    small = {"missions": ("circles",), "variants": ("pd", "pd+lm"), "phis": (0.0,)}
    monkeypatch.setattr(af, "along_flight_study", partial(af.along_flight_study, **small))
    monkeypatch.setattr(af, "along_flight_plan", partial(af.along_flight_plan, **small))
    monkeypatch.setattr(study, "default_runs", partial(default_runs, variants=("pd+lm",)))
    assert main(["stability", "--out", str(tmp_path), "--along-flight", "--along-every", "40", "--workers", "1"]) == 0
    text = (tmp_path / "stability.md").read_text()
    assert "## The learning loop along the flight" in text and "## The learning laws' finite-time" in text
    assert "| circles | pd | sign law | 1 | stable at all 1 points" in text and "| circles | pd+lm | sign law | 1 |" in text
    assert "--along-flight` adds them" not in text
    assert len((tmp_path / "along_flight.csv").read_text().splitlines()) == 3  # header, one point per run
    captured = capsys.readouterr()
    assert "along the flight: 2 runs, 2 frozen points, about" in captured.out
    assert "along circles, pd, sign law: learning held stable" in captured.out
    assert "along the flight" in captured.err and "2/2" in captured.err  # the progress bar, both runs done


def test_feed_forward_ramp_lag_in_the_co_simulation_is_the_trimmed_e_star(op, fmu, pd_ramp):
    """With the velocity feed-forward the co-simulated lag behind the 2.5 m/s
    ramp is e* of the forward-flight trim with the same gain (the drag's
    share, 0.056 m), a twentieth of the paper's PD's 1.056 m."""
    from quadrotor_paper.stability import forward_flight

    lag, run = ramp_lag(op.with_feedforward(1.0), 2.5, duration=15.0, fmu=fmu)
    assert run.status == "ok"
    trim = forward_flight(2.5, position=PositionParams(feedforward=1.0)).position_error[0]
    assert lag == pytest.approx(trim, abs=1e-4)
    assert lag < 0.06 * pd_ramp[0]


def test_operating_point_figures_drawn_aside_are_the_same_files(report, tmp_path):
    """The forked process of ``run_stability_analysis(workers > 1)`` writes what one process writes: the
    command's hover figures, the first drawn in its second process (the outer and inner loops' Bode
    plots, a Nyquist plot, a pole-zero map: one of each figure function), are the files drawn here from
    the command's own analyses."""
    from quadrotor_paper.stability.report import POINT_FIGURES_HERE, point_figures

    folder, _, study = report
    names = ["bode_outer_hover", "bode_inner_hover", "nyquist_outer_hover", "pzmap_hover"]
    points = [name for name in FIGURES if name != "gain_sweep"]  # the operating points' figures asked for
    assert [a.op.name for a in study.analyses][0] == "hover" and len(points) - POINT_FIGURES_HERE >= len(names)
    assert list(study.figures)[:4] == names and all(study.figures[n] == folder / f"{n}.png" for n in names)
    here = point_figures([a for a in study.analyses if a.op.name == "hover"], tmp_path / "here", names)
    assert list(here) == names
    for name, path in here.items():
        assert study.figures[name].read_bytes() == path.read_bytes(), name
