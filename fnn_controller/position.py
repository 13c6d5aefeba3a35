"""Position controller of section 3.1: per axis PD (eq. 19) in parallel with an
FNN (section 4.1) trained online by SMC or LM (eqs. 33-38, 57-62), eq. (26).

The output of each axis is the desired velocity of that axis,
``v*_axis = tau = tau_c - tau_n`` (m/s). The caller supplies the position
error ``e = p* - p`` (eq. 12) and its derivative ``de/dt = p*_dot - v``
(from the reference derivative and the measured velocity; no finite
differences). The paper has no feed-forward; two options add it (0, the
default, is the paper's law bit for bit): the reference velocity around the
PD (``feedforward``) and the reference acceleration d²p*/dt², passed on to
the velocity controller's desired force (``accel_feedforward``).

The learning part is the variant's (:mod:`fnn_controller.variants`: ``"pd"``,
FNN off, tau_n = 0, state passed through unchanged; ``"pd+smc"``;
``"pd+lm"``; and whatever else is registered).

The position-controller state ``fnn_state`` is the three axis states
(x, y, z) stacked; for the paper's variants (layout in
:mod:`fnn_controller.fnn`) 3 * 25 = 75 numbers.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .fnn import AXIS_STATE_SIZE, FnnInit
from .it2 import IT2Params
from .learning import LearningBounds
from .parameters import check_ranges, param

__all__ = [
    "FNN_STATE_SIZE", "PositionParams", "pd_law", "position_axis", "fnn_state_size",
    "position_controller", "position_controller_function", "initial_fnn_state", "axis_slice",
]

FNN_STATE_SIZE = 3 * AXIS_STATE_SIZE  # the paper's variants


@dataclass(frozen=True)
class PositionParams:
    """Gains of the position controller, paper values (section 5.1)."""

    kp: float = param(2.5, "1/s", "proportional gain of eq. 19")  # any sign: the stability analysis sweeps it
    kd: float = param(0.005, "1", "derivative gain of eq. 19 (s/s)")
    dt: float = param(0.01, "s", "learning (and controller) step", min=1e-4, max=1.0)
    gamma_smc: tuple[float, float, float] = param((1.5, 1.5, 1.5), "1/s", "gamma of eq. 38 for x, y, z", min=0.0)
    nu: tuple[float, float, float] = param((0.85, 0.85, 0.2), "s", "nu of eq. 38 for x, y, z", min=0.0)
    gamma_lm: tuple[float, float, float] = param((1.5, 1.5, 1.5), "m/s2", "gamma of eq. 61 for x, y, z", min=0.0)
    alpha_bar: tuple[float, float, float] = param((1.1, 1.1, 0.9), "1", "alpha_bar of eq. 62 for x, y, z",
                                                  min=0.0)
    feedforward: float = param(0.0, "1", "gain of the reference velocity fed forward around the PD: "
                               "v* = tau_c - tau_n + feedforward dp*/dt (0: the paper's law)", min=0.0, max=1.0)
    accel_feedforward: float = param(0.0, "1", "gain of the reference acceleration d2p*/dt2 passed to the velocity "
                                     "controller: a_ref = accel_feedforward d2p*/dt2 (0: the paper's law)",
                                     min=0.0, max=1.0)
    phi: tuple[float, float, float] = param((0.0, 0.0, 0.0), "m/s",
                                            "boundary layer of the learning laws' sgn(tau_c) for x, y, z: "
                                            "sat(tau_c / phi) in its place (0: the paper's sgn)", min=0.0)
    init: FnnInit = field(default_factory=FnnInit)  # initial FNN values (section 5.1)
    it2: IT2Params = field(default_factory=IT2Params)  # the interval type-2 FNN's own (variants pd+it2-*)
    bounds: LearningBounds = field(default_factory=LearningBounds)  # eqs. 27-29 and floors

    def __post_init__(self) -> None:
        check_ranges(self)


def axis_slice(axis: int, axis_state_size: int = AXIS_STATE_SIZE) -> slice:
    """Slice of axis ``axis`` (0 = x, 1 = y, 2 = z) in the position-controller state."""
    return slice(axis * axis_state_size, (axis + 1) * axis_state_size)


def fnn_state_size(variant: str) -> int:
    """Size of the position-controller state of ``variant`` (three axes)."""
    from .variants import variant as lookup

    return 3 * lookup(variant).axis_state_size


def pd_law(e, e_dot, kp, kd):
    """PD law, eq. (19): ``tau_c = kp e + kd de/dt`` (m/s)."""
    return kp * e + kd * e_dot


def position_axis(variant: str, e, e_dot, axis_state, axis: int, params: PositionParams = PositionParams(),
                  p_ref_dot=None):
    """One step of the position controller of one axis, eqs. (19), (24)-(26).

    Parameters
    ----------
    variant : a registered variant name (:func:`fnn_controller.variants.variant_names`)
    e : scalar
        Position error p* - p of this axis (m), eq. (12).
    e_dot : scalar
        Its derivative p*_dot - v (m/s).
    axis_state : vector
        The variant's parameters of this axis at step k.
    axis : int
        0, 1, 2 for x, y, z (selects the per-axis learning gains).
    params : PositionParams

    Returns
    -------
    dict
        ``tau`` (the desired velocity v*, eq. 26), ``tau_c`` (eq. 19),
        ``tau_n`` (eq. 24) and ``state_next``.
    """
    from .variants import variant as lookup

    law = lookup(variant).axis_law
    tau_c = pd_law(e, e_dot, params.kp, params.kd)
    tau_n, state_next = law(e, e_dot, tau_c, axis_state, axis, params)
    tau = tau_c - tau_n
    if p_ref_dot is not None and not is_zero(params.feedforward):
        tau = tau + params.feedforward * p_ref_dot  # the option; 0 keeps the paper's law bit for bit
    return {"tau": tau, "tau_c": tau_c, "tau_n": tau_n, "state_next": state_next}


def is_zero(gain) -> bool:
    """True for a gain that is the number 0 (an option switched off, whose term
    is then left out of the expressions: the paper's law bit for bit); False
    for any other number and for a symbol (a parametric build keeps the term)."""
    return isinstance(gain, (int, float)) and gain == 0


def position_controller(variant: str, e, e_dot, fnn_state, params: PositionParams = PositionParams(),
                        p_ref_dot=None, p_ref_ddot=None):
    """The three-axis position controller as CasADi expressions (section 3.1).

    Parameters
    ----------
    variant : a registered variant name
    e, e_dot : 3-vectors
        Position error p* - p (m, eq. 12) and its derivative p*_dot - v (m/s).
    fnn_state : vector of length ``fnn_state_size(variant)``
        Stacked axis states (x, y, z).
    params : PositionParams
    p_ref_dot : 3-vector, optional
        The reference velocity (m/s), fed forward with ``params.feedforward``.
    p_ref_ddot : 3-vector, optional
        The reference acceleration d²p*/dt² (m/s², world, z down), passed on
        scaled by ``params.accel_feedforward``.

    Returns
    -------
    dict
        ``v_ref`` (3, m/s, eq. 26 plus the feed-forward), ``tau_c`` (3), ``tau_n`` (3),
        ``fnn_state_next`` (``fnn_state_size(variant)``), ``a_ref`` (3, m/s²: the
        acceleration for the velocity controller's desired force,
        ``accel_feedforward d²p*/dt²``; ``None`` when the option is off or
        no acceleration is given, which the velocity controller reads as none).
    """
    size = fnn_state_size(variant) // 3
    axes = [position_axis(variant, e[a], e_dot[a], fnn_state[axis_slice(a, size)], a, params,
                          None if p_ref_dot is None else p_ref_dot[a]) for a in range(3)]
    off = p_ref_ddot is None or is_zero(params.accel_feedforward)
    return {
        "v_ref": ca.vertcat(*[ax["tau"] for ax in axes]),
        "tau_c": ca.vertcat(*[ax["tau_c"] for ax in axes]),
        "tau_n": ca.vertcat(*[ax["tau_n"] for ax in axes]),
        "fnn_state_next": ca.vertcat(*[ax["state_next"] for ax in axes]),
        "a_ref": None if off else params.accel_feedforward * p_ref_ddot,
    }


def _identifier(variant: str) -> str:
    from .variants.registry import identifier

    return identifier(variant)


def position_controller_function(variant: str, params: PositionParams = PositionParams()) -> ca.Function:
    """The position controller as one CasADi function.

    ``position_controller_<variant>(e[3], e_dot[3], fnn_state[n])
    -> (v_ref[3], fnn_state_next[75], tau_c[3], tau_n[3])`` with the units
    and meaning of :func:`position_controller`. The variant name in the
    function name has ``+`` replaced by ``_``.
    """
    e = ca.SX.sym("e", 3)
    e_dot = ca.SX.sym("e_dot", 3)
    fnn_state = ca.SX.sym("fnn_state", fnn_state_size(variant))
    out = position_controller(variant, e, e_dot, fnn_state, params)
    return ca.Function(
        f"position_controller_{_identifier(variant)}",
        [e, e_dot, fnn_state],
        [out["v_ref"], out["fnn_state_next"], out["tau_c"], out["tau_n"]],
        ["e", "e_dot", "fnn_state"],
        ["v_ref", "fnn_state_next", "tau_c", "tau_n"],
    )


def initial_fnn_state(rng: np.random.Generator | int, params: PositionParams = PositionParams(),
                      variant: str = "pd+lm") -> np.ndarray:
    """Position-controller state of ``variant`` at t = 0 (section 5.1) for the three axes.

    ``rng`` is a ``numpy.random.Generator`` or an integer seed (there is no
    default: every run names its randomness); the x, y and z axes draw from
    it in that order (for the paper's variants, their f_ij(0)).
    """
    from .variants import initial_axis_state, variant as lookup

    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        rng = np.random.default_rng(int(rng))
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator or an int seed, not {rng!r}")
    v = lookup(variant)
    return np.concatenate([initial_axis_state(v, rng, params) for _ in range(3)])
