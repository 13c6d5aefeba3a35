"""What the data say about the estimates: standard errors, 95 % intervals,
correlations, identifiability, residuals.

At the optimum, with ``J`` the Jacobian of the weighted residuals (each
divided by its output's noise level) with respect to the fitted names, and
the initial states estimated per segment eliminated (the Schur complement
of their blocks), the Fisher information is ``F = J^T J`` and the
covariance of the estimates ``s^2 F^-1``, ``s^2 = SSR / (n - p)`` the
residual variance per degree of freedom (1 when the noise levels are
right). The 95 % interval is ``value +- t_{0.975, n-p} std``.

**Identifiability.** The columns of ``J`` are scaled by the values
(``d r / d ln theta``: a relative change of each), and the singular values
of the scaled Jacobian ``J_s = U S V^T`` measured against the largest:
a direction ``v`` with ``s / s_max`` below ``tolerance`` is one the data do
not determine (changing the parameters along it leaves the residuals
unchanged). A parameter with a component of more than ``0.1`` in such a
direction is **not identifiable**: it is reported so, with the direction
(e.g. ``m`` and ``b`` together: only ``b / m`` is determined), and never
with a value, a standard error or an interval. The other parameters'
covariance is that of the determined subspace (the pseudo-inverse).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..study.summary import t975

__all__ = ["Statistics", "statistics", "residual_statistics", "whiteness", "at_bounds", "NULL_COMPONENT", "AT_BOUND",
           "NEAR_BOUND_STD"]

NULL_COMPONENT = 0.1  # a parameter with more than this in an undetermined direction is not identifiable
AT_BOUND = 1e-6  # an estimate this close to its bound (relative) is at it: the solver's projection puts it on the
# bound or, where the last steps approached it from inside, near it (measured 5.7e-12 from a bound at 0)
# a bound at 0 with the other side open: an estimate nearer to it than this share of its standard error is at it
# (its interval would cross the bound by two standard errors; the projected solver ends on an active bound or
# within 1e-11 of it, far below 1e-3 of any standard error)
NEAR_BOUND_STD = 1e-3
MAX_RHO = 0.97  # Andrews' AR(1) plug-in is clipped here (his section 6): a residual of rho -> 1 has no bandwidth


@dataclass
class Statistics:
    std: np.ndarray  # nan where not identifiable
    ci95: np.ndarray  # names x 2, nan where not identifiable
    correlation: np.ndarray  # nan rows/columns where not identifiable
    identifiable: np.ndarray  # bool
    singular_values: np.ndarray  # of the scaled Jacobian, relative to the largest
    null_directions: list  # [{name: component}] of the undetermined directions
    dof: int
    residual_variance: float
    at_bound: np.ndarray = None  # bool: the estimate sits at its bound (module docstring)
    std_robust: np.ndarray = None  # the sandwich's standard errors (module docstring), nan where std is
    ci95_robust: np.ndarray = None
    bandwidth: float = 0.0  # the sandwich's Bartlett bandwidth S, rows
    covariance: str = "classical"  # which one std and ci95 are: "classical" or "robust"
    std_classical: np.ndarray = None  # s^2 F^-1's, whichever std is

    def __post_init__(self):
        if self.std_classical is None:
            self.std_classical = self.std

    def use_robust(self) -> None:
        """Report the sandwich's standard errors and intervals (residuals that are not white)."""
        self.std, self.ci95 = self.std_robust, self.ci95_robust
        self.covariance = "robust"


def _fisher(J: np.ndarray, state_blocks) -> np.ndarray:
    F = J.T @ J
    start = 0
    for block in state_blocks:
        if block is None or not block.size:
            continue
        n = block.shape[0]
        Jg = J[start:start + n]
        H = block.T @ block
        C = Jg.T @ block
        F -= C @ np.linalg.pinv(H) @ C.T
        start += n
    return F


def at_bounds(theta: np.ndarray, lower: np.ndarray, upper: np.ndarray, std: np.ndarray | None = None) -> np.ndarray:
    """Which estimates sit at a finite bound: within :data:`AT_BOUND` of it,
    relative to the larger of the bound's and the interval's magnitudes. A
    bound at 0 with the other side open has no magnitude: there, within
    :data:`NEAR_BOUND_STD` of the estimate's standard error ``std`` (the
    classical one, every name free), else (no standard error) within
    :data:`AT_BOUND` in the name's own unit. Not an absolute 1e-6: a yaw
    coefficient ``d`` of 1.9e-7 N m s^2 with its bound at 0 would always be
    "at" it."""
    out = np.zeros(theta.size, bool)
    for j, (v, lo, hi) in enumerate(zip(theta, lower, upper)):
        width = hi - lo if np.isfinite(hi - lo) else 0.0
        for b in (lo, hi):
            if np.isfinite(b):
                ref = max(abs(b), abs(width) if width else 0.0)
                if ref:
                    out[j] |= abs(v - b) <= AT_BOUND * ref
                elif std is not None and np.isfinite(std[j]) and std[j] > 0:
                    out[j] |= abs(v - b) <= NEAR_BOUND_STD * std[j]
                else:
                    out[j] |= abs(v - b) <= AT_BOUND
    return out


def statistics(names, theta: np.ndarray, J: np.ndarray, residuals: np.ndarray, state_blocks,
               n_states_estimated: int, tolerance: float, lower: np.ndarray | None = None,
               upper: np.ndarray | None = None, n_outputs: int = 1, segment_rows=None) -> Statistics:
    """The estimates' statistics (module docstring). ``residuals``: the
    weighted output residuals, per segment its rows x ``n_outputs`` raveled
    (``segment_rows``: each segment's number of residuals; default one);
    ``J``: their Jacobian w.r.t. the fitted names; ``lower``, ``upper``: the
    fitted names' bounds."""
    p = len(names)
    every = _statistics(names, theta, J, residuals, state_blocks, n_states_estimated, tolerance, n_outputs,
                        segment_rows)
    bound = at_bounds(theta, lower, upper, every.std_classical) if lower is not None else np.zeros(p, bool)
    if not bound.any():
        return every
    free = ~bound
    st = _statistics([n for n, f in zip(names, free) if f], theta[free], J[:, free], residuals, state_blocks,
                     n_states_estimated + int(bound.sum()), tolerance, n_outputs, segment_rows)

    def grown(a, fill, square=False):
        out = np.full((p, p) if square else (p,) + a.shape[1:], fill, dtype=a.dtype)
        if square:
            out[np.ix_(free, free)] = a
        else:
            out[free] = a
        return out

    return Statistics(grown(st.std, np.nan), grown(st.ci95, np.nan), grown(st.correlation, np.nan, True),
                      grown(st.identifiable, True), st.singular_values, st.null_directions, st.dof,
                      st.residual_variance, bound, grown(st.std_robust, np.nan), grown(st.ci95_robust, np.nan),
                      st.bandwidth)


def _statistics(names, theta, J, residuals, state_blocks, n_states_estimated, tolerance, n_outputs,
                segment_rows) -> Statistics:
    n, p = residuals.size, len(names)
    dof = max(n - p - n_states_estimated, 1)
    s2 = float(residuals @ residuals) / dof
    if not p:
        e = np.zeros(0)
        return Statistics(e, np.zeros((0, 2)), np.zeros((0, 0)), np.zeros(0, bool), e, [], dof, s2,
                          np.zeros(0, bool), e, np.zeros((0, 2)), 0.0)
    scale = np.where(np.abs(theta) > 0, np.abs(theta), 1.0)
    F = _fisher(J, state_blocks)
    Fs = F * np.outer(scale, scale)
    w, V = np.linalg.eigh((Fs + Fs.T) / 2)
    w = np.clip(w, 0.0, None)
    sv = np.sqrt(w)[::-1]
    V = V[:, ::-1]
    smax = sv[0] if sv.size and sv[0] > 0 else 1.0
    rel = sv / smax
    null = [V[:, i] for i in range(p) if rel[i] < tolerance]
    identifiable = np.ones(p, bool)
    directions = []
    for v in null:
        identifiable &= np.abs(v) <= NULL_COMPONENT
        directions.append({names[j]: float(v[j]) for j in range(p) if abs(v[j]) > NULL_COMPONENT})
    keep = rel >= tolerance
    Vk, wk = V[:, keep], w[::-1][keep]
    cov_s = (Vk / wk) @ Vk.T if keep.any() else np.zeros((p, p))
    cov = s2 * cov_s * np.outer(scale, scale)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    t = t975(dof)  # scipy.stats.t.ppf(0.975, dof) bit for bit, without importing scipy.stats (~1.5 CPU-s a process)
    ci = np.column_stack([theta - t * std, theta + t * std])
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    # the sandwich: the bread is the classical covariance's (without s^2), the meat the scores' long-run variance
    bread = cov_s * np.outer(scale, scale)
    meat, bandwidth = _long_run_variance(J, residuals, state_blocks, n_outputs, segment_rows)
    std_r = np.sqrt(np.clip(np.diag(bread @ meat @ bread), 0, None))
    ci_r = np.column_stack([theta - t * std_r, theta + t * std_r])
    for a in (std, ci, std_r, ci_r):
        a[~identifiable] = np.nan
    corr[~identifiable, :] = np.nan
    corr[:, ~identifiable] = np.nan
    return Statistics(std, ci, corr, identifiable, rel, directions, dof, s2, np.zeros(p, bool), std_r, ci_r,
                      bandwidth)


def _segment_rows(n_rows: int, state_blocks, segment_rows) -> list[tuple[int, int, np.ndarray | None]]:
    """``(start, stop, block)`` of each segment's rows of ``J`` (``segment_rows``:
    each segment's residuals; none given: one segment)."""
    if not segment_rows:
        return [(0, n_rows, None)]
    out, start = [], 0
    blocks = list(state_blocks or []) + [None] * len(segment_rows)
    for n, block in zip(segment_rows, blocks):
        out.append((start, start + n, block))
        start += n
    return out


def _long_run_variance(J: np.ndarray, residuals: np.ndarray, state_blocks, n_outputs: int, segment_rows):
    """``J_p^T Omega J_p`` of the Newey-West estimator (module docstring)
    and its bandwidth ``S``, rows."""
    p = J.shape[1]
    parts = []
    for start, stop, block in _segment_rows(J.shape[0], state_blocks, segment_rows):
        Jp = J[start:stop]
        if block is not None and block.size:  # the initial states projected out: J_p^T J_p is the Schur complement
            Jp = Jp - block @ (np.linalg.pinv(block) @ Jp)
        e = residuals[start:stop]
        rows = e.size // n_outputs
        g = (Jp * e[:, None]).reshape(rows, n_outputs, p).sum(axis=1)
        parts.append((g, e.reshape(rows, n_outputs)))
    # Andrews' AR(1) plug-in over the outputs (their residuals weighted: equal variances), rho from all segments
    rho = np.array([_pooled_lag1([ee[:, k] for _, ee in parts]) for k in range(n_outputs)])
    rho = np.clip(rho, -MAX_RHO, MAX_RHO)
    alpha = float(np.sum(4 * rho ** 2 / ((1 - rho) ** 6 * (1 + rho) ** 2)) / np.sum(1 / (1 - rho) ** 4))
    n = sum(g.shape[0] for g, _ in parts)
    S = 1.1447 * (alpha * n) ** (1 / 3)
    meat = np.zeros((p, p))
    for g, _ in parts:
        meat += g.T @ g
        for lag in range(1, min(int(np.ceil(S)), g.shape[0])):
            w = 1.0 - lag / S
            if w <= 0:
                break
            G = g[lag:].T @ g[:-lag]
            meat += w * (G + G.T)
    return meat, float(S)


def _pooled_lag1(series: list[np.ndarray]) -> float:
    """The lag-one autocorrelation of a residual split into segments: the
    pairs within each segment, about the whole mean."""
    return float(_autocorrelations(series, 1)[0][0])


def _autocorrelations(series: list[np.ndarray], h: int) -> tuple[np.ndarray, np.ndarray]:
    """``(r_k, n_k)``, ``k = 1..h``: the autocorrelations of one residual
    split into segments (about its whole mean, each lag's products summed
    over the pairs within a segment only) and the number of those pairs."""
    mean = np.mean(np.concatenate(series)) if series else 0.0
    cs = [s - mean for s in series]
    denom = sum(float(c @ c) for c in cs)
    r, nk = np.zeros(h), np.zeros(h)
    for k in range(1, h + 1):
        nk[k - 1] = sum(max(c.size - k, 0) for c in cs)
        if denom > 0:
            r[k - 1] = sum(float(c[:-k] @ c[k:]) for c in cs if c.size > k) / denom
    return r, nk


def whiteness(series: list[np.ndarray], lags: int | None = None) -> dict:
    """The Ljung-Box test of one output's residuals, split into segments
    (module docstring): ``{"q", "lags", "p_value"}``. ``lags``: ``h``
    (default ``min(20, n // 5)``, at least 1; Ljung & Box used 20 to 30 lags
    for some hundred points). p-value by ``scipy.special.chdtrc`` (not
    ``scipy.stats``: 1.5 CPU-s to import)."""
    from scipy.special import chdtrc

    n = sum(s.size for s in series)
    h = lags if lags is not None else max(1, min(20, n // 5))
    r, nk = _autocorrelations(series, h)
    ok = nk > 0
    q = float(n * (n + 2) * np.sum(r[ok] ** 2 / nk[ok]))
    return {"q": q, "lags": int(h), "p_value": float(chdtrc(h, q))}


def residual_statistics(names, residuals: np.ndarray, sigma: np.ndarray, segment_rows=None,
                        lags: int | None = None) -> dict:
    """Per output: RMS, mean, standard deviation, largest magnitude, lag-one
    autocorrelation (near 0 for white noise; near 1 when the model misses
    something slow), the noise level used, and the Ljung-Box test
    (:func:`whiteness`, ``{"q", "lags", "p_value"}``) over the segments'
    rows (``segment_rows``: each segment's, default one segment)."""
    bounds = np.cumsum([0] + list(segment_rows or [residuals.shape[0]]))
    out = {}
    for j, name in enumerate(names):
        r = residuals[:, j]
        c = r - r.mean()
        denom = float(c @ c)
        lag1 = float(c[:-1] @ c[1:] / denom) if denom > 0 and r.size > 1 else 0.0
        out[name] = {"rms": float(np.sqrt(np.mean(r ** 2))), "mean": float(r.mean()), "std": float(r.std()),
                     "max_abs": float(np.max(np.abs(r))), "lag1_autocorrelation": lag1, "sigma": float(sigma[j]),
                     "ljung_box": whiteness([r[a:b] for a, b in zip(bounds[:-1], bounds[1:])], lags)}
    return out
