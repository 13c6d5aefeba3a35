"""The type-1 TSK FNN of §4.1 in parallel with the PD, trained online by a
learning rule of :mod:`fnn_controller.learning`: the part the SMC and LM
variants share (eqs. 24-25, inputs clipped to the box of eq. 27).

The laws' modules (CasADi) are imported when a law is first built: a
variant is registered, and its metadata read, without them."""
from __future__ import annotations

from ..axis_state import ALPHA, AXIS_STATE_SIZE, C1, C2, F, N_RULES, PRIMED, SIGMA1, SIGMA2, X1_PREV, X2_PREV


TYPE1_RANDOM = N_RULES  # uniform numbers drawn per axis: one per f_ij(0)


def type1_initial_axis(params, r):
    """§5.1's initial values, ``f_ij(0) = f_high r_ij``."""
    from ..fnn import initial_axis_expression

    return initial_axis_expression(params.init, r)


def type1_axis_state_bounds(params):
    """The projection box of eqs. (27)-(29) and the floors (:class:`LearningBounds`),
    per element of the type-1 axis state; the previous inputs are clipped inputs."""
    import numpy as np  # here: registering the variants (fnn-cosim's start) loads no numpy

    b = params.bounds
    low, high = np.full(AXIS_STATE_SIZE, -np.inf), np.full(AXIS_STATE_SIZE, np.inf)
    for sl, lo, hi in ((C1, -b.c1_max, b.c1_max), (C2, -b.c2_max, b.c2_max),
                       (SIGMA1, b.sigma1_min, b.sigma1_max), (SIGMA2, b.sigma2_min, b.sigma2_max),
                       (F, -b.f_max, b.f_max), (ALPHA, 0.0, b.alpha_max), (X1_PREV, -b.x1_max, b.x1_max),
                       (X2_PREV, -b.x2_max, b.x2_max), (PRIMED, 0.0, 1.0)):
        low[sl], high[sl] = lo, hi
    return low, high


def type1_axis_law(rule: str, gamma_field: str):
    """The axis law of the type-1 FNN trained by ``rule`` (``"smc"`` or
    ``"lm"``), its gain gamma read from the ``PositionParams`` field ``gamma_field``."""

    def axis_law(e, e_dot, tau_c, axis_state, axis, params):
        from ..fnn import fnn_output, normalized_firing_strength
        from ..learning import AxisGains, clip_inputs, learning_step

        x1, x2 = clip_inputs(e, e_dot, params.bounds)
        w_bar = normalized_firing_strength(x1, x2, axis_state[C1], axis_state[C2],
                                           axis_state[SIGMA1], axis_state[SIGMA2])
        tau_n = fnn_output(axis_state[F], w_bar)
        state_next = learning_step(AxisGains.of_axis(rule, params, axis, gamma_field), axis_state, x1, x2, tau_c,
                                   w_bar)
        return tau_n, state_next

    return axis_law
