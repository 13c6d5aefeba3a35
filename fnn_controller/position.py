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
``"pd+lm"``; and whatever else is registered). Every function here takes the
:class:`~fnn_controller.variants.Variant` itself, not its name: a name is
resolved once where it enters (``fnn_controller.variants.variant(name)``).
The parameters are :class:`~fnn_controller.position_parameters.PositionParams`.

The position-controller state ``fnn_state`` is the three axis states
(x, y, z) stacked; for the paper's variants (layout in
:mod:`fnn_controller.fnn`) 3 * 25 = 75 numbers.
"""
from __future__ import annotations

from fmu_models.lazy_casadi import ca
import numpy as np

from .fnn import AXIS_STATE_SIZE
from .position_parameters import PositionParams

_POSITION = PositionParams()  # the defaults: one (frozen) instance for every signature
from .variants.registry import Variant, identifier, initial_axis_state

__all__ = [
    "FNN_STATE_SIZE", "pd_law", "position_axis", "fnn_state_size",
    "position_controller", "position_controller_function", "initial_fnn_state", "axis_slice",
]

FNN_STATE_SIZE = 3 * AXIS_STATE_SIZE  # the paper's variants


def axis_slice(axis: int, axis_state_size: int = AXIS_STATE_SIZE) -> slice:
    """Slice of axis ``axis`` (0 = x, 1 = y, 2 = z) in the position-controller state."""
    return slice(axis * axis_state_size, (axis + 1) * axis_state_size)


def fnn_state_size(variant: Variant) -> int:
    """Size of the position-controller state of ``variant`` (three axes)."""
    return 3 * variant.axis_state_size


def pd_law(e, e_dot, kp, kd):
    """PD law, eq. (19): ``tau_c = kp e + kd de/dt`` (m/s)."""
    return kp * e + kd * e_dot


def position_axis(variant: Variant, e, e_dot, axis_state, axis: int, params: PositionParams = _POSITION,
                  p_ref_dot=None):
    """One step of the position controller of one axis, eqs. (19), (24)-(26).

    Parameters
    ----------
    variant : Variant
        The learning part (:func:`fnn_controller.variants.variant` of a name).
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
    tau_c = pd_law(e, e_dot, params.kp, params.kd)
    tau_n, state_next = variant.axis_law(e, e_dot, tau_c, axis_state, axis, params)
    tau = tau_c - tau_n
    if p_ref_dot is not None and not is_zero(params.feedforward):
        tau = tau + params.feedforward * p_ref_dot  # the option; 0 keeps the paper's law bit for bit
    return {"tau": tau, "tau_c": tau_c, "tau_n": tau_n, "state_next": state_next}


def is_zero(gain) -> bool:
    """True for a gain that is the number 0 (an option switched off, whose term
    is then left out of the expressions: the paper's law bit for bit); False
    for any other number and for a symbol (a parametric build keeps the term)."""
    return isinstance(gain, (int, float)) and gain == 0


def position_controller(variant: Variant, e, e_dot, fnn_state, params: PositionParams = _POSITION,
                        p_ref_dot=None, p_ref_ddot=None):
    """The three-axis position controller as CasADi expressions (section 3.1).

    Parameters
    ----------
    variant : Variant
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
    size = variant.axis_state_size
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


def position_controller_function(variant: Variant, params: PositionParams = _POSITION) -> ca.Function:
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
        f"position_controller_{identifier(variant.name)}",
        [e, e_dot, fnn_state],
        [out["v_ref"], out["fnn_state_next"], out["tau_c"], out["tau_n"]],
        ["e", "e_dot", "fnn_state"],
        ["v_ref", "fnn_state_next", "tau_c", "tau_n"],
    )


def initial_fnn_state(variant: Variant, rng: np.random.Generator | int,
                      params: PositionParams = _POSITION) -> np.ndarray:
    """Position-controller state of ``variant`` at t = 0 (section 5.1) for the three axes.

    ``rng`` is a ``numpy.random.Generator`` or an integer seed (there is no
    default: every run names its randomness); the x, y and z axes draw from
    it in that order (for the paper's variants, their f_ij(0)).
    """
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        rng = np.random.default_rng(int(rng))
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator or an int seed, not {rng!r}")
    return np.concatenate([initial_axis_state(variant, rng, params) for _ in range(3)])
