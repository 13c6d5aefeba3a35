"""PD + type-1 FNN trained by the sliding-mode laws of Theorem 1 (eqs. 33-38)."""
from __future__ import annotations

from ..axis_state import AXIS_STATE_PORTS, AXIS_STATE_SIZE
from .registry import Variant, register_variant
from .type1 import TYPE1_RANDOM, type1_axis_law, type1_axis_state_bounds, type1_initial_axis

PD_SMC = register_variant(Variant(
    name="pd+smc", label="PD+SMC-FNN",
    description="PD + type-1 FNN trained by the SMC laws (eqs. 33-38), adaptive learning rate alpha",
    axis_law=type1_axis_law("smc", "gamma_smc"),
    initial_axis=type1_initial_axis, n_random=TYPE1_RANDOM,
    axis_state_size=AXIS_STATE_SIZE, axis_state_bounds=type1_axis_state_bounds,
    axis_state_ports=AXIS_STATE_PORTS, parameters=("gamma_smc", "nu", "init", "bounds", "phi"),
    training="smc", fnn="type1",
))
