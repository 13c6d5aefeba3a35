"""Zero-order TSK fuzzy neural network of the paper's section 4.1.

Two inputs, x1 = e and x2 = de/dt, I = J = 3 Gaussian membership functions
per input (eqs. 21-22), product T-norm (eqs. 20, 23), normalized firing
strengths (eq. 25) and the weighted-average output (eq. 24). The rule index
follows the paper, k = (j - 1) J + i, so with 0-based indices the rule of
membership functions (i, j) is ``k = j * I + i`` (i runs fastest).

The builders are written with CasADi operations so that the same code is
evaluated numerically, code-generated to C and differentiated; they accept
CasADi ``SX``/``MX``/``DM`` values (and numpy arrays, which CasADi converts).

The learnable parameters of one axis are kept in a flat vector, the *axis
state*, whose layout is given by the slice constants of this module:

=========  =======  ====================================================
slice      size     content
=========  =======  ====================================================
C1         3        c1, centres of the MFs of x1 (m)
C2         3        c2, centres of the MFs of x2 (m/s)
SIGMA1     3        sigma1, widths of the MFs of x1 (m)
SIGMA2     3        sigma2, widths of the MFs of x2 (m/s)
F          9        f_ij, rule consequents (m/s), rule k = j * I + i
ALPHA      1        alpha, adaptive learning rate (eq. 38)
X1_PREV    1        x1 of the previous step (m), for eq. 33
X2_PREV    1        x2 of the previous step (m/s), for eq. 34
PRIMED     1        1 once a step has been taken since reset, else 0
=========  =======  ====================================================
"""
from __future__ import annotations

from fmu_models.lazy_casadi import ca
import numpy as np

# the layout of the axis state and the initial values: declared without CasADi (what a run reads)
from .axis_state import (ALPHA, AXIS_STATE_PORTS, AXIS_STATE_SIZE, C1, C2, F, N_MF, N_RULES, PRIMED, SIGMA1, SIGMA2,
                         X1_PREV, X2_PREV)
from .position_parameters import FnnInit

__all__ = [
    "N_MF", "N_RULES", "AXIS_STATE_SIZE", "AXIS_STATE_PORTS",
    "C1", "C2", "SIGMA1", "SIGMA2", "F", "ALPHA", "X1_PREV", "X2_PREV", "PRIMED",
    "FnnInit", "membership", "firing_exponent", "firing_strength",
    "normalized_firing_strength", "fnn_output", "initial_axis_expression",
]



def membership(x, c, sigma):
    """Gaussian membership grades of one input, eqs. (21)-(22).

    .. math:: \\mu_i(x) = \\exp\\left[-(x - c_i)^2 / \\sigma_i^2\\right]

    Parameters
    ----------
    x : scalar
        Input value (m for x1, m/s for x2).
    c, sigma : vector of length I
        Centres and widths, same unit as ``x``; sigma > 0.

    Returns
    -------
    vector of length I
        Membership grades in (0, 1].
    """
    return ca.exp(-((x - c) / sigma) ** 2)


def firing_exponent(x1, x2, c1, c2, sigma1, sigma2):
    """Exponents of the rule firing strengths, the bracket of eq. (23).

    Returns the vector ``E`` with ``E[j * I + i] = -A1_i^2 - A2_j^2`` where
    ``A1_i = (x1 - c1_i) / sigma1_i`` and ``A2_j = (x2 - c2_j) / sigma2_j``
    (eq. 41), so that ``W = exp(E)``.
    """
    a1_sq = ((x1 - c1) / sigma1) ** 2
    a2_sq = ((x2 - c2) / sigma2) ** 2
    return ca.vertcat(*[-a1_sq[i] - a2_sq[j] for j in range(N_MF) for i in range(N_MF)])


def firing_strength(x1, x2, c1, c2, sigma1, sigma2):
    """Firing strengths W_ij of the I*J rules, product T-norm, eqs. (20), (23).

    .. math:: W_{ij} = \\mu_{1i}(x_1)\\,\\mu_{2j}(x_2)

    Returns a vector of length I*J ordered by rule index k = j * I + i.
    """
    return ca.exp(firing_exponent(x1, x2, c1, c2, sigma1, sigma2))


def normalized_firing_strength(x1, x2, c1, c2, sigma1, sigma2):
    """Normalized firing strengths, eq. (25).

    .. math:: \\overline{W}_{ij} = W_{ij} / \\sum_{i,j} W_{ij}

    Computed as a soft-max of the exponents of eq. (23), shifted by their
    maximum: mathematically identical to eq. (25), but the denominator is
    at least 1 after the shift, so the result is finite and sums to 1 even
    when every W_ij underflows to zero (narrow MFs far from the input).
    """
    exponent = firing_exponent(x1, x2, c1, c2, sigma1, sigma2)
    shifted = ca.exp(exponent - ca.mmax(exponent))
    return shifted / ca.sum1(shifted)


def fnn_output(f, w_bar):
    """FNN output tau_n, the weighted average of eq. (24).

    .. math:: \\tau_n = \\sum_{i,j} f_{ij} \\overline{W}_{ij}

    Parameters
    ----------
    f : vector of length I*J
        Rule consequents (m/s), ordered like ``w_bar``.
    w_bar : vector of length I*J
        Normalized firing strengths (eq. 25).
    """
    return ca.dot(f, w_bar)


def initial_axis_expression(init: FnnInit, r):
    """Axis state at t = 0 (section 5.1) from N_RULES uniform numbers ``r`` in
    [0, 1): centres, widths, alpha, ``f_ij(0) = f_high r_ij`` (so f_ij(0) ~
    U[0, f_high]); previous inputs 0, not primed. CasADi (symbolic ``init``
    and ``r`` inside the controller FMU) or numbers alike."""
    ones = ca.DM.ones(N_MF)
    return ca.vertcat(*init.c1, *init.c2, init.sigma1 * ones, init.sigma2 * ones, init.f_high * r,
                      init.alpha, 0.0, 0.0, 0.0)
