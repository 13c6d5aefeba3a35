"""PD + type-1 FNN trained by the Levenberg-Marquardt laws of Theorem 3 (eqs. 57-62)."""
from __future__ import annotations

from ..axis_state import AXIS_STATE_PORTS, AXIS_STATE_SIZE
from .registry import Variant, register_variant
from .type1 import TYPE1_RANDOM, type1_axis_law, type1_axis_state_bounds, type1_initial_axis

PD_LM = register_variant(Variant(
    name="pd+lm", label="PD+LM-FNN",
    description="PD + type-1 FNN trained by the LM laws (eqs. 57-62), alpha held",
    axis_law=type1_axis_law("lm", "gamma_lm"),
    initial_axis=type1_initial_axis, n_random=TYPE1_RANDOM,
    axis_state_size=AXIS_STATE_SIZE, axis_state_bounds=type1_axis_state_bounds,
    axis_state_ports=AXIS_STATE_PORTS, parameters=("gamma_lm", "alpha_bar", "init", "bounds", "phi"),
    training="lm", fnn="type1",
))
