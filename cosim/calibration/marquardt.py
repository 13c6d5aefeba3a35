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

is solved by eliminating the states: the block Cholesky factor of the
block-tridiagonal state part ``H_xx`` (``S`` factors of ``ne x ne``
blocks, ``O(S ne^3)``), the ``nt x nt`` Schur complement ``H_tt - H_tx
H_xx^-1 H_xt``, its solve for ``dtheta``, and the states back-substituted.
(The small blocks go through numpy's LAPACK: scipy's, in the wheel
installed here, took 8 ms of CPU for one 16 x 16 triangular solve on the
loaded machine, numpy's 0.02 ms; its banded Cholesky 0.15 s for 64
unknowns.) Cost and memory grow with the
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
from scipy import sparse

__all__ = ["Result", "levenberg_marquardt", "schur_step", "MESSAGES"]

MESSAGES = {
    -1: "No step: the damped normal equations are not positive definite at any damping.",
    0: "The maximum number of function evaluations is exceeded.",
    1: "`gtol` termination condition is satisfied.",
    2: "`ftol` termination condition is satisfied.",
    3: "`xtol` termination condition is satisfied.",
    4: "Both `ftol` and `xtol` termination conditions are satisfied.",
}
INITIAL_DAMPING = 1e-6  # lambda relative to diag(H) at the start (Marquardt's scaling: invariant to the units)
SHRINK = 0.1  # lambda's largest decrease after a good step (Nielsen's rule caps it at 1/3: below)
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
    damping: float  # lambda at the end (a next run from x may start from it)


def _blocks(Axx, ne: int) -> tuple[np.ndarray, np.ndarray]:
    """The block-tridiagonal ``Axx`` as its diagonal blocks ``D`` (``S x ne x
    ne``) and those above the diagonal ``E`` (``E[i] = A[block i, block
    i + 1]``); entries farther from the diagonal are none (multiple shooting
    couples neighbouring segments only)."""
    S = Axx.shape[0] // ne
    D, E = np.zeros((S, ne, ne)), np.zeros((max(S - 1, 0), ne, ne))
    c = Axx.tocoo() if sparse.issparse(Axx) else sparse.coo_matrix(Axx)
    bi, bj = c.row // ne, c.col // ne
    on = bi == bj
    D[bi[on], c.row[on] % ne, c.col[on] % ne] = c.data[on]
    up = bj == bi + 1
    E[bi[up], c.row[up] % ne, c.col[up] % ne] = c.data[up]
    return D, E


def _block_tridiagonal_solve(D: np.ndarray, E: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``X`` of ``A X = B``, ``A`` symmetric positive definite, block
    tridiagonal (:func:`_blocks`), ``B`` ``S x ne x k``: ``A = L L^T`` with
    ``L_ii = chol(D_i - F_{i-1}^T F_{i-1})``, ``F_i = L_ii^-1 E_i``, then
    forward and back substitution, one block at a time."""
    S = D.shape[0]
    L, F, Y = [], [], []
    for i in range(S):
        Di = D[i] - F[i - 1].T @ F[i - 1] if i else D[i]
        L.append(np.linalg.cholesky(Di))
        if i < S - 1:
            F.append(np.linalg.solve(L[i], E[i]))
        Y.append(np.linalg.solve(L[i], B[i] - F[i - 1].T @ Y[i - 1] if i else B[i]))
    X = [None] * S
    for i in range(S - 1, -1, -1):
        X[i] = np.linalg.solve(L[i].T, Y[i] - F[i] @ X[i + 1] if i < S - 1 else Y[i])
    return np.stack(X)


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
    D, E = _blocks(Axx, ne)
    Y = _block_tridiagonal_solve(D, E, np.column_stack([Atx.T, b[nt:]]).reshape(m // ne, ne, nt + 1))
    Y = Y.reshape(m, nt + 1)
    if nt:
        S = Att - Atx @ Y[:, :nt]
        dt = _symmetric_solve((S + S.T) / 2, b[:nt] - Atx @ Y[:, nt])
        dx = Y[:, nt] - Y[:, :nt] @ dt
    else:
        dt, dx = np.zeros(0), Y[:, 0]
    return np.concatenate([dt, dx])


def _symmetric_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A^-1 b`` of a symmetric positive definite ``A`` by its Cholesky factor (``LinAlgError`` if it is none)."""
    L = np.linalg.cholesky(A)
    return np.linalg.solve(L.T, np.linalg.solve(L, b))


def levenberg_marquardt(fun: Callable[[np.ndarray], np.ndarray], jac: Callable, z0: np.ndarray, lower: np.ndarray,
                        upper: np.ndarray, scale: np.ndarray, nt: int, ne: int, ftol: float, xtol: float,
                        gtol: float, max_nfev: int, damping: float = INITIAL_DAMPING) -> Result:
    """Minimize ``0.5 |fun(z)|^2`` within ``[lower, upper]`` from ``z0``
    (module docstring). ``jac(z)``: the Jacobian at an accepted point, dense
    or sparse, with the layout of :func:`schur_step`; ``scale``: each
    unknown's size (the tolerances ``xtol`` and ``gtol`` are on the unknowns
    divided by it); ``max_nfev``: evaluations of ``fun`` at most;
    ``damping``: the first ``lambda`` (relative to ``diag(H)``). The first
    point's residuals must be finite (the caller's to say why not)."""
    z = np.clip(np.asarray(z0, dtype=float), lower, upper)
    r = fun(z)
    nfev, njev = 1, 0
    cost = 0.5 * float(r @ r)
    lam, nu = damping, 2.0
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
                if lam > 1e30:  # none does (a Jacobian of overflowing entries): not converged, said so
                    status, done = -1, True
                    break
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
                lam = max(lam * max(SHRINK, 1.0 - (2.0 * ratio - 1.0) ** 3), 1e-16)
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
    return Result(z, cost, r, nfev, njev, status, MESSAGES[status], lam)
