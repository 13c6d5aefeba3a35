"""Save a trained controller and resume learning: one file format, read and
written by the Python fast path directly and by the controller FMU through
FMI calls on its live instance; the two forms save the same state and resume alike."""
from __future__ import annotations

import json

import numpy as np
import pytest

from quadrotor_paper.cli import EXIT_BAD_INPUT, main
from tests.strict_json import read_summary

RUN = ["--set", "simulation.duration=5.0", "--quiet", "--no-plots"]


def _run(tmp_path, name, *extra) -> dict:
    out = tmp_path / name
    assert main(["run", "circles", "--out", str(out), *RUN, *extra]) == 0
    return read_summary(out / "summary.json")


def _state(path) -> np.ndarray:
    return np.array(json.loads(path.read_text())["state"])


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A 5 s run saved by each form, and each resumed by each form."""
    tmp = tmp_path_factory.mktemp("learned")
    files, rmse = {}, {}
    for form in ("python", "fmu"):
        files[form] = tmp / f"{form}.json"
        rmse[form] = _run(tmp, form, "--set", f'controller.form="{form}"', "--save-learned", str(files[form]))["rmse_m"]
    for source in ("python", "fmu"):
        for form in ("python", "fmu"):
            key = f"{source}->{form}"
            files[key] = tmp / f"{key}.json"
            rmse[key] = _run(tmp, key, "--set", f'controller.form="{form}"', "--load-learned", str(files[source]),
                             "--save-learned", str(files[key]))["rmse_m"]
    return files, rmse


def test_both_forms_save_the_same_state(saved):
    files, rmse = saved
    np.testing.assert_array_equal(_state(files["python"]), _state(files["fmu"]))
    assert json.loads(files["fmu"].read_text())["source"] == "fmu"
    assert rmse["python"] == rmse["fmu"]


def test_a_resumed_run_differs_from_a_fresh_one_and_both_forms_resume_alike(saved):
    files, rmse = saved
    assert rmse["python->python"] != rmse["python"]
    for key in ("python->fmu", "fmu->python", "fmu->fmu"):
        assert rmse[key] == rmse["python->python"], key
        np.testing.assert_array_equal(_state(files[key]), _state(files["python->python"]))
    assert not np.array_equal(_state(files["python->python"]), _state(files["python"]))  # it went on learning


@pytest.mark.parametrize("change, message", [
    (lambda doc: {**doc, "variant": "pd+smc"}, "saved from a 'pd+smc' controller, this one is 'pd+lm'"),
    (lambda doc: {**doc, "format": "something else"}, "not a 'fnn-cosim learned state' file"),
    (lambda doc: {**doc, "state": doc["state"][:-1]}, "'state' must be 85 finite numbers"),
    (lambda doc: {**doc, "names": doc["names"][::-1]}, "its state layout is not the pd+lm controller's"),
])
def test_a_file_that_cannot_serve_is_refused_in_one_line(saved, tmp_path, capsys, change, message):
    files, _ = saved
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(change(json.loads(files["python"].read_text()))))
    code = main(["run", "circles", "--out", str(tmp_path / "r"), *RUN, "--load-learned", str(bad)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_BAD_INPUT and len(err) == 1 and message in err[0] and str(bad) in err[0]


@pytest.mark.parametrize("version", [2, 3])
def test_a_learned_value_the_controller_fmu_refuses_is_one_line_naming_it_and_quoting_the_fmu(version):
    """The learned state is set into the live FMU by name, and the FMU checks
    each value like any input (here a non-finite value the file reader would
    have refused)."""
    from cosim.errors import FmuCallError
    from fmu_models.export.build import cached_fmu
    from fnn_controller.controller_fmu import controller_model
    from fnn_controller.step import state_ports
    from fnn_controller.variants import variant
    from quadrotor_paper.learned import LearnedControllerFmu

    names = [name for name, _, _ in state_ports(variant("pd+lm"))]
    state = np.zeros(len(names))
    state[3] = np.inf
    with LearnedControllerFmu("controller", cached_fmu(controller_model("pd+lm"), version), variant="pd+lm",
                              state=state) as fmu:
        with pytest.raises(FmuCallError) as info:
            fmu.start(0.0)
    assert "\n" not in str(info.value)
    assert info.value.log == f"[ERROR] {names[3]} = inf refused: not a finite number"
    assert info.value.variable == names[3] and f"setting {names[3]} = inf from the learned state" in str(info.value)
