"""Behaviour kept through refactoring: a short Table 2 and Table 3 study gives
the numbers stored in ``tests/paper/data/short_tables_reference.json``,
produced by main at commit 5fb03ad (before the engine and the application
were split) with the same settings: 10 s missions, seeds 0 and 1, the
paper's three variants, circles at 1 and 5 m/s and the figure-8. The tables
print three decimals; the check is far tighter (1e-9 m), so any change of
the numerics shows."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from quadrotor_paper.experiments import measure
from quadrotor_paper.report import table_study

REFERENCE = json.loads((Path(__file__).parent / "data" / "short_tables_reference.json").read_text())


@pytest.mark.parametrize("scenario", sorted(REFERENCE))
def test_short_table_studies_give_the_stored_numbers(scenario):
    stored = REFERENCE[scenario]
    variants = list(dict.fromkeys(r["variant"] for r in stored["runs"]))
    winds = list(dict.fromkeys(r["wind_m_s"] for r in stored["runs"]))
    number = 2 if winds != [None] else 3
    study = table_study(number, seeds=max(r["seed"] for r in stored["runs"]) + 1, duration=stored["duration_s"],
                        variants=variants, options=[], **({"winds": winds} if number == 2 else {}))
    rows = measure(study).rows
    got = {(r["case"], r.get("wind.speed"), r["seed"]): r for r in rows}
    assert len(got) == len(stored["runs"])
    for ref in stored["runs"]:
        row = got[(ref["variant"], ref["wind_m_s"], ref["seed"])]
        assert row["status"] == "ok", row
        assert row["rmse_m"] == pytest.approx(ref["rmse_m"], abs=1e-9), ref
