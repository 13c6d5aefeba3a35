"""The interval type-2 TSK FNN (:mod:`fnn_controller.it2`) in parallel with
the PD, trained online by the IT2 SMC or LM laws: the part the variants
``pd+it2-smc`` and ``pd+it2-lm`` share (inputs clipped to the box of eq. 27).

The IT2 parameters (width spread d, q(0), the q gain) are the nested field
``PositionParams.it2``. The laws' modules (CasADi) are imported when a law is
first built: a variant is registered, and its metadata read, without them."""
from __future__ import annotations

from ..axis_state import C1, C2, F, IT2_Q as Q, N_RULES, SIGMA1, SIGMA2

IT2_RANDOM = N_RULES  # uniform numbers drawn per axis: one per f_ij(0)
IT2_PARAMETERS = ("init", "bounds", "phi", "it2")  # read by both IT2 variants, besides their gains


def it2_initial_axis(params, r):
    """Section 5.1's initial values, ``f_ij(0) = f_high r_ij``, ``q(0) = q0``."""
    from ..it2 import it2_initial_axis_expression

    return it2_initial_axis_expression(params.init, params.it2, r)


def it2_axis_state_bounds(params):
    """The projection box of the IT2 axis state (eqs. 27-29, q in [0, 1])."""
    from ..it2 import it2_state_box

    return it2_state_box(params.bounds)


def it2_axis_law(rule: str, gamma_field: str):
    """The axis law of the IT2 FNN trained by ``rule`` (``"smc"`` or ``"lm"``),
    its gain gamma read from the ``PositionParams`` field ``gamma_field``."""

    def axis_law(e, e_dot, tau_c, axis_state, axis, params):
        from ..it2 import it2_learning_step, it2_normalized_firing_strengths, type_reduction
        from ..learning import AxisGains, clip_inputs

        it2 = params.it2
        x1, x2 = clip_inputs(e, e_dot, params.bounds)
        w_lower, w_upper = it2_normalized_firing_strengths(x1, x2, axis_state[C1], axis_state[C2],
                                                           axis_state[SIGMA1], axis_state[SIGMA2], it2.spread)
        tau_n, _, _ = type_reduction(axis_state[F], w_lower, w_upper, axis_state[Q])
        state_next = it2_learning_step(AxisGains.of_axis(rule, params, axis, gamma_field), it2.gamma_q, axis_state,
                                       x1, x2, tau_c, w_lower, w_upper)
        return tau_n, state_next

    return axis_law
