"""Behaviour kept through refactoring: a short Table 2 and Table 3 sweep gives
the numbers stored in ``tests/data/short_tables_reference.json``, produced
by main at commit 5fb03ad (before the engine and the application were split)
with the same settings: 10 s missions, seeds 0 and 1, every variant, circles
at 1 and 5 m/s and the figure-8. The tables print three decimals; the check
is far tighter (1e-9 m), so any change of the numerics shows."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from quadrotor_paper.experiments import Job, sweep
from cosim.scenario import load_scenario

REFERENCE = json.loads((Path(__file__).parent / "data" / "short_tables_reference.json").read_text())


@pytest.mark.parametrize("scenario", sorted(REFERENCE))
def test_short_table_runs_give_the_stored_numbers(scenario):
    stored = REFERENCE[scenario]
    sc = load_scenario(scenario, {"simulation.duration": stored["duration_s"]})
    jobs = [Job(r["variant"], r["wind_m_s"], r["seed"]) for r in stored["runs"]]
    got = sweep(sc, jobs, workers=1)
    for run, ref in zip(got, stored["runs"]):
        assert run["status"] == "ok", run
        assert run["rmse_m"] == pytest.approx(ref["rmse_m"], abs=1e-9), ref
