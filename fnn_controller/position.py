"""Position controller of section 3.1: per axis PD (eq. 19) in parallel with an
FNN (section 4.1) trained online by SMC or LM (eqs. 33-38, 57-62), eq. (26).

The output of each axis is the desired velocity of that axis,
``v*_axis = tau = tau_c - tau_n`` (m/s). The caller supplies the position
error ``e = p* - p`` (eq. 12) and its derivative ``de/dt = p*_dot - v``
(from the reference derivative and the measured velocity; no finite
differences). There is no velocity feed-forward: the paper has none.

Variants, selected by name: ``"pd"`` (FNN off, tau_n = 0, state passed
through unchanged), ``"pd+smc"``, ``"pd+lm"``.

The position-controller state ``fnn_state`` is the three axis states
(x, y, z; layout in :mod:`fnn_controller.fnn`) stacked, 3 * 25 = 75 numbers.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .fnn import (AXIS_STATE_SIZE, C1, C2, F, SIGMA1, SIGMA2, FnnInit, fnn_output,
                  initial_axis_state, normalized_firing_strength)
from .learning import LearningBounds, clip_inputs, learning_step

__all__ = [
    "VARIANTS", "FNN_STATE_SIZE", "PositionParams", "pd_law", "position_axis",
    "position_controller", "position_controller_function", "initial_fnn_state", "axis_slice",
]

VARIANTS = ("pd", "pd+smc", "pd+lm")
FNN_STATE_SIZE = 3 * AXIS_STATE_SIZE


@dataclass(frozen=True)
class PositionParams:
    """Gains of the position controller, paper values (section 5.1)."""

    kp: float = 2.5  # 1/s, proportional gain of eq. 19
    kd: float = 0.005  # 1 (s/s), derivative gain of eq. 19
    dt: float = 0.01  # s, learning (and controller) step
    gamma_smc: tuple[float, float, float] = (1.5, 1.5, 1.5)  # 1/s, gamma of eq. 38 for x, y, z
    nu: tuple[float, float, float] = (0.85, 0.85, 0.2)  # s, nu of eq. 38 for x, y, z
    gamma_lm: tuple[float, float, float] = (1.5, 1.5, 1.5)  # m/s^2, gamma of eq. 61 for x, y, z
    alpha_bar: tuple[float, float, float] = (1.1, 1.1, 0.9)  # 1, alpha_bar of eq. 62 for x, y, z
    init: FnnInit = field(default_factory=FnnInit)  # initial FNN values (section 5.1)
    bounds: LearningBounds = field(default_factory=LearningBounds)  # eqs. 27-29 and floors


def axis_slice(axis: int) -> slice:
    """Slice of axis ``axis`` (0 = x, 1 = y, 2 = z) in the position-controller state."""
    return slice(axis * AXIS_STATE_SIZE, (axis + 1) * AXIS_STATE_SIZE)


def pd_law(e, e_dot, kp, kd):
    """PD law, eq. (19): ``tau_c = kp e + kd de/dt`` (m/s)."""
    return kp * e + kd * e_dot


def _check_variant(variant: str) -> None:
    if variant not in VARIANTS:
        raise ValueError(f"unknown position-controller variant {variant!r}; expected one of {VARIANTS}")


def position_axis(variant: str, e, e_dot, axis_state, axis: int, params: PositionParams = PositionParams()):
    """One step of the position controller of one axis, eqs. (19), (24)-(26).

    Parameters
    ----------
    variant : {"pd", "pd+smc", "pd+lm"}
    e : scalar
        Position error p* - p of this axis (m), eq. (12).
    e_dot : scalar
        Its derivative p*_dot - v (m/s).
    axis_state : vector of length AXIS_STATE_SIZE
        FNN parameters of this axis at step k.
    axis : int
        0, 1, 2 for x, y, z (selects the per-axis learning gains).
    params : PositionParams

    Returns
    -------
    dict
        ``tau`` (the desired velocity v*, eq. 26), ``tau_c`` (eq. 19),
        ``tau_n`` (eq. 24), ``w_bar`` (eq. 25) and ``state_next``.
    """
    _check_variant(variant)
    tau_c = pd_law(e, e_dot, params.kp, params.kd)
    x1, x2 = clip_inputs(e, e_dot, params.bounds)
    w_bar = normalized_firing_strength(x1, x2, axis_state[C1], axis_state[C2],
                                       axis_state[SIGMA1], axis_state[SIGMA2])
    if variant == "pd":
        tau_n = 0.0 * tau_c
        state_next = axis_state
    else:
        tau_n = fnn_output(axis_state[F], w_bar)
        state_next = learning_step(
            variant[3:], axis_state, x1, x2, tau_c, w_bar, params.dt,
            gamma=params.gamma_smc[axis] if variant == "pd+smc" else params.gamma_lm[axis],
            nu=params.nu[axis], alpha_bar=params.alpha_bar[axis], bounds=params.bounds,
        )
    return {"tau": tau_c - tau_n, "tau_c": tau_c, "tau_n": tau_n, "w_bar": w_bar,
            "state_next": state_next}


def position_controller(variant: str, e, e_dot, fnn_state, params: PositionParams = PositionParams()):
    """The three-axis position controller as CasADi expressions (section 3.1).

    Parameters
    ----------
    variant : {"pd", "pd+smc", "pd+lm"}
    e, e_dot : 3-vectors
        Position error p* - p (m, eq. 12) and its derivative p*_dot - v (m/s).
    fnn_state : vector of length FNN_STATE_SIZE
        Stacked axis states (x, y, z).
    params : PositionParams

    Returns
    -------
    dict
        ``v_ref`` (3, m/s, eq. 26), ``tau_c`` (3), ``tau_n`` (3),
        ``fnn_state_next`` (FNN_STATE_SIZE).
    """
    axes = [position_axis(variant, e[a], e_dot[a], fnn_state[axis_slice(a)], a, params) for a in range(3)]
    return {
        "v_ref": ca.vertcat(*[ax["tau"] for ax in axes]),
        "tau_c": ca.vertcat(*[ax["tau_c"] for ax in axes]),
        "tau_n": ca.vertcat(*[ax["tau_n"] for ax in axes]),
        "fnn_state_next": ca.vertcat(*[ax["state_next"] for ax in axes]),
    }


def position_controller_function(variant: str, params: PositionParams = PositionParams()) -> ca.Function:
    """The position controller as one CasADi function.

    ``position_controller_<variant>(e[3], e_dot[3], fnn_state[75])
    -> (v_ref[3], fnn_state_next[75], tau_c[3], tau_n[3])`` with the units
    and meaning of :func:`position_controller`. The variant name in the
    function name has ``+`` replaced by ``_``.
    """
    _check_variant(variant)
    e = ca.SX.sym("e", 3)
    e_dot = ca.SX.sym("e_dot", 3)
    fnn_state = ca.SX.sym("fnn_state", FNN_STATE_SIZE)
    out = position_controller(variant, e, e_dot, fnn_state, params)
    return ca.Function(
        f"position_controller_{variant.replace('+', '_')}",
        [e, e_dot, fnn_state],
        [out["v_ref"], out["fnn_state_next"], out["tau_c"], out["tau_n"]],
        ["e", "e_dot", "fnn_state"],
        ["v_ref", "fnn_state_next", "tau_c", "tau_n"],
    )


def initial_fnn_state(rng: np.random.Generator | int, params: PositionParams = PositionParams()) -> np.ndarray:
    """Position-controller state at t = 0 (section 5.1) for the three axes.

    ``rng`` is a ``numpy.random.Generator`` or an integer seed (there is no
    default: every run names its randomness); the f_ij(0) of the x, y and z
    axes are drawn from it in that order.
    """
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        rng = np.random.default_rng(int(rng))
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator or an int seed, not {rng!r}")
    return np.concatenate([initial_axis_state(rng, params.init) for _ in range(3)])
