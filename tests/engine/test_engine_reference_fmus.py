"""FMUs we did not write: the Modelica Association's Reference FMUs
(``../shared/reference-fmus/``), flown through ``fnn-cosim run`` of a
scenario, in Co-Simulation and in Model Exchange, against their published
results and against fmpy's own runs.

* Co-Simulation at the default experiment: the published ``_out.csv`` to 1e-9
  (fmpy's ``simulate_fmu`` gives it exactly).
* Model Exchange, fixed-step Euler at the model's internal step
  (``FIXED_SOLVER_STEP`` of the Reference FMUs' sources, the integrator of
  their own Co-Simulation): the published ``_out.csv`` to 1e-12.
* Model Exchange, CVODE: within 1e-6 (relative to the signal's largest
  value) of fmpy's own CVode run at the same tolerance, the bounces of
  BouncingBall in the same communication step; Roberts (stiff chemistry)
  too, where its three concentrations keep adding up to one.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from cosim.loop.recorder import read_results
from quadrotor_paper.cli import main
from tests.catalog_fmus import simulated
from tests.strict_json import read_summary

REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"
pytestmark = pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {REFERENCE} "
                                                                "(a copy of the project outside its workplace)")

# FIXED_SOLVER_STEP of each model's config.h: the step of the Reference FMUs' own forward Euler
EULER_STEP = {"BouncingBall": 1e-3, "Dahlquist": 0.1, "VanDerPol": 0.01, "Stair": 0.2}
CONTINUOUS = ["BouncingBall", "Dahlquist", "VanDerPol"]
CVODE_TOLERANCE = 1e-10  # relative; at 1e-8 two correct CVODE runs (ours stops at every point) differ by ~2e-6


def fmu(version: int, model: str) -> Path:
    return REFERENCE / f"fmi{version}" / f"{model}.fmu"


def experiment(version: int, model: str) -> tuple[float, float]:
    """(step, stop time) of the model's default experiment; a step it does
    not give is the spacing of the published results."""
    de = read_model_description(str(fmu(version, model))).defaultExperiment
    step = float(de.stepSize) if de.stepSize else float(np.diff(published(model)["time"][:2])[0])
    return step, float(de.stopTime)


def outputs(version: int, model: str) -> list[str]:
    """The model's outputs as recorded signals (an array's elements, 1-based)."""
    names = []
    for v in read_model_description(str(fmu(version, model))).modelVariables:
        if v.causality == "output":
            size = int(v.dimensions[0].start or v.dimensions[0].variable.start) if v.dimensions else 0
            names += [f"{v.name}[{i}]" for i in range(1, size + 1)] if size else [v.name]
    return names


def published(model: str) -> np.ndarray:
    return np.genfromtxt(REFERENCE / "results" / f"{model}_out.csv", delimiter=",", names=True)


def toml_value(value) -> str:
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + " }"
    return json.dumps(value)


def fly(tmp_path: Path, version: int, model: str, step: float, stop: float, names=None,
        **fmu_keys) -> dict[str, np.ndarray]:
    """``fnn-cosim run`` of a one-FMU scenario recording ``names`` (default:
    every output); the columns of its results.csv, and its summary."""
    names = names or outputs(version, model)
    lines = ["[simulation]", f"duration = {stop!r}", f"step = {step!r}", "", f"[fmus.{model}]",
             f"path = {json.dumps(str(fmu(version, model)))}"]
    lines += [f"{key} = {toml_value(value)}" for key, value in fmu_keys.items()]
    lines += ["", "[record]", f"signals = {json.dumps([f'{model}.{n}' for n in names])}"]
    scenario = tmp_path / f"{model}.toml"
    scenario.parent.mkdir(parents=True, exist_ok=True)
    scenario.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--out", str(out), "--no-plots", "--quiet"]) == 0
    header, rows = read_results(out / "results.csv")
    columns = dict(zip(header, rows.T))
    return {"time": columns["time"], **{n: columns[f"{model}.{n}"] for n in names},
            "summary": read_summary(out / "summary.json")}


def worst(ours: dict[str, np.ndarray], theirs, names=None) -> float:
    """The largest difference of any output (of those in ``theirs``), relative
    to that output's largest magnitude."""
    names = names or [n for n in theirs.dtype.names if n != "time"]
    theirs = {n: np.asarray(theirs[n], dtype=float) for n in names}
    return max(float(np.max(np.abs(ours[n] - theirs[n])) / max(np.max(np.abs(theirs[n])), 1e-300)) for n in names)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("model", CONTINUOUS)
def test_co_simulation_gives_the_published_results(tmp_path, version, model):
    step, stop = experiment(version, model)
    ours, theirs = fly(tmp_path, version, model, step, stop), published(model)
    np.testing.assert_allclose(ours["time"], theirs["time"], rtol=0, atol=1e-12)  # theirs: summed steps
    assert worst(ours, theirs) <= 1e-9


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("model", CONTINUOUS)
def test_model_exchange_with_their_euler_step_gives_the_published_results(tmp_path, version, model):
    """The published results are the FMUs' own forward Euler: the master's
    Euler at the same step, handling the same events, lands on them."""
    step, stop = experiment(version, model)
    ours = fly(tmp_path, version, model, step, stop, interface="ModelExchange",
               solver={"method": "euler", "step": EULER_STEP[model]})
    assert worst(ours, published(model)) <= 1e-12


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("model", CONTINUOUS)
def test_model_exchange_with_cvode_lands_on_fmpys_cvode_run(tmp_path, version, model):
    step, stop = experiment(version, model)
    ours = fly(tmp_path, version, model, step, stop, interface="ModelExchange",
               solver={"relative_tolerance": CVODE_TOLERANCE})
    theirs = simulated(fmu(version, model), fmi_type="ModelExchange", solver="CVode",
                          relative_tolerance=CVODE_TOLERANCE, output_interval=step, stop_time=stop,
                          record_events=False)
    np.testing.assert_allclose(ours["time"], theirs["time"], rtol=0, atol=1e-12)
    assert worst(ours, theirs) <= 1e-6
    if model == "BouncingBall":  # a bounce (v from falling to rising) in the same communication step
        bounces = lambda v: np.flatnonzero((v[:-1] < 0) & (v[1:] > 0))  # noqa: E731
        assert bounces(ours["v"]).size >= 5
        np.testing.assert_array_equal(bounces(ours["v"]), bounces(theirs["v"]))


def test_roberts_is_solved_as_a_stiff_ode(tmp_path):
    """Robertson's chemistry (rates from 0.04 to 3e7): CVODE's BDF as fmpy runs
    it; its default experiment spans 1e-5 to 1e8 s on a log scale, which a
    fixed communication step cannot sample, so 40 s at 0.1 s are flown."""
    ours = fly(tmp_path, 3, "Roberts", 0.1, 40.0, interface="ModelExchange",
               solver={"relative_tolerance": CVODE_TOLERANCE})
    theirs = simulated(fmu(3, "Roberts"), fmi_type="ModelExchange", solver="CVode", start_time=0.0,
                          relative_tolerance=CVODE_TOLERANCE, output_interval=0.1, stop_time=40.0, record_events=False)
    assert worst(ours, theirs, ["y1", "y2", "y3"]) <= 1e-6
    np.testing.assert_allclose(ours["y1"] + ours["y2"] + ours["y3"], 1.0, rtol=0, atol=1e-12)
    assert ours["y2"].max() > 3e-5 and ours["y1"][-1] < 0.8  # the fast transient and the slow decay, both seen


def test_a_start_value_of_a_state_is_set_by_the_standard(tmp_path):
    """BouncingBall's height is a state with initial = "exact": a start
    value, set before initialization in both interfaces."""
    for interface in ("CoSimulation", "ModelExchange"):
        ours = fly(tmp_path / interface, 3, "BouncingBall", 0.01, 1.0, interface=interface, start={"h": 2.0})
        assert ours["h"][0] == 2.0 and ours["h"][1] < 2.0


@pytest.mark.parametrize("start, message", [
    ({"der(h)": 1.0}, "fmus.BouncingBall.start.der(h) = 1.0: 'der(h)' is a local with initial = calculated: the "
                      "standard lets an importer set only inputs and variables whose initial is exact or approx"),
    ({"g": -3.0}, "fmus.BouncingBall.start.g = -3.0: 'g' is a parameter: give it in 'parameters'"),
    ({"nope": 1.0}, "fmus.BouncingBall.start.nope = 1.0: 'nope' is no variable of the FMU"),
])
def test_a_start_value_the_standard_forbids_is_one_line(tmp_path, capsys, start, message):
    scenario = tmp_path / "ball.toml"
    scenario.write_text(f'[simulation]\nduration = 1.0\nstep = 0.01\n[fmus.BouncingBall]\n'
                        f'path = {json.dumps(str(fmu(3, "BouncingBall")))}\nstart = {toml_value(start)}\n')
    assert main(["run", str(scenario), "--out", str(tmp_path / "out"), "--no-plots", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_an_fmu_that_chatters_is_stopped_naming_the_time_and_the_fmu(tmp_path, capsys):
    """More events in one communication step than the solver allows (here
    one, with BouncingBall's bounces coming ever faster): one line with the
    FMU, the time and the reason; the rows before it are kept."""
    scenario = tmp_path / "ball.toml"
    scenario.write_text(f'[simulation]\nduration = 3.0\nstep = 0.5\n[fmus.Ball]\n'
                        f'path = {json.dumps(str(fmu(2, "BouncingBall")))}\ninterface = "ModelExchange"\n'
                        f'solver = {{ max_events = 1 }}\n[record]\nsignals = ["Ball.h"]\n')
    assert main(["run", str(scenario), "--out", str(tmp_path / "out"), "--no-plots", "--quiet"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "Ball" in err and "more than 1 events in one communication step" in err and "at t = " in err
    rows = np.genfromtxt(tmp_path / "out" / "results.csv", delimiter=",", names=True)
    assert rows.size >= 2 and rows["time"][0] == 0.0


def test_an_euler_step_that_does_not_divide_the_communication_step_is_refused(tmp_path, capsys):
    scenario = tmp_path / "ball.toml"
    scenario.write_text(f'[simulation]\nduration = 1.0\nstep = 0.01\n[fmus.Ball]\n'
                        f'path = {json.dumps(str(fmu(2, "BouncingBall")))}\ninterface = "ModelExchange"\n'
                        f'solver = {{ method = "euler", step = 0.003 }}\n')
    assert main(["run", str(scenario), "--out", str(tmp_path / "out"), "--no-plots", "--quiet"]) == 2
    assert ("fmus.Ball.solver.step = 0.003: the Euler step 0.003 s does not divide the communication step 0.01 s"
            in capsys.readouterr().err)


def test_scheduled_execution_only_is_refused_by_name(tmp_path, capsys):
    scenario = tmp_path / "clocks.toml"
    scenario.write_text(f'[simulation]\nduration = 1.0\nstep = 0.01\n[fmus.Clocks]\n'
                        f'path = {json.dumps(str(fmu(3, "Clocks")))}\n')
    assert main(["run", str(scenario), "--out", str(tmp_path / "out"), "--no-plots", "--quiet"]) == 2
    assert "neither Co-Simulation nor Model Exchange (Scheduled Execution only" in capsys.readouterr().err


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("interface", ["CoSimulation", "ModelExchange"])
def test_integer_outputs_and_resources_give_the_published_results(tmp_path, version, interface):
    """Resource reads its output from a file in the FMU's resources folder;
    Stair counts with time events (Model Exchange: Euler at its 0.2 s step)
    and asks to end the simulation at 9 s, in the step from 8.8 s: the run
    ends, status ok, at 8.8 s, where fmpy's Model Exchange run ends too
    (fmpy's Co-Simulation records one more row, at 9 s)."""
    keys = {"interface": interface}
    step, stop = experiment(version, "Resource")
    ours = fly(tmp_path / "resource", version, "Resource", step, stop, **keys)
    assert worst(ours, published("Resource")) == 0.0
    step, stop = experiment(version, "Stair")
    if interface == "ModelExchange":
        keys["solver"] = {"method": "euler", "step": EULER_STEP["Stair"]}
    ours, theirs = fly(tmp_path / "stair", version, "Stair", step, stop, **keys), published("Stair")
    assert ours["summary"]["status"] == "ok" and "asked to terminate the simulation" in ours["summary"]["terminated"]
    assert ours["time"][-1] == pytest.approx(8.8) and len(ours["time"]) == len(theirs) - 1
    np.testing.assert_array_equal(ours["counter"], theirs["counter"][:-1])


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("solver", ["CVode", "Euler"])
def test_stairs_counter_steps_at_fmpys_times(tmp_path, version, solver):
    step, stop = experiment(version, "Stair")
    ours = fly(tmp_path, version, "Stair", step, stop, interface="ModelExchange",
               solver={"method": solver.lower(), "step": EULER_STEP["Stair"]} if solver == "Euler" else {})
    theirs = simulated(fmu(version, "Stair"), fmi_type="ModelExchange", solver=solver, output_interval=step,
                          stop_time=stop, record_events=False)
    np.testing.assert_allclose(ours["time"], theirs["time"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ours["counter"], theirs["counter"])


def test_state_space_arrays_in_model_exchange_land_on_fmpys_cvode_run(tmp_path):
    """StateSpace (FMI 3.0): arrays sized by structural parameters, its
    state vector integrated by the master, every element recorded."""
    step, stop = experiment(3, "StateSpace")
    ours = fly(tmp_path, 3, "StateSpace", step, stop, interface="ModelExchange",
               solver={"relative_tolerance": CVODE_TOLERANCE})
    theirs = simulated(fmu(3, "StateSpace"), fmi_type="ModelExchange", solver="CVode",
                          relative_tolerance=CVODE_TOLERANCE, output_interval=step, stop_time=stop, record_events=False)
    names = outputs(3, "StateSpace")
    assert names == ["y[1]", "y[2]", "y[3]"]
    flat = {f"y[{i + 1}]": theirs["y"][:, i] for i in range(3)}
    assert max(float(np.max(np.abs(ours[n] - flat[n])) / np.max(np.abs(flat[n]))) for n in names) <= 1e-6


@pytest.mark.parametrize("version", [2, 3])
def test_feedthrough_in_model_exchange_gives_its_published_numbers(tmp_path, version):
    """Every numeric output of Feedthrough (no input connected: its start
    values) read from a Model Exchange instance, as published."""
    theirs = published("Feedthrough")
    names = [n for n in outputs(version, "Feedthrough") if n in theirs.dtype.names
             and not n.startswith(("String", "Binary", "Boolean"))]
    assert len(names) >= 3
    step, stop = experiment(version, "Feedthrough")
    ours = fly(tmp_path, version, "Feedthrough", step, stop, names=names, interface="ModelExchange")
    assert worst(ours, theirs, names) == 0.0


def test_fmi_1_0_is_refused_in_one_line(tmp_path):
    """An FMI 1.0 FMU (its modelDescription is enough to tell) is refused
    naming the version and what the master takes (docs/fmi-support.md)."""
    import zipfile

    from cosim.errors import FmuLoadError
    from cosim.fmi.fmu import FmuComponent

    path = tmp_path / "Old.fmu"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("modelDescription.xml", '<?xml version="1.0"?><fmiModelDescription fmiVersion="1.0" '
                         'modelName="Old" modelIdentifier="Old" guid="{0}" numberOfContinuousStates="0" '
                         'numberOfEventIndicators="0"><ModelVariables/></fmiModelDescription>')
    with pytest.raises(FmuLoadError, match=r"FMI 1.0 is not supported \(2.0 or 3.0\)"):
        FmuComponent("Old", path)


@pytest.mark.parametrize("version", [2, 3])
def test_a_model_exchange_run_resumes_from_its_snapshot(version):
    """A snapshot of a Model Exchange FMU holds its continuous and discrete
    states; resumed from it, an Euler run is the same run to the last bit,
    a CVODE run (restarted there) lands within its tolerance."""
    from cosim.fmi.fmu import FmuComponent
    from cosim.loop.master import Master
    from cosim.fmi.model_exchange import SolverSettings

    for solver, within in ((SolverSettings("euler", step=EULER_STEP["BouncingBall"]), 0.0),
                           (SolverSettings(relative_tolerance=CVODE_TOLERANCE), 1e-7)):
        ball = FmuComponent("B", fmu(version, "BouncingBall"), interface="ModelExchange", solver=solver)
        with Master([ball], [], [], 0.01, record=["B.h", "B.v"]) as master:
            whole = master.run(2.0, snapshots=[1.0])
            resumed = master.run(1.0, t0=1.0, restore=whole.snapshots[0].states)
        assert np.max(np.abs(resumed.data[:, 1:] - whole.data[100:, 1:])) <= within
        assert np.count_nonzero(np.diff(np.sign(resumed["B.v"])) > 0) >= 2  # bounces after the snapshot


def test_an_archive_keeps_how_the_master_runs_an_fmu(tmp_path):
    """An exported archive carries each FMU's interface, solver and start
    values, and the Model Exchange coupling (SSP 1.0 has no place for them:
    this engine's annotation), and
    the archive read back flies the same run."""
    from cosim.scenario.definition import parse_scenario
    from cosim.scenario.assembly import build_master
    from cosim.ssp.archive import load_ssp
    from cosim.ssp.export import export_ssp

    raw = {"simulation": {"duration": 2.0, "step": 0.01, "coupling": "loose"},
           "fmus": {"Ball": {"path": str(fmu(3, "BouncingBall")), "interface": "ModelExchange",
                             "solver": {"method": "euler", "step": 0.001}, "start": {"h": 2.0}}},
           "record": {"signals": ["Ball.h", "Ball.v"]}}
    scenario = parse_scenario(raw)
    loaded = load_ssp(export_ssp(scenario, tmp_path / "ball.ssp"))
    spec = loaded.fmus["Ball"]
    assert (spec["interface"], dict(spec["solver"]), dict(spec["start"])) == (
        "ModelExchange", {"method": "euler", "step": 0.001}, {"h": 2.0})
    assert loaded.coupling == "loose"
    runs = []
    for each in (scenario, loaded):
        with build_master(each) as master:
            runs.append(master.run(2.0))
    np.testing.assert_array_equal(runs[0].data, runs[1].data)
    assert runs[0].data[0, 1] == 2.0
