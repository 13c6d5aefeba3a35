"""PD + interval type-2 FNN trained by the LM-based laws (eqs. IT-6, IT-7,
IT-9 ... IT-11 of docs/controller.md: eqs. 57-62 with the IT2 regressor
W_bar_q, alpha held, and a learned q)."""
from __future__ import annotations

from ..axis_state import IT2_AXIS_STATE_PORTS, IT2_AXIS_STATE_SIZE
from .it2 import IT2_PARAMETERS, IT2_RANDOM, it2_axis_law, it2_axis_state_bounds, it2_initial_axis
from .registry import Variant, register_variant

PD_IT2_LM = register_variant(Variant(
    name="pd+it2-lm", label="PD+IT2-LM-FNN",
    description="PD + interval type-2 FNN (uncertain-width Gaussians, q-factor type reduction) trained by "
                "LM laws (eqs. 57-62 with the IT2 regressor), alpha held, learned q",
    axis_law=it2_axis_law("lm", "gamma_lm"),
    initial_axis=it2_initial_axis, n_random=IT2_RANDOM,
    axis_state_size=IT2_AXIS_STATE_SIZE, axis_state_bounds=it2_axis_state_bounds,
    axis_state_ports=IT2_AXIS_STATE_PORTS, parameters=("gamma_lm", "alpha_bar", *IT2_PARAMETERS),
    training="lm", fnn="it2",
))
