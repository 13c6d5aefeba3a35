"""The controller cut at v* (eq. 26): the outer and the inner function,
connected directly, are the whole controller step, bit for bit, for every
registered variant; each reads only its own parameters."""
from __future__ import annotations

import numpy as np
import pytest

import fnn_controller as fc
from fnn_controller.step import OUTPUTS
from fnn_controller.parametric import parameter_table, parameter_vector, parametric_step_function
from fnn_controller.parametric import (inner_parameter_table, inner_step_function, outer_parameter_table,
                                      outer_step_function)
from fnn_controller.split import INNER_OUTPUTS, OUTER_OUTPUTS

NAMES = [name for name, _, _ in OUTPUTS]


@pytest.mark.parametrize("variant", fc.variant_names())
@pytest.mark.parametrize("options", [{}, {"feedforward": 1.0, "accel_feedforward": 0.7}])
def test_outer_then_inner_is_the_whole_step_bit_for_bit(variant, options):
    """Both feed-forward options on as well: a_ref travels from the outer
    function's output to the inner function's input."""
    whole = parametric_step_function(variant)
    outer, inner = outer_step_function(variant), inner_step_function()
    p_whole = np.array([options.get(p.name, p.default) for p in parameter_table(variant)])
    p_outer = np.array([options.get(p.name, p.default) for p in outer_parameter_table(variant)])
    p_inner = np.array([options.get(p.name, p.default) for p in inner_parameter_table()])
    rng = np.random.default_rng(7)
    state = fc.initial_state(fc.variant(variant), 3)
    n_fnn = len(state) - 10
    for _ in range(40):  # a few steps, the state fed forward, so the learning laws act
        p_ref, p_ref_dot, p_ref_ddot = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        x = np.r_[rng.normal(size=6), rng.normal(size=3) * 0.3, rng.normal(size=3)]
        psi_ref = rng.uniform(-1, 1)
        res = whole(p_ref=p_ref, p_ref_dot=p_ref_dot, x=x, psi_ref=psi_ref, state=state, p=p_whole,
                    p_ref_ddot=p_ref_ddot)
        y, state_next = np.array(res["y"]).ravel(), np.array(res["state_next"]).ravel()
        y_outer, outer_next, _ = outer(p_ref, p_ref_dot, x[0:6], state[:n_fnn], p_outer, p_ref_ddot)
        y_outer = np.array(y_outer).ravel()
        a_ref = y_outer[[i for i, (n, _, _) in enumerate(OUTER_OUTPUTS) if n.startswith("a_ref_")]]
        assert np.array_equal(a_ref, options.get("accel_feedforward", 0.0) * p_ref_ddot)
        y_inner, inner_next, _ = inner(y_outer[0:3], x[3:12], psi_ref, state[n_fnn:], p_inner, a_ref)
        split = dict(zip([n for n, _, _ in OUTER_OUTPUTS], y_outer))
        split.update(zip([n for n, _, _ in INNER_OUTPUTS], np.array(y_inner).ravel()))
        assert np.array_equal(np.array([split[n] for n in NAMES]), y)
        assert np.array_equal(np.r_[np.array(outer_next).ravel(), np.array(inner_next).ravel()], state_next)
        state = state_next


def test_the_two_parameter_tables_partition_the_whole_one():
    """Every parameter of the whole step is read by exactly one side, except
    dt, the sample period both keep."""
    for variant in fc.variant_names():
        whole = {p.name for p in parameter_table(variant)}
        outer = {p.name for p in outer_parameter_table(variant)}
        inner = {p.name for p in inner_parameter_table()}
        assert outer | inner == whole
        assert outer & inner == {"dt"}
        assert "kp" in outer and "k_v" in inner and "vehicle.m" in inner
