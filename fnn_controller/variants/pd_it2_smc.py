"""PD + interval type-2 FNN trained by the SMC-based laws (eqs. IT-6 ... IT-9 of
docs/controller.md: eqs. 33-38 with the IT2 regressor W_bar_q, and a learned q)."""
from __future__ import annotations

from ..axis_state import IT2_AXIS_STATE_PORTS, IT2_AXIS_STATE_SIZE
from .it2 import IT2_PARAMETERS, IT2_RANDOM, it2_axis_law, it2_axis_state_bounds, it2_initial_axis
from .registry import Variant, register_variant

PD_IT2_SMC = register_variant(Variant(
    name="pd+it2-smc", label="PD+IT2-SMC-FNN",
    description="PD + interval type-2 FNN (uncertain-width Gaussians, q-factor type reduction) trained by "
                "SMC laws (eqs. 33-38 with the IT2 regressor), adaptive alpha, learned q",
    axis_law=it2_axis_law("smc", "gamma_smc"),
    initial_axis=it2_initial_axis, n_random=IT2_RANDOM,
    axis_state_size=IT2_AXIS_STATE_SIZE, axis_state_bounds=it2_axis_state_bounds,
    axis_state_ports=IT2_AXIS_STATE_PORTS, parameters=("gamma_smc", "nu", *IT2_PARAMETERS),
    training="smc", fnn="it2",
))
