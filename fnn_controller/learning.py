"""Online learning laws of the FNN: SMC (Theorem 1) and LM (Theorem 3).

The continuous-time laws of the paper (eqs. 33-38 and 57-62) are integrated
by forward Euler over the controller step dt (section 5.1: dt = 0.01 s), with
the safeguards of :class:`LearningBounds` (each one justified in
``docs/controller.md``):

* eqs. 33-34 / 57-58, ``c_dot = x_dot``, become ``c += x_k - x_{k-1}``: the
  previous inputs are part of the axis state; the very first step after a
  reset has no previous input and leaves c unchanged;
* the denominators ``(x - c)^2`` of eqs. 35-36 / 59-60 are floored at
  ``(a_min * sigma)^2``, i.e. ``|A| = |x - c| / sigma`` is taken as at least
  ``a_min`` (this removes the finite escape of sigma at A = 0);
* after each update every parameter is projected onto the box of eqs. 27-29
  (element-wise bounds, which imply the paper's norm bounds);
* the FNN inputs are clipped to ``|x1| <= x1_max``, ``|x2| <= x2_max``
  (assumption 27 enforced rather than assumed).

``sgn(0) = 0``: with a zero learning error nothing is learned.

Units. The paper uses one number alpha in two roles: in eq. (37)
``f_dot = ... alpha`` it is a rate of the output (m/s^2 here, tau being a
velocity), in eqs. (35)-(36) ``A A_dot = alpha sgn(tau_c)`` it acts as 1/s.
We keep the paper's single alpha and document it in m/s^2; then gamma of
eq. (38) is in 1/s and nu in s, gamma of eq. (61) in m/s^2, alpha_bar of
eq. (62) is dimensionless (compared with W_bar^T W_bar). ``W^T W`` in
eq. 37 needs no floor: the normalized strengths sum to 1, so
``W^T W >= 1 / (I J)`` (Cauchy-Schwarz).

Under LM, alpha (which still scales the sigma laws 59-60) is held at its
initial value: eq. 38 needs nu, which the paper gives for SMC only, and the
Lyapunov function of Theorem 3 (eq. 63) has no alpha term.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fmu_models.lazy_casadi import ca

from .axis_state import ALPHA, AXIS_STATE_SIZE, C1, C2, F, PRIMED, SIGMA1, SIGMA2, X1_PREV, X2_PREV
from .position_parameters import LearningBounds

__all__ = [
    "LearningBounds", "sgn", "switching", "sigma_rate", "smc_f_rate", "alpha_rate", "lm_delta",
    "lm_f_rate", "learning_step", "parameters_step", "project", "clip_inputs", "RULES", "AxisGains",
]

RULES = ("smc", "lm")


def sgn(x):
    """Signum with ``sgn(0) = 0`` (no learning when tau_c is exactly 0)."""
    return ca.sign(x)


def switching(tau_c, phi=0.0):
    """The switching term of every law: the paper's ``sgn(tau_c)`` or, with a
    boundary layer of width ``phi`` > 0 (m/s), ``sat(tau_c / phi)``, linear
    inside the layer and ``sgn`` outside it (not in the paper: an option).

    .. math:: s(\\tau_c) = \\begin{cases} \\mathrm{sgn}(\\tau_c) & \\phi = 0 \\\\
              \\max(-1, \\min(1, \\tau_c / \\phi)) & \\phi > 0 \\end{cases}

    ``phi`` may be a number (0 gives the paper's law exactly) or a symbol
    (the controller FMU's parameter).
    """
    if isinstance(phi, (int, float)) and phi == 0:
        return sgn(tau_c)
    saturated = ca.fmin(ca.fmax(tau_c / ca.fmax(phi, 1e-300), -1.0), 1.0)
    return saturated if isinstance(phi, (int, float)) else ca.if_else(phi > 0, saturated, sgn(tau_c))


def sigma_rate(x, c, sigma, alpha, tau_c, a_min, phi=0.0):
    """Width adaptation of eqs. (35)-(36) (SMC) and (59)-(60) (LM), floored.

    .. math:: \\dot\\sigma_i = -\\frac{\\sigma_i^3}{\\max[(x - c_i)^2,
              (a_{min}\\sigma_i)^2]}\\,\\alpha\\,\\mathrm{sgn}(\\tau_c)

    With ``a_min = 0`` this is the paper's law, under which
    ``d(A_i^2)/dt = 2 alpha sgn(tau_c)`` for every MF (the step to eq. 46);
    the floor makes ``A_i^2`` change at a relative rate of at most
    ``2 alpha / a_min^2`` where ``|A_i| < a_min`` (membership grade above
    ``exp(-a_min^2)``), so sigma cannot escape to infinity in finite time.

    Parameters
    ----------
    x : scalar
        FNN input (m or m/s).
    c, sigma : vectors of length I
        Centres and widths (unit of ``x``).
    alpha : scalar
        Learning rate (1/s).
    tau_c : scalar
        Learning error, the PD output (m/s).
    a_min : float
        Floor of ``|x - c| / sigma`` (1).
    """
    denominator = ca.fmax((x - c) ** 2, (a_min * sigma) ** 2)
    return -(sigma**3) / denominator * alpha * switching(tau_c, phi)


def smc_f_rate(w_bar, alpha, tau_c, phi=0.0):
    """Consequent adaptation of the SMC law, eq. (37).

    .. math:: \\dot f_{ij} = -\\frac{\\overline{W}_{ij}}{\\overline{W}^T
              \\overline{W}}\\,\\alpha\\,\\mathrm{sgn}(\\tau_c)

    so that ``sum_ij f_dot_ij W_bar_ij = -alpha sgn(tau_c)`` (eq. 48).
    """
    return -w_bar / ca.dot(w_bar, w_bar) * alpha * switching(tau_c, phi)


def alpha_rate(tau_c, alpha, gamma, nu):
    """Adaptive learning rate of the SMC law, eq. (38).

    .. math:: \\dot\\alpha = \\gamma |\\tau_c| - \\gamma \\nu \\alpha
    """
    return gamma * ca.fabs(tau_c) - gamma * nu * alpha


def lm_delta(w_bar, alpha_bar):
    """Levenberg-Marquardt damping of eq. (62): ``max(W_bar^T W_bar, alpha_bar)``."""
    return ca.fmax(ca.dot(w_bar, w_bar), alpha_bar)


def lm_f_rate(w_bar, tau_c, gamma, alpha_bar, phi=0.0):
    """Consequent adaptation of the LM law, eq. (61), by the rank-one identity.

    .. math:: \\dot f = -\\gamma (\\overline{W}\\,\\overline{W}^T + \\delta I)^{-1}
              \\overline{W}\\,\\mathrm{sgn}(\\tau_c)
              = -\\gamma \\frac{\\overline{W}}{\\delta + \\overline{W}^T
              \\overline{W}}\\,\\mathrm{sgn}(\\tau_c)

    with delta of eq. (62). The identity holds because ``W_bar`` is an
    eigenvector of ``W_bar W_bar^T + delta I`` with eigenvalue
    ``delta + W_bar^T W_bar``.
    """
    return -gamma * w_bar / (lm_delta(w_bar, alpha_bar) + ca.dot(w_bar, w_bar)) * switching(tau_c, phi)


def clip_inputs(x1, x2, bounds: LearningBounds):
    """FNN inputs clipped to the box of eq. (27)."""
    return project(x1, -bounds.x1_max, bounds.x1_max), project(x2, -bounds.x2_max, bounds.x2_max)


def project(value, low, high):
    """``value`` projected onto ``[low, high]`` (the projections of eqs. 28-29)."""
    return ca.fmin(ca.fmax(value, low), high)


@dataclass(frozen=True)
class AxisGains:
    """What the learning laws of one axis read besides its state and inputs:
    the ``training`` law (``"smc"``: eqs. 33-38; ``"lm"``: eqs. 57-62 with
    alpha held; :attr:`~fnn_controller.variants.Variant.training`), the step
    ``dt`` (s), the gains ``gamma`` and ``nu`` of eq. (38) (gamma is also the
    LM gain of eq. 61), ``alpha_bar`` of eq. (62), the floors and projection
    box ``bounds`` and the boundary layer ``phi`` (m/s, :func:`switching`; 0
    is the paper's ``sgn(tau_c)``). Numbers or CasADi symbols (the
    parametric step)."""

    training: str
    dt: Any
    gamma: Any
    nu: Any
    alpha_bar: Any
    bounds: LearningBounds = LearningBounds()
    phi: Any = 0.0

    def __post_init__(self):
        if self.training not in RULES:
            raise ValueError(f"unknown learning rule {self.training!r}; expected one of {RULES}")

    @classmethod
    def of_axis(cls, training: str, params, axis: int, gamma_field: str) -> "AxisGains":
        """Axis ``axis`` (0 = x) of the :class:`PositionParams` ``params``, the
        gain gamma read from its field ``gamma_field``."""
        return cls(training, params.dt, getattr(params, gamma_field)[axis], params.nu[axis],
                   params.alpha_bar[axis], params.bounds, params.phi[axis])


def _smc_consequents(f, alpha, w_bar, tau_c, gains: AxisGains):
    """f and alpha at k + 1 under SMC: eqs. (37) and (38)."""
    f_dot = smc_f_rate(w_bar, alpha, tau_c, gains.phi)
    alpha_next = project(alpha + gains.dt * alpha_rate(tau_c, alpha, gains.gamma, gains.nu), 0.0,
                         gains.bounds.alpha_max)
    return f + gains.dt * f_dot, alpha_next


def _lm_consequents(f, alpha, w_bar, tau_c, gains: AxisGains):
    """f and alpha at k + 1 under LM: eqs. (61)-(62), alpha held."""
    return f + gains.dt * lm_f_rate(w_bar, tau_c, gains.gamma, gains.alpha_bar, gains.phi), alpha


_CONSEQUENTS = {"smc": _smc_consequents, "lm": _lm_consequents}


def parameters_step(gains: AxisGains, state, previous_inputs, primed, x1, x2, tau_c, w_bar):
    """The centres, widths, consequents and alpha of one axis at step k + 1,
    eqs. (33)-(38) or (57)-(62) (``gains.training``), from the elements C1 ...
    ALPHA of ``state`` (the layout of :mod:`fnn_controller.fnn`, which the
    interval type-2 state shares), the previous inputs ``(x1, x2)`` and the
    ``primed`` flag (where each layout keeps them): the part of the learning step the type-1 and the interval type-2
    FNN have in common (the latter passes its regressor W_bar_q as
    ``w_bar``). Returns ``(c1, c2, sigma1, sigma2, f, alpha)``."""
    bounds, dt, phi = gains.bounds, gains.dt, gains.phi
    c1, c2 = state[C1], state[C2]
    sigma1, sigma2 = state[SIGMA1], state[SIGMA2]
    f, alpha = state[F], state[ALPHA]
    x1_prev, x2_prev = previous_inputs

    # eqs. 33-34 / 57-58 discretized with the inputs' increments
    c1_next = project(c1 + primed * (x1 - x1_prev), -bounds.c1_max, bounds.c1_max)
    c2_next = project(c2 + primed * (x2 - x2_prev), -bounds.c2_max, bounds.c2_max)
    # eqs. 35-36 / 59-60
    sigma1_next = project(sigma1 + dt * sigma_rate(x1, c1, sigma1, alpha, tau_c, bounds.a_min, phi),
                          bounds.sigma1_min, bounds.sigma1_max)
    sigma2_next = project(sigma2 + dt * sigma_rate(x2, c2, sigma2, alpha, tau_c, bounds.a_min, phi),
                          bounds.sigma2_min, bounds.sigma2_max)
    f_next, alpha_next = _CONSEQUENTS[gains.training](f, alpha, w_bar, tau_c, gains)
    return c1_next, c2_next, sigma1_next, sigma2_next, project(f_next, -bounds.f_max, bounds.f_max), alpha_next


def learning_step(gains: AxisGains, state, x1, x2, tau_c, w_bar):
    """One forward-Euler step of the SMC or LM learning laws for one axis.

    Parameters
    ----------
    gains : AxisGains
        The law (``"smc"``: eqs. 33-38; ``"lm"``: eqs. 57-62 with alpha
        held), the step, the gains, the bounds and the boundary layer.
    state : vector of length AXIS_STATE_SIZE
        Axis state at step k (layout in :mod:`fnn_controller.fnn`).
    x1, x2 : scalar
        FNN inputs at step k, already clipped (:func:`clip_inputs`).
    tau_c : scalar
        PD output at step k (eq. 19), the learning error (m/s).
    w_bar : vector of length I*J
        Normalized firing strengths at step k (eq. 25).

    Returns
    -------
    vector of length AXIS_STATE_SIZE
        Axis state at step k + 1.
    """
    parameters = parameters_step(gains, state, (state[X1_PREV], state[X2_PREV]), state[PRIMED], x1, x2, tau_c, w_bar)
    next_state = ca.vertcat(*parameters, x1, x2, ca.DM(1.0))
    assert next_state.shape[0] == AXIS_STATE_SIZE
    return next_state
