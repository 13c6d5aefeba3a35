"""The fnn-cosim command line: run, errors, scenarios, build-fmu."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from quadrotor_paper.cli import EXIT_BAD_INPUT, EXIT_RUN_FAILED, main
from cosim.loop.recorder import read_results
from tests.strict_json import read_summary


def test_run_writes_results_plots_and_summary(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["run", "circles", "--set", "simulation.duration=2.0", "--set", "wind.speed=5",
                 "--variant", "pd+smc", "--seed", "4", "--out", str(out), "--quiet", "--profile"])
    assert code == 0
    summary = read_summary(out / "summary.json")
    assert summary["status"] == "ok" and summary["variant"] == "pd+smc" and summary["seed"] == 4
    assert 0 < summary["rmse_m"] < 1.5 and summary["rows"] == 201
    assert {"fmu", "record", "guard", "fmu:controller"} <= set(summary["cost_per_step_us"])  # all FMUs
    for name in ("results.csv", "results.csv.json", "summary.md", "trajectory.png", "error.png",
                 "control_signals.png", "wind.png"):
        assert (out / name).is_file(), name
    columns, data = read_results(out / "results.csv")
    assert data.shape == (201, len(columns)) and data[-1, 0] == pytest.approx(2.0)
    assert f"Euclidean RMSE: {summary['rmse_m']:.4f} m" in capsys.readouterr().out


def test_bad_scenario_value_exits_with_its_message(tmp_path, capsys):
    code = main(["run", "circles", "--set", "simulation.step=-0.01", "--out", str(tmp_path), "--quiet"])
    assert code == EXIT_BAD_INPUT
    assert "fnn-cosim: error: simulation.step = -0.01: must be positive" in capsys.readouterr().err


def test_divergence_exits_nonzero_and_keeps_the_partial_csv(tmp_path, capsys):
    out = tmp_path / "div"
    code = main(["run", "circles", "--set", 'envelope={ "Quadrotor.z" = [-15.2, -14.8] }',
                 "--set", "simulation.duration=10.0", "--out", str(out), "--quiet", "--no-plots"])
    assert code == EXIT_RUN_FAILED
    err = capsys.readouterr().err
    assert "diverged at t = " in err and "Quadrotor.z = " in err and "outside its envelope [-15.2, -14.8]" in err
    summary = read_summary(out / "summary.json")
    assert summary["status"] == "diverged"
    columns, data = read_results(out / "results.csv")
    assert 1 < len(data) < 1001 and len(data) == summary["rows"]


def test_scenarios_lists_the_shipped_missions(capsys):
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    assert "circles" in out and "figure8" in out


def test_build_fmu_writes_the_plant_wind_references_and_every_controller(tmp_path, capsys):
    from tests.fmu_validation import validate_fmu

    from fmu_models.catalog import MODEL_NAMES
    from fmu_models.export.build import FMI_VERSIONS
    from fnn_controller.controller_fmu import fmu_identifier
    from fnn_controller.split import INNER_IDENTIFIER, outer_identifier
    from fnn_controller.variants import variant_names

    assert main(["build-fmu", "--out", str(tmp_path)]) == 0
    paths = [Path(p) for p in capsys.readouterr().out.split()]
    names = (set(MODEL_NAMES) | {fmu_identifier(v) for v in variant_names()}
             | {outer_identifier(v) for v in variant_names()} | {INNER_IDENTIFIER})
    assert {"Quadrotor", "WindGust", "ReferenceTwoCircles", "ControllerPDLM", "PositionControllerPDLM",
            "VelocityController", "VelocityLink3"} <= names
    assert sorted(p.stem for p in paths) == sorted(n for n in names for _ in FMI_VERSIONS)
    assert all(p.suffix == ".fmu" and p.exists() and validate_fmu(str(p)) == [] for p in paths)


HEAVY_MODULES = ("control", "scipy.signal", "matplotlib")


def _imported_modules(*argv: str, cwd) -> tuple[subprocess.CompletedProcess, set[str]]:
    """Run the ``fnn-cosim`` entry point in a fresh interpreter and return
    every module it imported (Python's own ``-X importtime`` listing)."""
    script = Path(sys.executable).with_name("fnn-cosim")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "quadrotor_paper.cli"]
    env = {**os.environ, "PYTHONPROFILEIMPORTTIME": "1"}
    proc = subprocess.run(command + list(argv), capture_output=True, text=True, env=env, cwd=cwd)
    modules = {line.rsplit("|", 1)[1].strip() for line in proc.stderr.splitlines()
               if line.startswith("import time:") and line.count("|") == 2}
    return proc, modules - {"imported package"}


def test_the_command_line_loads_no_analysis_or_plotting_library_it_does_not_use(tmp_path):
    proc, modules = _imported_modules("--help", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "quadrotor_paper.cli" in modules
    assert not modules & set(HEAVY_MODULES), sorted(modules & set(HEAVY_MODULES))


# What a run of already-built FMUs has no use for: the studies' cluster and
# statistics, plots (--no-plots), the linear analysis, the FMU builder, the
# in-process controller's CasADi function, the split controller, SSP archives.
NOT_FOR_A_RUN = ("dask", "distributed", "matplotlib", "control", "scipy", "casadi.casadi", "fmu_models.export.build",
                 "fmu_models.export.codegen", "fnn_controller.fast", "fnn_controller.split", "cosim.study.definition",
                 "cosim.study.run", "cosim.ssp.archive", "cosim.ssp.export")


def test_a_run_of_built_fmus_builds_no_model_and_loads_no_study_or_plotting_library(tmp_path):
    argv = ("run", "circles", "--no-plots", "--quiet", "--set", "simulation.duration=0.5")
    assert main([*argv, "--out", str(tmp_path / "first")]) == 0  # the FMUs built (or found) and recorded
    proc, modules = _imported_modules(*argv, "--out", str(tmp_path / "run"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert {"fmpy", "cosim.loop.master", "quadrotor_paper.controller_component"} <= modules  # the listing sees the run
    loaded = sorted(m for m in modules if any(m == name or m.startswith(name + ".") for name in NOT_FOR_A_RUN))
    assert loaded == []
