"""The learning loop frozen along a flight (quadrotor_paper.stability.along_flight):
a snapshot of a run linearized from the FMUs is the trimmed loop where the
run is at trim, the linear loop predicts the co-simulated decay of a
perturbation for the PD, and the study runs every case through the one
study runner."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.scenario.definition import load_scenario
from cosim.scenario.assembly import build_master
from quadrotor_paper.stability import hover
from quadrotor_paper.stability.along_flight import (SECONDS_PER_POINT, AlongFlight, along_flight, along_flight_plan,
                                                    along_flight_study, flight_events, learned_state_names)
from quadrotor_paper.stability.fmu_loop import fmu_closed_loop, snapshot_loop

HOVER = {"trajectory": {"kind": "hover", "x": 0.0, "y": 0.0, "z": -15.0}, "wind.speed": 0.0,
         "simulation.duration": 20.0}


def test_a_snapshot_of_a_settled_hover_is_the_trimmed_hover_loop():
    """PD hovering in still air for 15 s has settled at the trim point: the
    loop from its snapshot (plant state read from its FMU state, controller
    at its FMU state, inputs as they were) is fmu_closed_loop(hover())."""
    scenario = load_scenario("circles", {**HOVER, "controller.variant": "pd"})
    with build_master(scenario) as master:
        snap = master.run(20.0, snapshots=[15.0]).snapshots[0]
        paths = {f.name: f.path for f in master.fmus}
    frozen = snapshot_loop(snap, paths["Quadrotor"], paths["controller"])
    trimmed = fmu_closed_loop(hover(), "pd")
    assert frozen.spectral_radius == pytest.approx(trimmed.spectral_radius, abs=1e-9)
    np.testing.assert_allclose(np.sort(np.abs(frozen.poles)), np.sort(np.abs(trimmed.poles)), atol=1e-8)
    assert frozen.plant.operating_point["z"] == pytest.approx(-15.0, abs=1e-6)


def test_along_the_circles_the_pd_loop_is_stable_and_the_linear_decay_is_the_co_simulated_one():
    scenario = load_scenario("circles", {"controller.variant": "pd", "simulation.duration": 12.0})
    flight = along_flight(scenario, AlongFlight(every=5.0))
    assert flight.status == "ok" and [p.time for p in flight.points] == [5.0, 10.0]
    for p in flight.points:
        assert p.radius < 0.98 and p.radius_held == p.radius  # a PD learns nothing
        assert p.error < 1e-4
        assert p.linear_rate < -1.0 and p.nonlinear_rate == pytest.approx(p.linear_rate, abs=0.05)
        # along the least stable mode (the PD's flight modes: its FNN is inert)
        assert p.mode_linear_rate < -2.5 and p.mode_nonlinear_rate == pytest.approx(p.mode_linear_rate, abs=0.05)


def test_learning_on_and_learning_held_are_two_readings_of_the_same_loop():
    """PD+LM with the boundary layer at 10 s of the circles: with the learned
    state held the flight modes are the PD's (< 1); with learning on, the
    learned widths add modes at |z| about 1 (the laws integrate), and the
    co-simulation, perturbed along that mode, grows as slowly."""
    scenario = load_scenario("circles", {"controller.variant": "pd+lm", "controller.position.phi": [0.2] * 3,
                                         "simulation.duration": 12.0})
    p = along_flight(scenario, AlongFlight(every=10.0, check=1.0)).points[0]
    assert p.radius_held < 0.98
    assert abs(p.radius - 1.0) < 1e-3
    assert math.isfinite(p.linear_rate) and math.isfinite(p.nonlinear_rate)
    assert abs(p.mode_linear_rate) < 0.01 and p.mode_nonlinear_rate == pytest.approx(p.mode_linear_rate, abs=0.01)


def test_the_study_runs_every_case_through_the_study_runner_in_case_order():
    arguments = dict(missions=("circles",), variants=("pd", "pd+lm"), phis=(0.0, 0.2),
                     metric=AlongFlight(every=2.0, check=0.0), overrides={"simulation.duration": 4.0})
    calls = []
    flights = along_flight_study(**arguments, progress=lambda done, total: calls.append((done, total)))
    assert [(f.variant, f.phi) for f in flights] == [("pd", 0.0), ("pd+lm", 0.0), ("pd+lm", 0.2)]
    assert calls[0] == (0, 3) and calls[-1] == (3, 3) and [d for d, _ in calls] == sorted(d for d, _ in calls)
    plan = along_flight_plan(**arguments, workers=2)  # counted before anything runs: what the study then did
    assert (plan.runs, plan.points) == (len(flights), sum(len(f.points) for f in flights)) == (3, 6)
    assert plan.seconds == pytest.approx(6 * SECONDS_PER_POINT / 2)
    assert str(plan).startswith("along the flight: 3 runs, 6 frozen points, about ") and "on 2 workers" in str(plan)
    for f in flights:
        assert f.status == "ok" and [p.time for p in f.points] == [2.0, 4.0]
        assert all(math.isnan(p.linear_rate) for p in f.points)  # check = 0: no perturbation check
        # each case's settings reached its run: the study's points are those of the case flown alone
        alone = load_scenario("circles", overrides={**arguments["overrides"], "controller.variant": f.variant,
                                                    "controller.position.phi": [f.phi] * 3})
        assert along_flight(alone, arguments["metric"]).points == f.points
    assert flights[1].points != flights[2].points  # the boundary layer changes what pd+lm learns


def test_flight_events_and_learned_state_names():
    assert flight_events(load_scenario("circles")) == [(17.0, "gust reverses"), (pytest.approx(25.2122, abs=1e-4),
                                                                                  "second circle"), (34.0, "gust reverses")]
    crossings = flight_events(load_scenario("figure8"))
    assert {label for _, label in crossings} == {"crossing"} and crossings[0][0] == pytest.approx(8.8858, abs=1e-4)
    names = learned_state_names("pd+lm")
    assert "f_11_x" in names and "sigma2_3_z" in names and not any(n.startswith("R_ref") for n in names)


def test_snapshot_times_must_be_whole_steps():
    with pytest.raises(ValueError, match=r"every 0\.015 s: not a whole number of steps of 0\.01 s"):
        AlongFlight(every=0.015).snapshot_times(load_scenario("circles"))


def _flight(radius, held, lin=(-1.0,), nl=(-1.1,), mode=(math.nan, math.nan)):
    from quadrotor_paper.stability.along_flight import FlightPoint, AlongFlightRun

    n = len(radius)
    lin, nl = (list(lin) * n)[:n], (list(nl) * n)[:n]
    points = tuple(FlightPoint(float(t + 1), r, h, 1e-7, 0.1, a, b, *mode)
                   for t, (r, h, a, b) in enumerate(zip(radius, held, lin, nl)))
    return AlongFlightRun("circles", "pd+lm", 0.0, "ok", None, points)


def test_the_verdicts_read_stable_neutral_and_unstable_from_the_growth_rate():
    from quadrotor_paper.stability.along_flight import verdict

    stable = verdict(_flight([0.97, 0.98], [0.97, 0.98]))
    assert stable["held"].startswith("stable at all 2 points (max 0.9800") and stable["on"].startswith("stable")
    neutral = verdict(_flight([1.00004, 0.97], [0.97, 0.97]))  # ln(1.00004)/0.01 = 0.004 1/s
    assert neutral["on"].startswith("neutral: learning modes at abs(z) = 1 + 4.0e-05")
    slow = verdict(_flight([1.0006, 0.97, 1.0002], [0.97, 1.2, 0.97]))  # 0.06 1/s and 0.02 1/s: both grow
    assert slow["on"].startswith("UNSTABLE at 2 of 3 points (max 1.0006 (+0.06 1/s) at 1 s)")
    assert slow["held"].startswith("UNSTABLE at 1 of 3 points (max 1.2000 (+18.2 1/s) at 2 s)")
    assert verdict(_flight([0.9], [0.9], lin=(-1.0,), nl=(-1.3,)))["check"] == \
        "rates differ by median 0.300 1/s, max 0.300 1/s"
    assert verdict(_flight([1.04, 1.04], [0.9, 0.9], mode=(4.0, -3.0)))["mode"] == \
        "rates differ by median 7.000 1/s; predicted to grow at 2 of 2 points, co-simulation grows at 0 of those"
    assert verdict(_flight([0.9], [0.9]))["mode"] == "not made"


def test_the_report_writes_the_section_the_table_and_the_points(tmp_path):
    from quadrotor_paper.stability.report import _section_along_flight
    from quadrotor_paper.stability.along_flight import write_points

    class Study:  # the report reads only these
        dt = 0.01
        along_flight = [_flight([0.97, 1.0006], [0.97, 0.97])]

    text = "\n".join(_section_along_flight(Study))
    assert "## The learning loop along the flight" in text
    assert "| circles | pd+lm | sign law | 2 | stable at all 2 points" in text and "UNSTABLE at 1 of 2" in text
    write_points(Study.along_flight, tmp_path / "points.csv")
    lines = (tmp_path / "points.csv").read_text().splitlines()
    assert lines[0].startswith("mission,variant,phi_mps,time,radius,radius_held") and len(lines) == 3
