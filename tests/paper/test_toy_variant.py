"""A toy controller variant registered from a test module (tests/paper/
toy_variant.py): one module is all it takes to appear in the command line
and as a row of a table run (``--variants``)."""
from __future__ import annotations

import json

import pytest

import toy_variant
from cosim.scenario import registry
from fnn_controller.variants import unregister_variant, variant_names
from quadrotor_paper.tables import cell
from tests.strict_json import read_summary


@pytest.fixture
def toy():
    with registry.scoped():  # the case the table registers for it goes with it
        toy_variant.register()
        yield toy_variant.NAME
        unregister_variant(toy_variant.NAME)


def test_a_toy_variant_is_one_module_away_from_the_cli_and_the_tables(toy, tmp_path, capsys):
    from quadrotor_paper.cli import _parser, main

    assert toy in variant_names()
    assert _parser().parse_args(["run", "circles", "--variant", toy]).variant == toy
    out = tmp_path / "t2"
    assert main(["table2", "--seeds", "1", "--winds", "1", "--duration", "3", "--workers", "1",
                 "--variants", f"pd,{toy}", "--out", str(out), "--quiet"]) == 0
    summary = read_summary(out / "summary.json")
    toy_cell = cell(summary, toy, 1.0)
    assert toy_cell["runs"] == 1 and toy_cell["metrics"]["rmse_m"]["mean"] > 0
    table = (out / "table2.md").read_text()
    assert "| PD+toy | " in table and "| PD+toy | " in capsys.readouterr().out
    toy_row = next(line for line in table.splitlines() if line.startswith("| PD+toy |"))
    assert toy_row.split("|")[3].strip() == "–"  # the paper has no such row
    # 20 % more P gain lags the ramp less than the PD alone
    assert toy_cell["metrics"]["rmse_m"]["mean"] < cell(summary, "pd", 1.0)["metrics"]["rmse_m"]["mean"]
