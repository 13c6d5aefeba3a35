"""PD alone (eq. 19): no FNN, ``tau_n = 0``.

The axis state is the type-1 FNN's, carried through unchanged, so that every
variant draws the same f_ij(0) from a seed and shares one state layout.
"""
from __future__ import annotations

from ..axis_state import AXIS_STATE_PORTS, AXIS_STATE_SIZE
from .registry import Variant, register_variant
from .type1 import TYPE1_RANDOM, type1_axis_state_bounds, type1_initial_axis


def axis_law(e, e_dot, tau_c, axis_state, axis, params):
    return 0.0 * tau_c, axis_state


PD = register_variant(Variant(
    name="pd", label="PD", description="PD position controller alone (eq. 19)",
    axis_law=axis_law, initial_axis=type1_initial_axis, n_random=TYPE1_RANDOM,
    axis_state_size=AXIS_STATE_SIZE, axis_state_bounds=type1_axis_state_bounds,
    axis_state_ports=AXIS_STATE_PORTS, learns=False,
))
