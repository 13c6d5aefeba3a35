"""Table 2 and Table 3 on a reduced setting: the FNN rows beat PD; the
markdown and summary.json hold every cell."""
from __future__ import annotations

import json

import pytest

from quadrotor_paper.cli import main
from quadrotor_paper.tables import PAPER_TABLE2, deviations, table2_markdown, table3_markdown


def test_table2_reduced_fnn_rows_beat_pd(tmp_path, capsys):
    out = tmp_path / "t2"
    assert main(["table2", "--seeds", "2", "--winds", "1,5", "--duration", "15", "--workers", "2",
                 "--variants", "pd,pd+smc,pd+lm", "--options", "none", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["runs"]) == 2 * 2 * 3 and all(r["status"] == "ok" for r in summary["runs"])
    cells = summary["cells"]
    for wind in ("1", "5"):
        pd = cells["pd"][wind]["mean"]
        assert cells["pd"][wind]["runs"] == 2 and len(cells["pd"][wind]["rmse"]) == 2
        for fnn in ("pd+smc", "pd+lm"):
            assert cells[fnn][wind]["mean"] < 0.75 * pd, (fnn, wind, cells[fnn][wind]["mean"], pd)
    md = (out / "table2.md").read_text()
    assert "| PD+LM-FNN |" in md and "0.966" in md and "Reduction of the RMSE over PD" in md
    assert "| PD+LM-FNN |" in capsys.readouterr().out


def test_table3_reduced(tmp_path):
    out = tmp_path / "t3"
    assert main(["table3", "--seeds", "1", "--duration", "20", "--workers", "1", "--options", "none",
                 "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["cells"]["pd+lm"]["mean"] < summary["cells"]["pd"]["mean"]
    assert "0.327" in (out / "table3.md").read_text()


def test_markdown_known_answer():
    cells = {v: {w: {"mean": x, "std": 0.01, "runs": 10, "failed": 0} for w, x in by.items()}
             for v, by in PAPER_TABLE2.items()}
    cells["pd+lm"][5.0]["mean"] = 0.3  # more than 30 % below the paper's 0.689
    md = table2_markdown(cells)
    assert "| PD | 0.966 ± 0.010 | 0.966 |" in md
    assert "0.300 ± 0.010 †" in md
    assert "| PD+SMC-FNN | 65 % | 65 % | 55 % | 55 % | 50 % | 50 % |" in md
    devs = deviations(cells, None)
    assert devs == [{"table": 2, "variant": "pd+lm", "wind_m_s": 5.0, "ours": 0.3, "paper": 0.689,
                     "relative": pytest.approx(0.3 / 0.689 - 1)}]
    t3 = table3_markdown({"pd": {None: {"mean": 0.327, "std": 0, "runs": 1, "failed": 0}},
                          "pd+lm": {None: {"mean": 0.2, "std": 0, "runs": 1, "failed": 1}}})
    assert "| PD+LM-FNN | 0.200 ± 0.000 (1/1 diverged) | 0.228 | 39 % | 30 % |" in t3


@pytest.mark.slow
def test_full_reproduction(tmp_path):
    """The whole job (about 20 s on 2 cores): report with both tables and every figure."""
    assert main(["reproduce", "--out", str(tmp_path), "--quiet"]) == 0
    report = (tmp_path / "report.md").read_text()
    assert "## Table 2" in report and "## Table 3" in report
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary["table2"]["runs"]) == 90 and len(summary["table3"]["runs"]) == 30
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
    paper = json.loads((tmp_path / "paper" / "summary.json").read_text())
    opt = json.loads((tmp_path / "opt" / "summary.json").read_text())
    assert opt["cells"]["pd"]["rmse"] == paper["cells"]["pd"]["rmse"]
    assert opt["cells"]["pd-ff"]["mean"] < 0.5 * opt["cells"]["pd"]["mean"]
    assert opt["cells"]["pd-ff-acc"]["mean"] != opt["cells"]["pd-ff"]["mean"]  # the acceleration arrives
    assert opt["options"]["pd-ff-acc"]["connections"] and opt["options"]["pd-ff"]["overrides"] == {
        "controller.position.feedforward": 1.0}
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


def test_options_are_data_with_names_apart_from_the_variants():
    from fnn_controller.variants import variant_names
    from quadrotor_paper.options import DEFAULT_OPTIONS, OPTIONS, check_options

    assert not set(OPTIONS) & set(variant_names())
    assert set(DEFAULT_OPTIONS) <= set(OPTIONS)
    assert all(o.variant in variant_names() for o in OPTIONS.values())
    with pytest.raises(ValueError, match="'nope'"):
        check_options(["pd-ff", "nope"])


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
        summary = json.loads((out / "summary.json").read_text())
        assert summary["scenario"] == scenario
        cell = summary["cells"]["pd+lm"]["3"]
        spread[scenario] = cell["std"]
        assert cell["ci95"][0] < cell["mean"] < cell["ci95"][1] or cell["std"] == 0
    assert spread["circles_sensors"] > 10 * spread["circles"]
    assert spread["circles_sensors"] > 1e-4  # m
