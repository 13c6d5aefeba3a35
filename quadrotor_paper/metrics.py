"""Tracking metrics of a run.

Euclidean position error e(t_n) = |p*(t_n) - p(t_n)| (m, Fig. 9) and its RMSE
over every communication point of the run, n = 0 .. N (Tables 2 and 3):

    RMSE = sqrt( (1 / (N + 1)) * sum_n |p*(t_n) - p(t_n)|^2 )

State estimation (docs/estimation.md, eqs. E15-E17): the normalized
estimation error squared of a k-vector block with error e_n and the
filter's covariance P_n, ``NEES_n = e_n^T P_n^-1 e_n`` (chi-square with k
degrees of freedom for a consistent filter), and the rows where a signal
has settled (unchanged for ``settle`` seconds).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["position_error", "euclidean_error", "squared_error", "rmse", "pd_share", "oscillation_period", "nees", "settled",
           "wrap_angle"]


def position_error(result, position: Sequence[str], reference: Sequence[str]) -> np.ndarray:
    """p* - p per axis, shape (rows, len(position)) (m)."""
    return np.column_stack([result[r] - result[p] for p, r in zip(position, reference)])


def euclidean_error(result, position: Sequence[str], reference: Sequence[str]) -> np.ndarray:
    """|p* - p| per row (m), the curve of Fig. 9."""
    return np.linalg.norm(position_error(result, position, reference), axis=1)


def squared_error(result, position: Sequence[str], reference: Sequence[str]) -> np.ndarray:
    """|p* - p|^2 per row (m^2), the terms of the RMSE."""
    e = position_error(result, position, reference)
    return np.sum(e * e, axis=1)


def rmse(result, position: Sequence[str], reference: Sequence[str]) -> float:
    """Euclidean RMSE (m) over all recorded rows (NaN without rows), summed as
    a run's streamed metrics sum (:class:`cosim.loop.online.Sum`: numpy's
    ``mean`` to the bit up to its 65 536 values)."""
    from cosim.loop.online import Sum

    total = Sum()
    total.add(squared_error(result, position, reference))
    mean = total.mean()
    return float(np.sqrt(mean)) if mean is not None else float("nan")


def pd_share(tau_c: np.ndarray, tau_n: np.ndarray) -> np.ndarray:
    """|tau_c| / (|tau_c| + |tau_n|): the PD's share of the control effort
    (1 while the FNN has learned nothing, toward 0 once it has taken over)."""
    total = np.abs(tau_c) + np.abs(tau_n)
    return np.divide(np.abs(tau_c), total, out=np.ones_like(total), where=total > 0)


def oscillation_period(x: np.ndarray, step: float, longest: float = 5.0) -> tuple[float, float]:
    """Period (s) of the dominant oscillation of ``x``: the lag of the first
    peak of its autocorrelation after the first zero crossing, with that
    peak's height (1 for a pure oscillation, near 0 when there is none)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    ac = np.correlate(x, x, "full")[len(x) - 1:]
    if ac[0] == 0:
        return float("nan"), 0.0
    ac = ac / ac[0]
    first_zero = int(np.argmax(ac < 0))
    k = first_zero + int(np.argmax(ac[first_zero:first_zero + int(longest / step)]))
    return k * step, float(ac[k])


def nees(error: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """NEES per row (eq. E15): ``e_n^T P_n^-1 e_n`` for errors of shape (N, k)
    and covariances of shape (N, k, k); NaN where P_n is singular. A
    component whose variance is exactly 0 is one the filter holds, not
    estimates (the vertical wind of a filter without that state,
    docs/estimation.md): it is left out of the row's NEES, which then has
    one degree of freedom fewer, when its error is 0, and makes it infinite
    when not (a filter certain of a wrong value)."""
    error, covariance = np.asarray(error, dtype=float), np.asarray(covariance, dtype=float)
    held = np.diagonal(covariance, axis1=1, axis2=2) == 0 if covariance.ndim == 3 else np.zeros(error.shape, bool)
    if np.any(held):
        wrong = np.any(held & (error != 0), axis=1)
        error = np.where(held, 0.0, error)
        covariance = covariance + np.einsum("ni,ij->nij", held.astype(float), np.eye(error.shape[1]))
        out = nees(error, covariance)
        out[wrong] = np.inf
        out[np.all(held, axis=1)] = np.nan  # nothing estimated
        return out
    try:  # every row in one call (LAPACK's gesv per matrix, as row by row below)
        return (error[:, None, :] @ np.linalg.solve(covariance, error[..., None]))[:, 0, 0]  # e @ x as below
    except np.linalg.LinAlgError:  # one singular P: row by row, NaN where singular
        pass
    out = np.full(len(error), np.nan)
    for n, (e, P) in enumerate(zip(error, covariance)):
        try:
            out[n] = float(e @ np.linalg.solve(P, e))
        except np.linalg.LinAlgError:
            pass
    return out


def settled(time: np.ndarray, signal: np.ndarray, settle: float) -> np.ndarray:
    """Rows at least ``settle`` seconds after the start and after the last
    change of ``signal`` (shape (N,) or (N, k)): where an estimate of it may
    be asked to have converged (E17)."""
    time = np.asarray(time, dtype=float)
    signal = np.asarray(signal, dtype=float).reshape(len(time), -1)
    changed = np.r_[True, np.any(signal[1:] != signal[:-1], axis=1)]
    last_change = np.maximum.accumulate(np.where(changed, time, -np.inf))
    return (time - time[0] >= settle) & (time - last_change >= settle) if len(time) else changed


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angle difference wrapped to [-pi, pi) (rad): the error of a yaw estimate."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi
