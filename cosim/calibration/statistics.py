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

from ..summary import t975

__all__ = ["Statistics", "statistics", "residual_statistics", "NULL_COMPONENT"]

NULL_COMPONENT = 0.1  # a parameter with more than this in an undetermined direction is not identifiable


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


def statistics(names, theta: np.ndarray, J: np.ndarray, residuals: np.ndarray, state_blocks,
               n_states_estimated: int, tolerance: float) -> Statistics:
    """The estimates' statistics (module docstring). ``residuals``: the
    weighted output residuals; ``J``: their Jacobian w.r.t. the fitted names."""
    n, p = residuals.size, len(names)
    dof = max(n - p - n_states_estimated, 1)
    s2 = float(residuals @ residuals) / dof
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
    std[~identifiable] = np.nan
    ci[~identifiable] = np.nan
    corr[~identifiable, :] = np.nan
    corr[:, ~identifiable] = np.nan
    return Statistics(std, ci, corr, identifiable, rel, directions, dof, s2)


def residual_statistics(names, residuals: np.ndarray, sigma: np.ndarray) -> dict:
    """Per output: RMS, mean, standard deviation, largest magnitude, lag-one
    autocorrelation (near 0 for white noise; near 1 when the model misses
    something slow), and the noise level used."""
    out = {}
    for j, name in enumerate(names):
        r = residuals[:, j]
        c = r - r.mean()
        denom = float(c @ c)
        lag1 = float(c[:-1] @ c[1:] / denom) if denom > 0 and r.size > 1 else 0.0
        out[name] = {"rms": float(np.sqrt(np.mean(r ** 2))), "mean": float(r.mean()), "std": float(r.std()),
                     "max_abs": float(np.max(np.abs(r))), "lag1_autocorrelation": lag1, "sigma": float(sigma[j])}
    return out
