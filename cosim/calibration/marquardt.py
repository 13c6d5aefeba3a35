"""Levenberg-Marquardt for multiple shooting: the step by the Schur complement of the segments' states.

The unknowns ``z = [theta, x0_1, ..., x0_S]``: ``nt`` fitted names, then
``S`` blocks of ``ne`` estimated initial states. A segment's output rows
touch ``theta`` and its own block; a continuity row between segments ``i``
and ``i + 1`` touches ``theta`` and both blocks. The normal matrix ``H =
J^T J`` is therefore an *arrow* (``theta``'s rows and columns, dense)
around a *block-tridiagonal* state part (half-bandwidth ``2 ne - 1``), as
in bundle adjustment (Triggs et al., "Bundle Adjustment - A Modern
Synthesis", 2000, section 6.1; Nocedal & Wright, "Numerical Optimization",
2nd ed., section 10.3). The damped step

    (H + lambda diag(H)) dz = -g,    g = J^T r

is solved by eliminating the states: the banded Cholesky factor of the
state part ``H_xx`` (``scipy.linalg.cholesky_banded``, ``O(S ne^3)``), the
``nt x nt`` Schur complement ``H_tt - H_tx H_xx^-1 H_xt``, its solve for
``dtheta``, and the states back-substituted. Cost and memory grow with the
log's length, not its square (the sparse ``lsmr`` iterations and the dense
SVD it replaces: hundreds of iterations a step on an ill-conditioned
system, and an SVD of rows x unknowns).

The iteration (Marquardt 1963; the damping update of Nielsen, "Damping
parameter in Marquardt's method", IMM-REP-1999-05): a trial point is taken
where its actual reduction of the cost ``0.5 |r|^2`` is a positive share of
the reduction the linear model predicts; otherwise (also where the
residuals are not finite: a trial point the FMU cannot simulate) it is
rejected and the damping grows (a shorter step). Bounds: the projected
Levenberg-Marquardt method (Kanzow, Yamashita & Fukushima, J. Comput. Appl.
Math. 172, 2004): a variable at a bound whose gradient points out of the box
is held there (its row and column taken out of the step), and every trial
point is projected onto the box. The stopping rules and messages are scipy's
``least_squares``'s (``ftol``, ``xtol``, ``gtol``, ``max_nfev``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import linalg, sparse

__all__ = ["Result", "levenberg_marquardt", "schur_step", "MESSAGES"]

MESSAGES = {
    0: "The maximum number of function evaluations is exceeded.",
    1: "`gtol` termination condition is satisfied.",
    2: "`ftol` termination condition is satisfied.",
    3: "`xtol` termination condition is satisfied.",
    4: "Both `ftol` and `xtol` termination conditions are satisfied.",
}
INITIAL_DAMPING = 1e-3  # lambda relative to diag(H) at the start (Marquardt's scaling: invariant to the units)
DIAGONAL_FLOOR = 1e-12  # diag(H) entries below this share of the largest (in scaled unknowns) are raised to it
ACCEPT = 1e-4  # a trial point is taken when its actual reduction is above this share of the predicted one


@dataclass
class Result:
    """As scipy's ``OptimizeResult`` of ``least_squares``: what the calibrator reads."""

    x: np.ndarray
    cost: float  # 0.5 |r|^2 at x
    fun: np.ndarray
    nfev: int
    njev: int
    status: int  # MESSAGES' keys; > 0: converged
    message: str


def _banded(Hxx, w: int) -> np.ndarray:
    """The symmetric ``Hxx`` in the upper form of ``scipy.linalg.cholesky_banded``
    (``ab[w + i - j, j] = H[i, j]``, ``i <= j``), half-bandwidth ``w``."""
    m = Hxx.shape[0]
    ab = np.zeros((w + 1, m))
    if sparse.issparse(Hxx):
        c = Hxx.tocoo()
        upper = (c.row <= c.col) & (c.col - c.row <= w)
        ab[w + c.row[upper] - c.col[upper], c.col[upper]] = c.data[upper]
    else:
        for k in range(min(w, m - 1) + 1):
            ab[w - k, k:] = np.diagonal(Hxx, k)
    return ab


def schur_step(H, g: np.ndarray, damping: np.ndarray, nt: int, ne: int, free: np.ndarray) -> np.ndarray:
    """The step ``dz`` of ``(H + diag(damping)) dz = -g`` over the ``free``
    unknowns (the others held: ``dz = 0``), by eliminating the states
    (module docstring). ``H``: dense or sparse, the first ``nt`` unknowns the
    fitted names, then blocks of ``ne`` states whose coupling reaches the
    neighbouring block only. Raises ``numpy.linalg.LinAlgError`` where the
    damped matrix is not positive definite (more damping helps)."""
    n = g.size
    A = (sparse.csr_matrix(H) if sparse.issparse(H) else np.asarray(H)).copy()
    held = ~free
    diag = damping.copy()
    if held.any():  # a held unknown: its row and column out, 1 on the diagonal, 0 on the right
        keep = sparse.diags(free.astype(float))
        A = keep @ A @ keep if sparse.issparse(A) else A * np.outer(free, free)
        diag = np.where(held, 1.0, diag)
    b = np.where(free, -g, 0.0)
    if sparse.issparse(A):
        A = (A + sparse.diags(diag)).tocsr()
        Att = A[:nt, :nt].toarray()
        Atx = A[:nt, nt:].toarray()
        Axx = A[nt:, nt:]
    else:
        A = A + np.diag(diag)
        Att, Atx, Axx = A[:nt, :nt], A[:nt, nt:], A[nt:, nt:]
    m = n - nt
    if not m:
        return _symmetric_solve(Att, b)
    w = min(max(2 * ne - 1, 0), m - 1)
    factor = linalg.cholesky_banded(_banded(Axx, w), lower=False, check_finite=False)
    Y = linalg.cho_solve_banded((factor, False), np.column_stack([Atx.T, b[nt:]]), check_finite=False)
    if nt:
        S = Att - Atx @ Y[:, :nt]
        dt = _symmetric_solve((S + S.T) / 2, b[:nt] - Atx @ Y[:, nt])
        dx = Y[:, nt] - Y[:, :nt] @ dt
    else:
        dt, dx = np.zeros(0), Y[:, 0]
    return np.concatenate([dt, dx])


def _symmetric_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    return linalg.cho_solve(linalg.cho_factor(A, check_finite=False), b, check_finite=False)


def levenberg_marquardt(fun: Callable[[np.ndarray], np.ndarray], jac: Callable, z0: np.ndarray, lower: np.ndarray,
                        upper: np.ndarray, scale: np.ndarray, nt: int, ne: int, ftol: float, xtol: float,
                        gtol: float, max_nfev: int) -> Result:
    """Minimize ``0.5 |fun(z)|^2`` within ``[lower, upper]`` from ``z0``
    (module docstring). ``jac(z)``: the Jacobian at an accepted point, dense
    or sparse, with the layout of :func:`schur_step`; ``scale``: each
    unknown's size (the tolerances ``xtol`` and ``gtol`` are on the unknowns
    divided by it); ``max_nfev``: evaluations of ``fun`` at most. The first
    point's residuals must be finite (the caller's to say why not)."""
    z = np.clip(np.asarray(z0, dtype=float), lower, upper)
    r = fun(z)
    nfev, njev = 1, 0
    cost = 0.5 * float(r @ r)
    lam, nu = INITIAL_DAMPING, 2.0
    status = 0
    while nfev < max_nfev:
        J = jac(z)
        njev += 1
        g = np.asarray(J.T @ r).ravel()
        H = (J.T @ J).tocsr() if sparse.issparse(J) else J.T @ J
        d = np.asarray(H.diagonal()).ravel() * scale ** 2
        # Marquardt's damping, diag(H), in the scaled unknowns floored (a column the residuals hardly see)
        damping = np.maximum(d, DIAGONAL_FLOOR * max(float(d.max(initial=0.0)), np.finfo(float).tiny)) / scale ** 2
        # held: at a bound with the descent direction -g pointing out of the box
        held = ((z <= lower) & (g > 0)) | ((z >= upper) & (g < 0))
        if float(np.max(np.abs(np.where(held, 0.0, g)) * scale, initial=0.0)) < gtol:
            status = 1
            break
        done = False
        while nfev < max_nfev:
            try:
                step = schur_step(H, g, lam * damping, nt, ne, ~held)
            except np.linalg.LinAlgError:  # not positive definite to round-off: more damping makes it so
                if lam > 1e30:
                    raise
                lam, nu = lam * nu, 2 * nu
                continue
            z_new = np.clip(z + step, lower, upper)
            step = z_new - z
            predicted = -float(g @ step) - 0.5 * float(step @ (H @ step))
            r_new = fun(z_new)
            nfev += 1
            cost_new = 0.5 * float(r_new @ r_new) if np.isfinite(r_new).all() else np.inf
            reduction = cost - cost_new
            ratio = reduction / predicted if predicted > 0 else (1.0 if reduction == 0 == predicted else -1.0)
            step_norm = float(np.linalg.norm(step / scale))
            if reduction > 0 and ratio > ACCEPT:
                ftol_met = reduction < ftol * cost and ratio > 0.25
                xtol_met = step_norm < xtol * (xtol + float(np.linalg.norm(z_new / scale)))
                z, r, cost = z_new, r_new, cost_new
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
                nu = 2.0
                if ftol_met or xtol_met:
                    status = 4 if ftol_met and xtol_met else (2 if ftol_met else 3)
                    done = True
                break
            # rejected: more damping, a shorter step; a step too small to change anything ends the fit (xtol)
            if step_norm < xtol * (xtol + float(np.linalg.norm(z / scale))):
                status, done = 3, True
                break
            lam, nu = lam * nu, 2 * nu
        if done:
            break
    return Result(z, cost, r, nfev, njev, status, MESSAGES[status])
