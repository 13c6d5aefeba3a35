"""The shipped missions fly bit for bit alike in every form: with the
reference trajectory and the controller as Python components (the
trajectory evaluated on the master's grid t0 + n h, the controller's CasADi
step in process), as the shipped scenario builds them (their FMUs, in the
master's compiled loop), and as the all-FMU scenario of SSP archives
(:func:`quadrotor_paper.portable.all_fmu`). It holds because an FMU's time
comes from a step counter (``docs/fmi-export.md``): before, the reference
FMUs' outputs were one ulp off at about a third of the points."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from cosim.fmi.fmu import FmuComponent
from cosim.scenario.definition import load_scenario, parse_scenario
from cosim.scenario.assembly import build_master
from fnn_controller.variants import variant_names
from quadrotor_paper.portable import all_fmu
from quadrotor_paper.trajectories import ReferenceComponent, make_trajectory


# the module's masters share one extraction of each FMU (tests/conftest.py: one_extraction)
pytestmark = pytest.mark.usefixtures("one_extraction")


def python_reference(name: str, trajectory: str, **parameters) -> ReferenceComponent:
    """A ``[trajectory]`` of that kind as the Python component it used to be (a scenario factory)."""
    return ReferenceComponent(make_trajectory(trajectory, **parameters), name)


def _with_python_components(scenario):
    raw = copy.deepcopy(scenario.raw)
    trajectory = raw.pop("trajectory")
    raw["components"] = {"reference": {"factory": f"{__name__}:python_reference",
                                       "trajectory": trajectory.pop("kind"), **trajectory}}
    raw["controller"]["form"] = "python"
    return parse_scenario(raw, source=scenario.source, name=scenario.name)


def _fly(scenario):
    with build_master(scenario) as master:
        kinds = {type(c).__name__ for c in master.components.values()}
        return master.run(scenario.duration, seed=scenario.seed, t0=scenario.start_time), kinds


@pytest.mark.parametrize("variant", variant_names())
@pytest.mark.parametrize("mission", ["circles", "figure8"])
def test_every_form_of_a_shipped_mission_flies_bit_for_bit_alike(mission, variant):
    # its first 10 s: the forms differed at about a third of the points before (a time one ulp off), which
    # a tenth of the steps shows as well; the Python form's loop is what this test spends its time on
    shipped = load_scenario(mission, {"controller.variant": variant, "simulation.duration": 10.0})
    python, python_kinds = _fly(_with_python_components(shipped))
    assert {"ReferenceComponent", "ControllerComponent"} <= python_kinds
    for form in (shipped, all_fmu(shipped)):
        run, kinds = _fly(form)
        assert kinds <= {"FmuComponent", "LearnedControllerFmu"}  # FMUs only: the compiled loop
        assert run.status == python.status == "ok" and run.columns == python.columns
        for i, name in enumerate(run.columns):
            np.testing.assert_array_equal(run.data[:, i], python.data[:, i], err_msg=name)


def test_the_shipped_missions_build_their_reference_and_controller_as_fmus():
    with build_master(load_scenario("circles")) as master:
        assert isinstance(master.components["reference"], FmuComponent)
        assert isinstance(master.components["controller"], FmuComponent)
        assert master.python == [] and master.plan.compiled
