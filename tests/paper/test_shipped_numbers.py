"""Behaviour kept: Tables 2-3 and every shipped study give, run for run, the
numbers main gave before the one-study-model rework (issue 16), stored in
``tests/paper/data/reference_runs.json`` (``fnn-cosim reproduce`` and
``fnn-cosim sweep`` of every shipped study at commit 3b1a015).

Compared with ``==``: the same code flies the same runs to the same bits.
In the normal suite two runs of each study (its first and its last, which
differ in case or grid point); behind ``-m slow`` every run of every study."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from cosim.study.runner import MasterCache, execute
from cosim.scenario.definition import apply_overrides, parse_scenario
from cosim.study.definition import load_study, runs
from quadrotor_paper.experiments import lean_signals, measure, study_metrics

REFERENCE = json.loads((Path(__file__).parent / "data" / "reference_runs.json").read_text())["studies"]


def _check(name: str, index: int, status: str, metrics: dict) -> None:
    stored = REFERENCE[name]["runs"][str(index)]
    assert status == stored["status"], (name, index)
    for m in ("rmse_m", "max_error_m", "final_error_m"):
        if m in stored:
            assert metrics.get(m) == stored[m], (name, index, m)


def _planned(study, indices):
    chosen = [r for r in runs(study) if r.index in indices]
    for run in chosen:  # the plan still puts the same run at this index
        stored = REFERENCE[study.name]["runs"][str(run.index)]
        assert (run.case, dict(run.values), run.seed) == (stored["case"], stored["values"], stored["seed"])
    return chosen


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_the_first_and_last_run_of_every_shipped_study_are_unchanged(name):
    study = load_study(name)
    assert len(REFERENCE[name]["runs"]) == sum(1 for _ in runs(study))
    base = parse_scenario(apply_overrides(study.scenario.raw, {"record.signals": lean_signals(study.scenario)}),
                          source=study.scenario.source)
    cache = MasterCache()
    try:
        for run in _planned(study, {0, len(REFERENCE[name]["runs"]) - 1}):
            rec = execute(base.raw, str(base.source), run, study_metrics, cache)
            _check(name, run.index, rec["status"], rec["metrics"])
    finally:
        cache.close()


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_every_run_of_every_shipped_study_is_unchanged(name):
    study = load_study(name)
    _planned(study, set(range(len(REFERENCE[name]["runs"]))))
    result = measure(study, workers=2)
    assert len(result.rows) == len(REFERENCE[name]["runs"])
    for row in result.rows:
        _check(name, row["run"], row["status"], row)
