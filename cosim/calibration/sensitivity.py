"""Forward sensitivities of a segment's outputs to the unknowns.

With the Jacobians of the right-hand side at each row (:meth:`~cosim.calibration.model.LogModel.jacobians_at`),
the sensitivity ``S = dx/d(theta, x0)`` of the states obeys the variational
equation ``dS/dt = A(t) S + G(t)``, ``S(t_0) = [0, I]`` (the initial state's
own columns, where it is estimated), carried along the log from row to
row: over a step ``h`` the trapezoidal Magnus step

    [S_{k+1}; I] = expm(h/2 [[A_k + A_{k+1}, G_k + G_{k+1}], [0, 0]]) [S_k; I]

(second order in ``h``; it needs the Jacobians at the rows only, where the
trajectory gives the states, and is exact for a linear time-invariant
model). The outputs' sensitivity is ``dy_k = C_k S_k + [D_k, 0]``.

The trajectory itself comes from the FMU's own integrator, so the
sensitivities describe it to the Magnus step's order: they steer the
solver and give the statistics; the estimates are where the residuals,
computed exactly, are least.

Where the FMU provides no directional derivatives (or ``jacobian =
"differences"``), :func:`differences` gives the Jacobian of the residuals by
central differences of whole simulations, with the error estimate
``max |J(h) - J(2 h)|``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["segment_sensitivities", "expm_batch"]


def expm_batch(M: np.ndarray) -> np.ndarray:
    """``exp(M_k)`` of a stack of small matrices (``k x n x n``) by scaling
    and squaring their Taylor series to order 8 (truncation below 1e-16
    relative once the scaled norm is at most 0.25), all at once: one row's
    matrices cost numpy's call overhead only once a stack."""
    norm = float(np.max(np.sum(np.abs(M), axis=2), initial=0.0))
    if not np.isfinite(norm):  # the Jacobians overflowed (a trial point near escape): not finite, for the solver
        return np.full(M.shape, np.nan)  # to take its fallback (solve.py), not an OverflowError here
    s = max(0, int(np.ceil(np.log2(norm / 0.25)))) if norm > 0.25 else 0
    A = M / (2.0 ** s)
    eye = np.broadcast_to(np.eye(M.shape[1]), M.shape)
    E = eye.copy()
    for k in range(8, 0, -1):  # Horner: I + A/1 (I + A/2 (I + ... ))
        E = eye + np.matmul(A, E) / k
    for _ in range(s):
        E = np.matmul(E, E)
    return E


def segment_sensitivities(model, theta: np.ndarray, seg, traj, estimated: np.ndarray, stride: int = 1):
    """``(dY, dX_end)`` of one segment: ``dY`` rows x outputs x unknowns
    (the fitted names, then the estimated initial states ``estimated``, a
    boolean mask over the states), ``dX_end`` the end state's (None if the
    segment ends the log).

    ``stride``: the Jacobians are evaluated at every ``stride``-th row (and
    the last), the Magnus step taken between them, the sensitivities of the
    rows between interpolated linearly: ``stride`` times fewer FMU calls for
    a Jacobian that is second order in ``stride h`` (the solver's iterations;
    the statistics take ``stride = 1``)."""
    p = model.problem
    nx, nt = len(model.states), len(p.fit)
    ne = int(estimated.sum())
    n_rows = seg.last - seg.first
    steps = traj.states.shape[0] - 1
    t = model.times
    model.start_probes(theta, float(t[0]))
    ny = len(p.outputs)
    at = np.unique(np.concatenate([np.arange(0, steps + 1, max(int(stride), 1)), [steps]]))
    m = at.size
    rows = seg.first + at
    A, G, C, D = model.jacobians_at(theta, t[rows], traj.states[at],
                                    p.input_values[rows] if p.inputs else np.zeros((m, 0)))
    h = np.diff(t[seg.first + at])[:, None, None]
    M = np.zeros((m - 1, nx + nt, nx + nt))
    M[:, :nx, :nx] = 0.5 * h * (A[:-1] + A[1:])
    M[:, :nx, nx:] = 0.5 * h * (G[:-1] + G[1:])
    E = expm_batch(M) if m > 1 else M
    Phi, Gam = E[:, :nx, :nx], E[:, :nx, nx:]
    S = np.zeros((m, nx, nt + ne))
    S[0][np.flatnonzero(estimated), nt + np.arange(ne)] = 1.0
    for q in range(m - 1):
        S[q + 1] = Phi[q] @ S[q]
        S[q + 1, :, :nt] += Gam[q]
    Y = np.matmul(C, S)
    Y[:, :, :nt] += D
    if m == steps + 1:
        dY = Y[:n_rows]
    else:  # the rows between: linear interpolation of the output sensitivities
        rows = np.arange(n_rows)
        q = np.clip(np.searchsorted(at, rows, side="right") - 1, 0, m - 2)
        w = ((rows - at[q]) / (at[q + 1] - at[q]))[:, None, None]
        dY = (1 - w) * Y[q] + w * Y[q + 1]
    return dY, (S[-1] if steps == n_rows else None)
