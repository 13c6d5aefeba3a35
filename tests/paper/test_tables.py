"""Table 2 and Table 3 on a reduced setting: the FNN rows beat PD; the
markdown and the study's summary.json hold every cell; ``fnn-cosim table2``
is the shipped study ``table2``, run for run."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from cosim.study.definition import load_study, plan
from cosim.study.run import read_runs
from quadrotor_paper.cli import main
from quadrotor_paper.report import table_study
from quadrotor_paper.tables import PAPER_TABLE2, cell, deviations, table2_markdown, table3_markdown
from tests.strict_json import read_summary


def _mean(summary, case, wind=None):
    return cell(summary, case, wind)["metrics"]["rmse_m"]["mean"]


def _rmse(out: Path, case: str) -> list[float]:
    """A row's RMSE of every run, in plan order."""
    return [float(r["rmse_m"]) for r in sorted(read_runs(out / "runs.csv"), key=lambda r: int(r["run"]))
            if r["case"] == case]


def test_table2_reduced_fnn_rows_beat_pd(tmp_path, capsys):
    out = tmp_path / "t2"
    assert main(["table2", "--seeds", "2", "--winds", "1,5", "--duration", "15", "--workers", "2",
                 "--variants", "pd,pd+smc,pd+lm", "--options", "none", "--out", str(out), "--quiet"]) == 0
    summary = read_summary(out / "summary.json")
    rows = read_runs(out / "runs.csv")
    assert len(rows) == summary["rows"] == 2 * 2 * 3 and all(r["status"] == "ok" for r in rows)
    for wind in (1.0, 5.0):
        pd = _mean(summary, "pd", wind)
        assert cell(summary, "pd", wind)["runs"] == 2
        assert sorted(int(r["seed"]) for r in rows if r["case"] == "pd" and float(r["wind.speed"]) == wind) == [0, 1]
        for fnn in ("pd+smc", "pd+lm"):
            assert _mean(summary, fnn, wind) < 0.75 * pd, (fnn, wind, _mean(summary, fnn, wind), pd)
    md = (out / "table2.md").read_text()
    assert "| PD+LM-FNN |" in md and "0.966" in md and "Reduction of the RMSE over PD" in md
    assert "| PD+LM-FNN |" in capsys.readouterr().out


def test_table3_reduced(tmp_path):
    out = tmp_path / "t3"
    assert main(["table3", "--seeds", "1", "--duration", "20", "--workers", "1", "--options", "none",
                 "--out", str(out), "--quiet"]) == 0
    summary = read_summary(out / "summary.json")
    assert _mean(summary, "pd+lm") < _mean(summary, "pd")
    assert "0.327" in (out / "table3.md").read_text()


def test_the_table_command_is_the_shipped_study_run_for_run(tmp_path):
    """``fnn-cosim table2`` without arguments plans exactly ``fnn-cosim sweep
    table2``'s runs (same fingerprint, same plan); with arguments it is the
    study file that says the same, and both give the same rows."""
    for number in (2, 3):
        shipped = load_study(f"table{number}")
        assert table_study(number).fingerprint == shipped.fingerprint
        assert plan(table_study(number)) == plan(shipped)
    (tmp_path / "small.toml").write_text(
        'scenario = "circles"\nname = "table2"\ndescription = "small"\n[set]\n"simulation.duration" = 2.0\n'
        '[cases.pd]\n[cases."pd+lm"]\n[cases.lm-bl]\nseeds = 1\n[sweep]\nseeds = 2\n'
        '[sweep.grid]\n"wind.speed" = [3.0]\n')
    common = ["--workers", "1", "--quiet"]
    assert main(["sweep", str(tmp_path / "small.toml"), "--out", str(tmp_path / "sweep"), "--no-plots", *common]) == 0
    assert main(["table2", "--seeds", "2", "--winds", "3", "--duration", "2", "--variants", "pd,pd+lm",
                 "--options", "lm-bl", "--option-seeds", "1", "--out", str(tmp_path / "table"), *common]) == 0
    a, b = (sorted(read_runs(tmp_path / d / "runs.csv"), key=lambda r: int(r["run"])) for d in ("sweep", "table"))
    assert len(a) == 5
    assert [{k: v for k, v in r.items() if k != "wall_time_s"} for r in a] == \
        [{k: v for k, v in r.items() if k != "wall_time_s"} for r in b]


def _summary(values: dict, cases: list[str], wind_key: bool = True) -> dict:
    """A study summary with one cell per (case, wind): ``values[case][wind] = (mean, failed)``."""
    from quadrotor_paper.options import OPTIONS
    from fnn_controller.variants import variant

    labels = {c: OPTIONS[c].label if c in OPTIONS else variant(c).label for c in cases}
    cells = [{"case": c, "label": labels[c], "values": {"wind.speed": w} if wind_key else {}, "runs": 10,
              "ok": 10 - failed, "diverged": failed, "failed": 0, "seeds": list(range(10)), "errors": [],
              "metrics": {"rmse_m": {"n": 10 - failed, "mean": mean, "std": 0.01, "ci95": None}}}
             for c in cases for w, (mean, failed) in values[c].items()]
    return {"cases": [{"name": c, "label": labels[c]} for c in cases], "cells": cells}


def test_markdown_known_answer():
    values = {v: {w: (x, 0) for w, x in by.items()} for v, by in PAPER_TABLE2.items()}
    values["pd+lm"][5.0] = (0.3, 0)  # more than 30 % below the paper's 0.689
    summary = _summary(values, list(values))
    md = table2_markdown(summary)
    assert "| PD | 0.966 ± 0.010 | 0.966 |" in md
    assert "0.300 ± 0.010 †" in md
    assert "| PD+SMC-FNN | 65 % | 65 % | 55 % | 55 % | 50 % | 50 % |" in md
    devs = deviations(summary, None)
    assert devs == [{"table": 2, "variant": "pd+lm", "wind_m_s": 5.0, "ours": 0.3, "paper": 0.689,
                     "relative": pytest.approx(0.3 / 0.689 - 1)}]
    t3 = table3_markdown(_summary({"pd": {None: (0.327, 0)}, "pd+lm": {None: (0.2, 1)}}, ["pd", "pd+lm"],
                                  wind_key=False))
    assert "| PD+LM-FNN | 0.200 ± 0.010 (1/10 diverged) | 0.228 | 39 % | 30 % |" in t3


@pytest.mark.slow
def test_full_reproduction(tmp_path):
    """The whole job (about 20 s on 2 cores): report with both tables and every figure."""
    assert main(["reproduce", "--out", str(tmp_path), "--quiet"]) == 0
    report = (tmp_path / "report.md").read_text()
    assert "## Table 2" in report and "## Table 3" in report
    summary = read_summary(tmp_path / "summary.json")
    assert summary["table2"]["rows"] == 186 and summary["table3"]["rows"] == 62
    for f in summary["figures"]["files"]:
        assert (tmp_path / "figures").joinpath(f).exists()


def test_an_unknown_variant_is_refused_before_any_run(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["table2", "--variants", "pd,pd+fuzzy", "--out", str(tmp_path / "t"), "--quiet"])
    assert exc.value.code == 2
    assert "unknown variant 'pd+fuzzy'; known: pd, pd+smc, pd+lm" in capsys.readouterr().err
    assert not (tmp_path / "t").exists()


def test_option_rows_follow_the_papers_rows_which_stay_bit_identical(tmp_path):
    """Option rows (quadrotor_paper/options.py) below the paper's, "–" in the
    paper's columns; the paper's rows give the very same numbers with and
    without them; feed-forward takes the PD's lag away (figure-8: 0.3 m)."""
    common = ["table3", "--seeds", "1", "--duration", "12", "--workers", "1", "--variants", "pd", "--quiet"]
    assert main(common + ["--options", "none", "--out", str(tmp_path / "paper")]) == 0
    assert main(common + ["--options", "pd-ff,pd-ff-acc", "--out", str(tmp_path / "opt")]) == 0
    opt = read_summary(tmp_path / "opt" / "summary.json")
    assert _rmse(tmp_path / "opt", "pd") == _rmse(tmp_path / "paper", "pd")
    assert _mean(opt, "pd-ff") < 0.5 * _mean(opt, "pd")
    assert _mean(opt, "pd-ff-acc") != _mean(opt, "pd-ff")  # the acceleration arrives
    cases = {c["name"]: c for c in opt["cases"]}
    assert cases["pd-ff-acc"]["connect"] and cases["pd-ff"]["overrides"] == {
        "controller.variant": "pd", "controller.position.feedforward": 1.0}
    lines = (tmp_path / "opt" / "table3.md").read_text().splitlines()
    rows = [line for line in lines if line.startswith("| PD")]
    assert [r.split(" | ")[0] for r in rows] == ["| PD", "| PD + feed-forward",
                                                 "| PD + velocity and acceleration feed-forward"]
    assert rows[1].split(" | ")[2] == "–" and rows[0].split(" | ")[2] == "0.327"


def test_unknown_option_is_refused_naming_it(capsys):
    with pytest.raises(SystemExit):
        main(["table2", "--options", "pd-ff,warp-drive", "--quiet"])
    err = capsys.readouterr().err
    assert "'warp-drive'" in err and "pd-ff" in err


def test_options_are_cases_with_names_apart_from_the_variants():
    from cosim.scenario import registry
    from fnn_controller.variants import variant_names
    from quadrotor_paper.options import DEFAULT_OPTIONS, OPTIONS, VARIANT_KEY

    assert not set(OPTIONS) & set(variant_names())
    assert set(DEFAULT_OPTIONS) <= set(OPTIONS)
    assert all(o.overrides[VARIANT_KEY] in variant_names() for o in OPTIONS.values())
    assert {**{v: registry.cases()[v] for v in variant_names()}, **OPTIONS}.items() <= registry.cases().items()


def test_table2_with_noise_on_has_spread_over_the_seeds_and_with_it_off_none(tmp_path):
    """The seed draws f_ij(0) and, on circles_sensors, the noise: the cells
    then spread and their intervals open; on the clean circles the LM cell's
    spread is f_ij(0)'s alone, far smaller."""
    spread = {}
    for scenario in ("circles", "circles_sensors"):
        out = tmp_path / scenario
        assert main(["table2", "--scenario", scenario, "--seeds", "3", "--winds", "3", "--duration", "4",
                     "--workers", "1", "--variants", "pd+lm", "--options", "none", "--out", str(out),
                     "--quiet"]) == 0
        summary = read_summary(out / "summary.json")
        assert summary["scenario"] == scenario
        stats = cell(summary, "pd+lm", 3.0)["metrics"]["rmse_m"]
        spread[scenario] = stats["std"]
        assert stats["ci95"][0] < stats["mean"] < stats["ci95"][1] or stats["std"] == 0
    assert spread["circles_sensors"] > 10 * spread["circles"]
    assert spread["circles_sensors"] > 1e-4  # m
