"""A toy controller variant, the way a user adds one: one module and its
registration. ``pd+toy`` adds a proportional "FNN" that learns nothing:
tau_n = -0.2 tau_c, i.e. the PD's gains raised by 20 %; its axis state is
one number, the last tau_c (to show a state of another size)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from fnn_controller.variants import Variant, register_variant

NAME = "pd+toy"


def axis_law(e, e_dot, tau_c, axis_state, axis, params):
    return -0.2 * tau_c, tau_c


TOY = Variant(
    name=NAME, label="PD+toy", description="PD with 20 % more gain, through tau_n (a test variant)",
    axis_law=axis_law, initial_axis=lambda params, r: ca.DM.zeros(1), n_random=0, axis_state_size=1,
    axis_state_bounds=lambda params: (np.full(1, -np.inf), np.full(1, np.inf)),
    axis_state_ports=(("last_tau_c", "m/s"),), learns=False,
)


def register() -> None:
    register_variant(TOY)
