"""The controller cut at v* as two FMUs: the outer loop of each variant
(``PositionController<V>``, ground) and the inner loop (``VelocityController``,
on board). They validate, and over random steps each gives exactly what its
CasADi function gives (the function the whole controller is built from)."""
from __future__ import annotations

import numpy as np
import pytest
from fmpy import read_model_description
from tests.fmu_validation import validate_fmu

import fnn_controller as fc
from fmu_models.export.build import cached_fmu
from fmu_models.export.model import FmuModel, Sampled
from fnn_controller.controller_fmu import ACCELERATION_INPUTS, REFERENCE_INPUTS
from fnn_controller.parametric import (inner_parameter_table, inner_step_function, outer_initial_function,
                                      outer_parameter_table, outer_step_function)
from fnn_controller.split import (A_REF_PORTS, INNER_MEASURED, INNER_OUTPUTS, OUTER_MEASURED, OUTER_OUTPUTS,
                                  inner_model, outer_model)

from fmi2_harness import Fmi2Instance


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("which", ["pd+lm", "pd+it2-smc", "inner"])
def test_the_split_fmus_validate(which, version):
    model = inner_model() if which == "inner" else outer_model(which)
    assert validate_fmu(str(cached_fmu(model, version))) == []


def test_the_inner_fmu_draws_nothing_and_has_no_seed():
    md = read_model_description(str(cached_fmu(inner_model(), 2)))
    names = {v.name for v in md.modelVariables}
    assert "seed" not in names
    assert {"v_ref_x", "psi_ref", "vehicle.m", "k_v", "dt"} <= names
    assert not {"x", "y", "z", "kp"} & names  # the position is the ground's business


def test_a_model_that_draws_needs_a_seed():
    with pytest.raises(ValueError, match="needs a seed"):
        FmuModel("Bad", "draws without a seed", variables=outer_model("pd+lm").variables,
                 sampled=Sampled(update=None, initial=None, n_random=3, seed=None, sample_period="dt"))


@pytest.mark.parametrize("variant", ["pd+smc", "pd+lm"])
def test_outer_and_inner_fmus_step_as_their_functions_bit_for_bit(variant):
    options = {"feedforward": 1.0, "accel_feedforward": 0.5}  # every input and output in use
    outer = Fmi2Instance(str(cached_fmu(outer_model(variant), 2)), parameters={"seed": 5, **options})
    psi_ref = 0.4  # rad: the commanded yaw, a parameter held for the run
    inner = Fmi2Instance(str(cached_fmu(inner_model(), 2)), parameters={"psi_ref": psi_ref})
    f_outer, f_inner = outer_step_function(variant), inner_step_function()
    p_outer = np.array([options.get(p.name, p.default) for p in outer_parameter_table(variant)])
    p_inner = np.array([p.default for p in inner_parameter_table()])
    v = fc.variant(variant)
    state = np.array(outer_initial_function(variant)(p_outer, np.random.default_rng(5).random(3 * v.n_random))).ravel()
    vel_state = fc.initial_velocity_state()
    references = [n for n, _, _ in REFERENCE_INPUTS]
    rng = np.random.default_rng(11)
    try:
        for _ in range(100):
            ref, x = rng.normal(size=9), np.r_[rng.normal(size=6), rng.normal(size=3) * 0.3, rng.normal(size=3)]
            rng.uniform(-1, 1)  # the draw psi_ref had when it was an input: the other values stay as they were
            outer.set(**dict(zip(references, ref)), **dict(zip(OUTER_MEASURED, x[0:6])),
                      **dict(zip((n for n, _, _ in ACCELERATION_INPUTS), ref[6:9])))
            got_outer = outer.get(*(n for n, _, _ in OUTER_OUTPUTS))
            y, state, _ = f_outer(ref[0:3], ref[3:6], x[0:6], state, p_outer, ref[6:9])
            assert np.array_equal(got_outer, np.array(y).ravel())
            a_ref = got_outer[-3:]
            inner.set(**dict(zip(("v_ref_x", "v_ref_y", "v_ref_z"), got_outer[0:3])),
                      **dict(zip(INNER_MEASURED, x[3:12])), **dict(zip((n for n, _, _ in A_REF_PORTS), a_ref)))
            got_inner = inner.get(*(n for n, _, _ in INNER_OUTPUTS))
            y, vel_state, _ = f_inner(got_outer[0:3], x[3:12], psi_ref, vel_state, p_inner, a_ref)
            assert np.array_equal(got_inner, np.array(y).ravel())
            state, vel_state = np.array(state).ravel(), np.array(vel_state).ravel()
            outer.step()
            inner.step()
    finally:
        outer.close()
        inner.close()
