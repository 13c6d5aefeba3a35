"""Interval type-2 zero-order TSK FNN and its online learning laws (not in the
paper: the "beyond the paper" IT2 variants ``pd+it2-smc`` and ``pd+it2-lm``).

The network has the type-1 FNN's structure (:mod:`fnn_controller.fnn`): two
inputs x1 = e, x2 = de/dt (clipped to the box of eq. 27), I = J = 3 membership
functions per input, product T-norm, 9 rules with zero-order consequents f_ij,
rule k = j * I + i. Each membership function is an *interval type-2 Gaussian
with uncertain width* and a fixed (but adapted, eqs. 33-34) centre:

.. math:: \\underline\\mu_i(x) = \\exp[-(x - c_i)^2 / \\sigma_i^2], \\qquad
          \\overline\\mu_i(x) = \\exp[-(x - c_i)^2 / ((1 + d)\\sigma_i)^2]

so the lower MF is exactly the type-1 MF of the same state and the upper one
is ``1 + d`` times wider (``d`` = :attr:`IT2Params.spread`; ``d = 0`` gives the
type-1 FNN). The output is the closed-form type reduction of Biglarbegian,
Melek and Mendel (the q-factor form):

.. math:: \\tau_n = q \\sum f \\underline{\\overline W} + (1 - q) \\sum f \\overline{\\overline W}
          = \\sum f_{ij} \\overline W^q_{ij},\\quad \\overline W^q = q \\underline{\\overline W}
          + (1 - q) \\overline{\\overline W}

with ``W_bar_lower``, ``W_bar_upper`` the lower and upper firing strengths
normalized as in eq. 25. ``q`` is learned (projected onto [0, 1]), as in
Kayacan, Cigdem and Kaynak (IEEE TIE 2012). Derivation and Lyapunov argument
(eqs. IT-1 ... IT-12): ``docs/controller.md``, section "Interval type-2 FNN".

Axis state (26 numbers): the type-1 layout with ``q`` inserted after alpha.

=========  =======  ====================================================
slice      size     content
=========  =======  ====================================================
C1         3        c1, centres of the MFs of x1 (m)
C2         3        c2, centres of the MFs of x2 (m/s)
SIGMA1     3        sigma1, widths of the lower MFs of x1 (m); upper: (1 + d) sigma1
SIGMA2     3        sigma2, widths of the lower MFs of x2 (m/s); upper: (1 + d) sigma2
F          9        f_ij, rule consequents (m/s), rule k = j * I + i
ALPHA      1        alpha, adaptive learning rate (eq. 38; held under LM)
Q          1        q, weight of the lower firing strengths in the type reduction (1)
X1_PREV    1        x1 of the previous step (m), for eq. 33
X2_PREV    1        x2 of the previous step (m/s), for eq. 34
PRIMED     1        1 once a step has been taken since reset, else 0
=========  =======  ====================================================
"""
from __future__ import annotations

from fmu_models.lazy_casadi import ca
import numpy as np

from .axis_state import (ALPHA, AXIS_STATE_SIZE, C1, C2, F, IT2_AXIS_STATE_PORTS, IT2_AXIS_STATE_SIZE, N_MF,
                         N_RULES, SIGMA1, SIGMA2)
from .axis_state import IT2_PRIMED as PRIMED, IT2_Q as Q, IT2_X1_PREV as X1_PREV, IT2_X2_PREV as X2_PREV
from .fnn import FnnInit, normalized_firing_strength
from .learning import AxisGains, LearningBounds, parameters_step, project, switching
from .position_parameters import IT2Params

__all__ = [
    "C1", "C2", "SIGMA1", "SIGMA2", "F", "ALPHA", "Q", "X1_PREV", "X2_PREV", "PRIMED",
    "IT2_AXIS_STATE_SIZE", "IT2_AXIS_STATE_PORTS", "IT2Params", "IT2_DEFAULTS",
    "it2_normalized_firing_strengths", "type_reduction",
    "it2_regressor", "q_rate", "it2_learning_step", "it2_initial_axis_expression", "it2_state_box",
]



IT2_DEFAULTS = IT2Params()


def it2_normalized_firing_strengths(x1, x2, c1, c2, sigma1, sigma2, spread):
    """``(W_bar_lower, W_bar_upper)``: each bound normalized as eq. 25 (the
    shifted soft-max of :func:`fnn_controller.fnn.normalized_firing_strength`,
    finite and summing to 1 even when every strength underflows)."""
    return (normalized_firing_strength(x1, x2, c1, c2, sigma1, sigma2),
            normalized_firing_strength(x1, x2, c1, c2, (1 + spread) * sigma1, (1 + spread) * sigma2))


def it2_regressor(w_bar_lower, w_bar_upper, q):
    """``W_bar_q = q W_bar_lower + (1 - q) W_bar_upper`` (eq. IT-5): the
    gradient of the output with respect to f; sums to 1."""
    return q * w_bar_lower + (1 - q) * w_bar_upper


def type_reduction(f, w_bar_lower, w_bar_upper, q):
    """The q-factor type reduction of Biglarbegian, Melek and Mendel (eq. IT-4).

    Returns ``(tau_n, y_lower, y_upper)`` with ``y_lower = sum f W_bar_lower``,
    ``y_upper = sum f W_bar_upper`` and ``tau_n = q y_lower + (1 - q) y_upper``
    (``= sum f W_bar_q``), between the two for q in [0, 1].
    """
    y_lower, y_upper = ca.dot(f, w_bar_lower), ca.dot(f, w_bar_upper)
    return q * y_lower + (1 - q) * y_upper, y_lower, y_upper


def q_rate(y_lower, y_upper, tau_c, gamma_q, phi=0.0):
    """The q law (eq. IT-9): ``q_dot = -gamma_q (y_lower - y_upper) s(tau_c)``,
    so that ``tau_c (d tau_n / d q) q_dot = -gamma_q |tau_c| (y_lower - y_upper)^2``
    (with ``phi = 0``) is never positive."""
    return -gamma_q * (y_lower - y_upper) * switching(tau_c, phi)


def it2_learning_step(gains: AxisGains, gamma_q, state, x1, x2, tau_c, w_bar_lower, w_bar_upper):
    """One forward-Euler step of the IT2 SMC or LM laws for one axis.

    Parameters
    ----------
    gains : AxisGains (:mod:`fnn_controller.learning`)
        ``training = "smc"``: eqs. IT-6 ... IT-9 (centres and widths as eqs.
        33-36, f by eq. 37 with the regressor ``W_bar_q``, alpha by eq. 38);
        ``"lm"``: eqs. IT-10, IT-11 (centres and widths as eqs. 57-60, f by
        eqs. 61-62 with ``W_bar_q``, alpha held); the step, gains, bounds (q
        is projected onto [0, 1]) and boundary layer.
    gamma_q : gain of the q law (1/m: q_dot in 1/s, y_lower - y_upper in m/s)
    state : vector of length IT2_AXIS_STATE_SIZE
        Axis state at step k.
    x1, x2 : scalar
        FNN inputs at step k, already clipped.
    tau_c : scalar
        PD output at step k (m/s), the learning error.
    w_bar_lower, w_bar_upper : vectors of length I*J
        Normalized lower and upper firing strengths at step k.

    Returns
    -------
    vector of length IT2_AXIS_STATE_SIZE, the axis state at step k + 1.
    """
    f, q = state[F], state[Q]
    # IT-6 ... IT-8, IT-10, IT-11: eqs. 33-38 / 57-62 with the regressor W_bar_q, on the lower
    # (nominal) widths (the upper width (1 + d) sigma follows)
    parameters = parameters_step(gains, state, (state[X1_PREV], state[X2_PREV]), state[PRIMED], x1, x2, tau_c,
                                 it2_regressor(w_bar_lower, w_bar_upper, q))
    y_lower, y_upper = ca.dot(f, w_bar_lower), ca.dot(f, w_bar_upper)
    q_next = project(q + gains.dt * q_rate(y_lower, y_upper, tau_c, gamma_q, gains.phi), 0.0, 1.0)  # IT-9

    next_state = ca.vertcat(*parameters, q_next, x1, x2, ca.DM(1.0))
    assert next_state.shape[0] == IT2_AXIS_STATE_SIZE
    return next_state


def it2_initial_axis_expression(init: FnnInit, it2: IT2Params, r):
    """Axis state at t = 0 from N_RULES uniform numbers ``r`` in [0, 1): the
    type-1 values of section 5.1 (``sigma`` the lower width), ``f_ij(0) =
    f_high r_ij``, ``q(0) = q0``; previous inputs 0, not primed."""
    ones = ca.DM.ones(N_MF)
    return ca.vertcat(*init.c1, *init.c2, init.sigma1 * ones, init.sigma2 * ones, init.f_high * r,
                      init.alpha, it2.q0, 0.0, 0.0, 0.0)


def it2_state_box(bounds: LearningBounds):
    """``(low, high)``: the projection box of eqs. 27-29 per element of the IT2
    axis state, q in [0, 1]."""
    b = bounds
    low, high = np.full(IT2_AXIS_STATE_SIZE, -np.inf), np.full(IT2_AXIS_STATE_SIZE, np.inf)
    for sl, lo, hi in ((C1, -b.c1_max, b.c1_max), (C2, -b.c2_max, b.c2_max),
                       (SIGMA1, b.sigma1_min, b.sigma1_max), (SIGMA2, b.sigma2_min, b.sigma2_max),
                       (F, -b.f_max, b.f_max), (ALPHA, 0.0, b.alpha_max), (Q, 0.0, 1.0),
                       (X1_PREV, -b.x1_max, b.x1_max), (X2_PREV, -b.x2_max, b.x2_max), (PRIMED, 0.0, 1.0)):
        low[sl], high[sl] = lo, hi
    return low, high


assert N_RULES == 9
