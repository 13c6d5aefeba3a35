"""The learning laws' finite-time claims, evaluated on recorded runs.

This module is part of the paper application, outside the linear stability
package (it was ``quadrotor_paper/stability/finite_time.py``): it checks the
FNN's learning laws, which have no linearization. The stability report
(``fnn-cosim stability``, :mod:`quadrotor_paper.stability.report`) still
includes its results as the section "The learning laws' finite-time claims
on recorded runs" (``docs/stability.md``).

The paper's claims (section 4), with tau = tau_c - tau_n the control
(eq. 26), ``B`` a bound of ``|d tau/dt|`` (eq. 30) and S_p = tau_c/K_d (eq. 68):

* **SMC, Theorem 1, eq. (53)**: if ``B <= alpha*/2`` then
  ``dV_c/dt <= -alpha*/2 |tau_c| + nu alpha*^2/4``, so V_c decreases until
  ``|tau_c| < nu alpha*/2``. With the smallest admissible ``alpha* = 2 B`` the
  neighbourhood is ``|tau_c| < nu B``. No reaching time is given.
* **LM, Theorem 3, eq. (66)**: with ``delta = W^T W`` (the proof's choice) and
  ``gamma > B/4`` (as printed), ``dV_c/dt <= -gamma/4 |tau_c|``. From eq. (65),
  ``-gamma/2 |tau_c| + B |tau_c| <= -gamma/4 |tau_c|`` actually needs
  ``B <= gamma/4``, i.e. ``gamma >= 4 B``; both conditions are reported.
* **LM, Theorem 4, eq. (70)**: ``S_p`` reaches zero within
  ``t_h <= 4 K_d S_p(0)/gamma = 4 |tau_c(0)|/gamma``.

Two assumptions the proofs make without saying so, checked on the same runs
for the type-1 and the interval type-2 laws (eqs. IT-14, IT-15 of
``docs/controller.md``):

* **alpha* inside the projection box (SMC).** The proof of Theorem 1 needs a
  constant ``alpha* >= 2 B`` in ``V_c``; the law projects alpha onto
  ``[0, alpha_max]``, and a projected adaptive law keeps the Lyapunov
  argument only if ``alpha*`` lies in the box: ``2 B <= alpha_max``, i.e.
  ``B <= alpha_max / 2``.
* **W_bar does not move (eq. 45, IT-12).** In continuous time the centre and
  width laws leave the normalized firing strengths unchanged; the forward
  Euler step does not (second order in ``dt alpha``): the largest step-to-step
  change of the regressor the law uses (W_bar, or W_bar_q for the IT2 FNN),
  ``max_n ||W_n - W_{n-1}||_inf``, is reported, and
  :func:`regressor_step_change` gives it for one step at a given alpha, away
  from the width floor (second order) and at it (first order).

What a run shows (per axis): ``B`` measured as ``max |Delta tau|/h`` (and its
99th percentile), the time |tau_c| enters eq. (53)'s neighbourhood for good,
the first time tau_c reaches zero (changes sign), the largest |tau_c| after
t_h, and for LM the delta the law actually uses (``max(W^T W, alpha_bar)``,
eq. 62) and the resulting decrease rate ``gamma W^T W/(delta + W^T W)``
against the proof's gamma/2.

No law is written again here: W_bar (eq. 25) or W_bar_q (IT-5), delta (eq.
62) and the f rate (eq. 61) are the controller's own CasADi definitions
(``fnn_controller.fnn.normalized_firing_strength``,
``fnn_controller.it2.it2_normalized_firing_strengths``, ``it2_regressor``,
``fnn_controller.learning.clip_inputs``, ``lm_delta``, ``lm_f_rate``), built
into one ``casadi.Function`` and mapped over the samples of a run
(:func:`_claims_function`).

The runs are co-simulations by the master (plant FMU, h = 0.01 s) that
record the learned state the controller publishes (its internal signals
``controller.f_12_x``, ..., the controller FMU's local variables): a 1 m
position step from hover, and the paper's mission (shipped scenario
``circles``, 3 m/s gust).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

from fmu_models.lazy_casadi import ca
import numpy as np

from fnn_controller import PositionParams
from fnn_controller.fnn import ALPHA, C1, C2, SIGMA1, SIGMA2, normalized_firing_strength
from fnn_controller.it2 import Q, it2_normalized_firing_strengths, it2_regressor
from fnn_controller.learning import LearningBounds, clip_inputs, lm_delta, lm_f_rate
from fnn_controller.position import axis_slice
from fnn_controller.variants import variant as _variant
from fnn_controller.variants import variants as _variants

from .controller_component import internal_ports
from .controller_component import controller_variant

__all__ = ["Recording", "AxisClaims", "recorded", "evaluate_claims", "default_runs",
           "regressor_step_change", "CLAIM_MISSIONS", "CLAIM_VARIANTS"]

_AXES = ("x", "y", "z")
# the learning variants the claims cover, by law: the type-1 FNN (eq. 25) and the interval type-2 FNN (IT-5)
_SMC, _LM = (tuple(v.name for v in _variants().values() if v.training == law) for law in ("smc", "lm"))
CLAIM_VARIANTS = (*_SMC, *_LM)


@dataclass(frozen=True, eq=False)
class Recording:
    """One recorded co-simulation: time (n,), per axis (n, 3) the position
    error e, its derivative e_dot, tau_c, tau_n and tau = v*; the controller
    position-controller states *before* each step (n, 3 x axis state); its
    variant and gains."""

    name: str
    variant: str
    t: np.ndarray
    e: np.ndarray
    e_dot: np.ndarray
    tau_c: np.ndarray
    tau_n: np.ndarray
    tau: np.ndarray
    states: np.ndarray
    position: PositionParams
    status: str = "ok"


def _signals(variant: str) -> list[str]:
    """What the claims read: the reference and the vehicle's position and
    velocity, the controller's tau_c, tau_n, v* and its learned state."""
    signals = [f"reference.{s}" for s in ("x", "y", "z", "vx", "vy", "vz")]
    signals += [f"Quadrotor.{s}" for s in ("x", "y", "z", "u", "v", "w")]
    signals += [f"controller.{k}_{a}" for k in ("tau_c", "tau_n", "v_ref") for a in _AXES]
    return signals + [f"controller.{port.name}" for port in internal_ports(variant)]


def _position(scenario) -> PositionParams:
    """The position controller's parameters of ``scenario``'s controller."""
    from .controller_component import controller_settings

    return controller_settings(scenario).position


def recorded(scenario, result) -> dict[str, Recording]:
    """A study's metric (module level: it may run on a Dask worker): the
    run as the claims read it, ``{"recorded": Recording}``."""
    variant = controller_variant(scenario)
    position = _position(scenario)
    # the learned state recorded at t_n is the one step n starts from (both forms of the controller)
    states = np.column_stack([result[f"controller.{port.name}"] for port in internal_ports(variant)])

    def cols(fmt):
        return np.column_stack([result[fmt.format(a=a)] for a in _AXES])

    e = cols("reference.{a}") - cols("Quadrotor.{a}")
    vel = np.column_stack([result[f"Quadrotor.{s}"] for s in ("u", "v", "w")])
    e_dot = np.column_stack([result[f"reference.v{a}"] for a in _AXES]) - vel
    return {"recorded": Recording(scenario.name, variant, result.time.copy(), e, e_dot, cols("controller.tau_c_{a}"),
                            cols("controller.tau_n_{a}"), cols("controller.v_ref_{a}"), states, position,
                            result.status)}


def _is_it2(variant: str) -> bool:
    return _variant(variant).fnn == "it2"


def _regressor(x1, x2, s, variant: str, position: PositionParams):
    """The regressor the law of ``variant`` uses at one sample, from the
    controller's own definitions: W_bar of eq. 25 (type-1) or
    W_bar_q = q W_bar_lower + (1 - q) W_bar_upper of IT-5 (interval type-2),
    the inputs clipped by eq. 27."""
    c1, c2 = clip_inputs(x1, x2, position.bounds)
    if _is_it2(variant):
        lower, upper = it2_normalized_firing_strengths(c1, c2, s[C1], s[C2], s[SIGMA1], s[SIGMA2],
                                                       position.it2.spread)
        return it2_regressor(lower, upper, s[Q])
    return normalized_firing_strength(c1, c2, s[C1], s[C2], s[SIGMA1], s[SIGMA2])


@lru_cache(maxsize=None)
def _claims_function(variant: str, position: PositionParams) -> ca.Function:
    """The law's terms at one sample, from the controller's definitions.

    Inputs ``x1 = e``, ``x2 = de/dt`` (clipped by ``clip_inputs``), the axis
    state, ``gamma`` and ``alpha_bar``; outputs the regressor W (W_bar of eq. 25,
    or W_bar_q of IT-5), ``W^T W``, ``delta = lm_delta(W, alpha_bar)`` (eq. 62,
    IT-11) and the decrease rate of tau_n, ``-W^T lm_f_rate(W, 1, gamma,
    alpha_bar)`` (eq. 61 / IT-10 with sgn(tau_c) = 1), which is
    ``gamma W^T W/(delta + W^T W)``.
    """
    x1, x2 = ca.SX.sym("x1"), ca.SX.sym("x2")
    s = ca.SX.sym("axis_state", _variant(variant).axis_state_size)
    gamma, alpha_bar = ca.SX.sym("gamma"), ca.SX.sym("alpha_bar")
    w = _regressor(x1, x2, s, variant, position)
    rate = -ca.dot(w, lm_f_rate(w, 1.0, gamma, alpha_bar))
    return ca.Function("claims", [x1, x2, s, gamma, alpha_bar], [w, ca.dot(w, w), lm_delta(w, alpha_bar), rate],
                       ["x1", "x2", "axis_state", "gamma", "alpha_bar"], ["w", "w_squared", "delta", "rate"])


def _law_terms(run: Recording, axis: int, gamma: float, alpha_bar: float):
    """The regressor (n, 9), W^T W, delta (eq. 62) and the decrease rate at
    every sample of ``axis`` of ``run``: :func:`_claims_function` mapped over
    the samples."""
    f = _claims_function(run.variant, run.position).map(len(run.t))
    states = run.states[:, axis_slice(axis, _variant(run.variant).axis_state_size)].T
    out = f(run.e[:, axis][None, :], run.e_dot[:, axis][None, :], states, gamma, alpha_bar)
    w = np.array(out[0]).T
    return (w, *(np.array(o).ravel() for o in out[1:]))


def _regressor_steps(w: np.ndarray) -> np.ndarray:
    """``||W_n - W_{n-1}||_inf`` from the third sample on: from step 2 the
    centre law has moved every centre with its input (eqs. 33-34), so ``x - c``
    is what it was and only the widths (and the clipping) move W."""
    return np.abs(np.diff(w[1:], axis=0)).max(axis=1) if len(w) > 2 else np.zeros(0)


def regressor_step_change(variant: str, alpha: float, position: PositionParams = PositionParams(),
                          x1=np.linspace(-3.0, 3.0, 25), x2=np.linspace(-30.0, 30.0, 25),
                          tau_c: float = 1.0) -> tuple[float, float]:
    """The largest change of the regressor (W_bar, eq. 25, or W_bar_q, IT-5)
    over one learning step at ``alpha``, with the inputs held (so the centres
    do not move) and the section 5.1 initial values, over the grid of inputs
    ``x1 x x2`` (default: the span of the initial centres).

    Returns ``(away from the floor, at the floor)``: the largest change over
    the inputs where no membership function has ``|A| = |x - c|/sigma <
    a_min``, and over those where one has (``nan`` where the grid has none).
    The continuous-time laws leave the regressor unchanged (eq. 45, IT-12)
    away from the floor; there the forward Euler step moves it at second order
    in ``dt alpha``; at the floor the width law is another law and moves it
    at first order. q is held (IT-9 moves it by design). The step is the
    variant's own ``axis_law``, not a copy.
    """
    v = _variant(variant)
    state0 = np.array(ca.DM(v.initial_axis(position, ca.DM(np.random.default_rng(0).random(v.n_random))))).ravel()
    state0[ALPHA] = alpha
    s = ca.SX.sym("s", v.axis_state_size)
    e, e_dot = ca.SX.sym("e"), ca.SX.sym("e_dot")
    _, nxt = v.axis_law(e, e_dot, tau_c, s, 0, position)
    step = ca.Function("step", [e, e_dot, s], [nxt])
    reg = ca.Function("w", [e, e_dot, s], [_regressor(e, e_dot, s, variant, position)])
    a_min = position.bounds.a_min
    worst = {False: math.nan, True: math.nan}
    for a in x1:
        for b in x2:
            state = state0.copy()
            state[-3:] = (a, b, 1.0)  # primed with the same inputs: the centres stay where they are
            after = np.array(step(a, b, state)).ravel()
            if _is_it2(variant):
                after[Q] = state[Q]
            change = float(np.abs(np.array(reg(a, b, after)) - np.array(reg(a, b, state))).max())
            on_floor = bool((np.abs(a - state[C1]) / state[SIGMA1] < a_min).any()
                            or (np.abs(b - state[C2]) / state[SIGMA2] < a_min).any())
            worst[on_floor] = np.nanmax([worst[on_floor], change])
    return float(worst[False]), float(worst[True])


@dataclass(frozen=True)
class AxisClaims:
    """The bounds of eqs. (53), (66), (70) next to what one axis of a run shows.

    Times in s from the start of the run; ``nan`` where an event never happens.
    """

    run: str
    variant: str
    axis: str
    tau_c0: float  # m/s, |tau_c(0)|
    tau_c_max: float  # m/s, max |tau_c| over the run
    B: float  # m/s^2, max |d tau/dt| on the run
    B99: float  # m/s^2, its 99th percentile
    gamma: float
    final_band: float  # m/s, max |tau_c| over the last fifth of the run
    t_zero: float  # s, first time tau_c reaches 0 (changes sign)
    # SMC, eq. 53
    nu: float = math.nan
    radius_53: float = math.nan  # m/s, nu alpha*/2 with alpha* = 2 B
    t_enter_53: float = math.nan  # s, |tau_c| < radius_53 from then on
    alpha_min: float = math.nan
    alpha_max: float = math.nan
    # LM, eqs. 66 and 70
    t_h_70: float = math.nan  # s, 4 |tau_c(0)| / gamma
    max_after_t_h: float = math.nan  # m/s, max |tau_c| for t >= t_h
    printed_condition: bool | None = None  # gamma > B/4
    needed_condition: bool | None = None  # gamma >= 4 B
    delta_is_wtw: float = math.nan  # fraction of samples where delta = W^T W (the proof's choice)
    rate_min: float = math.nan  # m/s^2, min of gamma W^T W / (delta + W^T W)
    rate_max: float = math.nan
    # assumptions of both proofs
    alpha_bound: float = math.nan  # m/s^2, the projection's alpha_max (SMC)
    alpha_star_in_box: bool | None = None  # SMC: alpha* = 2 B <= alpha_max
    regressor_step_max: float = math.nan  # max ||W_n - W_{n-1}||_inf (eq. 45 / IT-12 say 0)


def _enter_for_good(t: np.ndarray, inside: np.ndarray) -> float:
    if inside.all():
        return float(t[0])
    if not inside[-1]:
        return math.nan
    return float(t[np.flatnonzero(~inside)[-1] + 1])


def evaluate_claims(run: Recording, axis: int) -> AxisClaims:
    """:class:`AxisClaims` of ``axis`` (0, 1, 2) of ``run``."""
    t, tc, tau = run.t, run.tau_c[:, axis], run.tau[:, axis]
    h = float(t[1] - t[0])
    rates = np.abs(np.diff(tau)) / h
    B, B99 = float(rates.max()), float(np.percentile(rates, 99))
    sign = np.sign(tc)
    crossing = np.flatnonzero((sign[1:] != sign[0]) | (sign[1:] == 0))
    t_zero = float(t[crossing[0] + 1]) if sign[0] != 0 and crossing.size else (0.0 if sign[0] == 0 else math.nan)
    last = t >= t[0] + 0.8 * (t[-1] - t[0])
    common = dict(run=run.name, variant=run.variant, axis=_AXES[axis], tau_c0=float(abs(tc[0])),
                  tau_c_max=float(np.abs(tc).max()), B=B, B99=B99,
                  final_band=float(np.abs(tc[last]).max()), t_zero=t_zero)
    p = run.position
    if run.variant not in CLAIM_VARIANTS:
        raise ValueError(f"run {run.name!r}: variant {run.variant!r} has no learning law "
                         f"({', '.join(CLAIM_VARIANTS)})")
    gamma = p.gamma_smc[axis] if run.variant in _SMC else p.gamma_lm[axis]
    w, wtw, delta, rate = _law_terms(run, axis, gamma, p.alpha_bar[axis])  # eqs. 25 / IT-5, 61, 62
    steps = _regressor_steps(w)
    common["regressor_step_max"] = float(steps.max()) if steps.size else math.nan
    if run.variant in _SMC:
        nu = p.nu[axis]
        radius = nu * B  # nu alpha*/2 with alpha* = 2 B
        alpha = run.states[:, axis_slice(axis, _variant(run.variant).axis_state_size)][:, ALPHA]
        return AxisClaims(gamma=gamma, nu=nu, radius_53=radius,
                          t_enter_53=_enter_for_good(t, np.abs(tc) < radius),
                          alpha_min=float(alpha.min()), alpha_max=float(alpha.max()),
                          alpha_bound=p.bounds.alpha_max, alpha_star_in_box=bool(2 * B <= p.bounds.alpha_max),
                          **common)
    t_h = 4.0 * float(abs(tc[0])) / gamma  # eq. 70 with S_p(0) = tau_c(0)/K_d
    after = t >= t[0] + t_h
    return AxisClaims(gamma=gamma, t_h_70=t_h,
                      max_after_t_h=float(np.abs(tc[after]).max()) if after.any() else math.nan,
                      printed_condition=bool(gamma > B / 4), needed_condition=bool(gamma >= 4 * B),
                      delta_is_wtw=float(np.mean(delta == wtw)), rate_min=float(rate.min()),
                      rate_max=float(rate.max()), **common)


# the two missions of the claims: (name, dotted overrides of the circles scenario)
CLAIM_MISSIONS = (
    ("step 1 m", {"trajectory": {"kind": "hover", "x": 1.0, "y": 0.0, "z": -15.0}, "wind.speed": 0.0,
                  "simulation.duration": 20.0}),
    ("circles, 3 m/s gust", {"wind.speed": 3.0}),
)


def default_runs(variants=CLAIM_VARIANTS, kp: float | None = None, kd: float | None = None,
                 workers: int = 1) -> list[Recording]:
    """The two recorded runs per variant, a study on ``circles`` (one case
    per mission and variant): a 1 m step of the x reference from hover (20 s,
    no wind), and the paper's mission (50 s, 3 m/s gust); PD gains of the
    ``circles`` scenario (the paper's) unless given."""
    from cosim.study.definition import parse_study

    from .experiments import measure

    gains = {f"controller.position.{k}": float(v) for k, v in (("kp", kp), ("kd", kd)) if v is not None}
    cases = {f"{name} / {variant}": {"label": name, "set": {**overrides, **gains, "controller.variant": variant,
                                                            "record.signals": _signals(variant)}}
             for variant in variants for name, overrides in CLAIM_MISSIONS}
    study = parse_study({"scenario": "circles", "name": "learning_claims", "cases": cases})
    labels = {c.name: c.label for c in study.cases}
    rows = measure(study, workers=workers, metrics=recorded, metric_names=()).rows  # each case records its own signals
    return [replace(row["recorded"], name=labels[row["case"]]) for row in rows]
