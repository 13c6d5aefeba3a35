"""The weighted least-squares fit over segments (:mod:`~cosim.calibration.marquardt`).

Unknowns: the fitted names (parameters, then constant inputs) and, per
segment, the initial states that are estimated (``initial_states =
"estimated"``, or states the log lacks). Residuals, each divided by its
output's noise level ``sigma``: every compared output at every fitted row,
``(y_model - y_log) / sigma``; and, for states the log lacks, the
continuity of consecutive segments, ``(x_end(i) - x_start(i + 1)) / scale``
(multiple shooting). Bounds: the fitted names' ``min``/``max``; an
estimated initial state's, its variable's and the parameter's that starts
it (the tighter: a state the FMU refuses to start from is never tried).

``sigma`` per output: the settings' ``noise``, else two passes: the first
with each output's spread over the log, the second from the first's
residuals (each output's RMS residual): the estimate of the noise that the
statistics then use.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from scipy import sparse

from ..errors import CosimError, FmuCallError, FmuError, ScenarioError, SimulationTerminated
from .marquardt import INITIAL_DAMPING, levenberg_marquardt
from .model import LogModel, REL_STEP
from .problem import _float
from .segments import Segment
from .sensitivity import segment_sensitivities

__all__ = ["Fit", "fit", "CONTINUITY_WEIGHT"]

CONTINUITY_WEIGHT = 1e3  # continuity residuals weigh this much more than one output sample (per state scale)

COARSE_TOLERANCE = 1e-8  # the iterations with Jacobians at every stride-th row stop here; exact ones go on
COARSE_EVALUATIONS = 20  # at most this many simulations with them (their convergence is linear near the optimum)
METHODS = {"casadi": "forward sensitivities (CasADi, the model's own definition)",
           "derivatives": "forward sensitivities (directional derivatives)", "differences": "central differences"}
_MODEL: LogModel | None = None  # a worker process's model: its copy, pickled to it once (_Workers)


def _simulated(model: LogModel, theta, s: Segment, x0):
    """The segment's trajectory, or why the FMU cannot make it at ``theta``
    (an :class:`~cosim.errors.FmuError`: a refused step, a Model Exchange
    solver's failure, the FMU asking to terminate; or a trajectory that is
    not finite), for :meth:`_Problem.simulate` to reject."""
    try:
        tr = model.simulate(theta, s, x0)
    except (FmuCallError, SimulationTerminated) as exc:
        return exc
    finite = np.isfinite(tr.states).all(axis=1)
    finite[:len(tr.outputs)] &= np.isfinite(tr.outputs).all(axis=1)
    if not finite.all():
        t = float(model.times[s.first + int(np.argmin(finite))])
        return FmuCallError(model.cs.name, model.cs.path, f"at t = {t:.4f} s: the trajectory is not finite (NaN or "
                                                          f"infinite outputs or states)")
    return tr


def _fmu_name(exc: FmuError) -> str:
    return Path(exc.path).name if exc.path else exc.instance


def _named(names, theta) -> str:
    return ", ".join(f"{n} = {float(v):.6g}" for n, v in zip(names, theta))


def _finite(J) -> bool:
    return bool(np.isfinite(J.data if sparse.issparse(J) else J).all())


def _simulate_part(job):
    theta, part = job
    return [_simulated(_MODEL, theta, s, x0) for s, x0 in part]


def _sensitivities_part(job):
    theta, part, estimated, stride = job
    out = [segment_sensitivities(_MODEL, theta, s, tr, estimated, stride) for s, tr in part]
    return out, _MODEL.derivative_error


def _start_worker(model: LogModel) -> None:
    """A worker process's start (:class:`_Workers`): its model, closed when the worker leaves."""
    from multiprocessing.util import Finalize

    global _MODEL
    _MODEL = model
    # not atexit: a worker process leaves by os._exit after multiprocessing's finalizers only (its FMU
    # instances freed, their extracted folders removed)
    Finalize(model, _close_worker, (model,), exitpriority=10)


def _close_worker(model: LogModel) -> None:
    model.close()
    model.cs.close()


class _Workers:
    """Segments shared by ``n`` worker processes (:func:`cosim.executor.parallel`),
    each holding its own copy of the model with its own FMU instances (an
    FMU instance is memory of its process), pickled to it once when it
    starts (:meth:`~cosim.calibration.model.LogModel.__reduce__`): a task
    carries the point and its segments only. Segment ``i`` goes to part
    ``i mod n``; the results come back in order."""

    def __init__(self, model: LogModel, n: int):
        import contextlib

        from ..executor import parallel

        self.n = n
        self._workers = contextlib.ExitStack()
        self.pool = self._workers.enter_context(parallel("processes", n, initializer=_start_worker,
                                                         initargs=(model,), name="cosim-fit"))

    def _parts(self, items):
        return [items[k::self.n] for k in range(self.n)]

    def _merge(self, parts, total):
        out = [None] * total
        for k, part in enumerate(parts):
            out[k::self.n] = part
        return out

    def simulate(self, theta, segments, x0):
        parts = self._parts(list(zip(segments, x0)))
        results = self.pool.map(_simulate_part, [(theta, part) for part in parts])
        return self._merge(results, len(segments))

    def sensitivities(self, theta, segments, trajs, estimated, stride):
        parts = self._parts(list(zip(segments, trajs)))
        results = self.pool.map(_sensitivities_part, [(theta, part, estimated, stride) for part in parts])
        error = max(r[1] for r in results)
        return self._merge([r[0] for r in results], len(segments)), error

    def close(self):
        self._workers.close()


@dataclass
class Fit:
    """The solver's result and what the statistics need."""

    theta: np.ndarray  # fitted names
    x0: np.ndarray  # segments x states: each segment's initial state
    estimated: np.ndarray  # mask over states: estimated per segment
    sigma: np.ndarray  # per output
    residuals: list  # per segment: rows x outputs, y_model - y_log (unweighted)
    jacobian: np.ndarray  # the weighted residuals' Jacobian (dense) at the optimum, output rows only
    jacobian_state_blocks: list  # per segment: its rows' columns of its estimated states
    converged: bool
    message: str
    evaluations: int
    cost: float
    method: str
    error_estimate: float
    history: list = field(default_factory=list)
    compile_seconds: float = 0.0  # the CasADi way's C generated and compiled in this run (0: found in the cache)


class _Problem:
    """Residuals and Jacobian of the unknown vector ``z = [theta, x0 of each segment (estimated states)]``."""

    def __init__(self, model: LogModel, segments: list[Segment], estimated: np.ndarray, x0_log: np.ndarray,
                 sigma: np.ndarray, method: str, progress: Callable | None, workers: "_Workers | None" = None,
                 symbolic=None):
        self.model, self.segments, self.estimated = model, segments, estimated
        self.symbolic = symbolic  # cosim.calibration.symbolic.SymbolicModel: the model's own CasADi definition
        self.workers = workers
        self.stride = 1  # rows between Jacobian evaluations (cosim.calibration.sensitivity)
        self.x0_log, self.sigma = x0_log, sigma
        p = model.problem
        self.nt, self.ne = len(p.fit), int(estimated.sum())
        self.method = method
        self.progress = progress
        self.cache: dict = {}
        self.evaluations = 0
        self.scale_x = np.maximum(np.abs(x0_log).max(axis=0), 1.0) if x0_log.size else np.ones(0)
        self.continuity = [i for i in range(len(segments) - 1)] if self.ne else []
        self.error_estimate = 0.0
        self._last_jacobian = (None, None)

    def split(self, z):
        theta = z[:self.nt]
        x0 = self.x0_log.copy()
        if self.ne:
            x0[:, self.estimated] = z[self.nt:].reshape(len(self.segments), self.ne)
        return theta, x0

    def simulate(self, z):
        key = z.tobytes()
        if key not in self.cache:
            theta, x0 = self.split(z)
            self.cache.clear()
            if self.symbolic is not None:
                done = self.symbolic.simulate(theta, self.segments, x0)
            elif self.workers is not None:
                done = self.workers.simulate(theta, self.segments, list(x0))
            else:
                done = [_simulated(self.model, theta, s, x0[i]) for i, s in enumerate(self.segments)]
            trajs = []
            for s, tr in zip(self.segments, done):
                if isinstance(tr, FmuError):
                    if not self.evaluations:  # the first guess: nothing to fall back on; the user's input to change
                        raise ScenarioError(f"the first guess {_named(self.model.problem.fit, theta)}: "
                                            f"{_fmu_name(tr)} cannot simulate it: "
                                            f"{tr.reason}") from None
                    # a trial point the FMU cannot simulate (refused, its solver failed, not finite): infinite
                    # residuals, which the solver rejects (its damping grows: a shorter step), as a step into a
                    # region the model cannot fly; the one place every way (serial, workers, CasADi) meets it
                    tr = self._failed(s)
                trajs.append(tr)
            self.cache[key] = trajs
            self.evaluations += 1
        return self.cache[key]

    def _failed(self, s):
        from .model import Trajectory

        nx, ny = len(self.model.states), len(self.model.problem.outputs)
        steps = (s.last - s.first) if s.last < self.model.times.size else (s.last - s.first - 1)
        return Trajectory(np.full((steps + 1, nx), np.inf), np.full((s.last - s.first, ny), np.inf))

    def residuals(self, z) -> np.ndarray:
        trajs = self.simulate(z)
        p = self.model.problem
        parts = [((tr.outputs - p.output_values[s.first:s.last]) / self.sigma).ravel()
                 for s, tr in zip(self.segments, trajs)]
        if self.continuity:
            _, x0 = self.split(z)
            for i in self.continuity:
                d = (trajs[i].states[-1] - x0[i + 1])[self.estimated] / self.scale_x[self.estimated]
                parts.append(CONTINUITY_WEIGHT * d)
        return np.concatenate(parts)

    def jacobian(self, z):
        """The residuals' Jacobian at an accepted point ``z``. The coarse one
        (``stride > 1``: one RK4 step, or one Magnus step, over several
        rows) can overflow where the trajectory itself does not (a stiff
        trial point: measured on the plant with ``Ix`` at a tenth and ``b``
        30 times the truth); the exact one is taken there. An exact Jacobian
        that is not finite (the sensitivities of a finite trajectory
        overflow along a segment: measured on VanDerPol's forward Euler at
        ``mu = 44``, whose continuous-time variational equation grows
        where the discrete trajectory does not) is taken by central
        differences of the trajectories; where those are not finite either,
        the solver has no direction: one line, naming the point."""
        key = (z.tobytes(), self.stride)
        if self._last_jacobian[0] != key:
            J = self._jacobian(z)
            if not _finite(J) and self.stride > 1:
                stride, self.stride = self.stride, 1
                try:
                    J = self._jacobian(z)
                finally:
                    self.stride = stride
            if not _finite(J) and self.method != "differences":
                J = self._differences(z)  # the trajectories are finite there: their differences may be
            if not _finite(J):
                theta, _ = self.split(z)
                where = f"at {_named(self.model.problem.fit, theta)}: the residuals' Jacobian is not finite"
                if self.evaluations <= 1:  # the first guess: the user's to change
                    raise ScenarioError(f"the first guess: {where}")
                raise FmuCallError(self.model.cs.name, self.model.cs.path,
                                   f"{where}; shorter segments (--segment) or bounds on the fitted names keep "
                                   f"the solver away from there")
            self._last_jacobian = (key, J)
        return self._last_jacobian[1]

    def _jacobian(self, z):
        if self.method == "differences":
            return self._differences(z)
        theta, x0 = self.split(z)
        trajs = self.simulate(z)
        nt, ne = self.nt, self.ne
        if self.symbolic is not None:  # exact: CasADi's forward mode through the trajectory
            done = self.symbolic.sensitivities(theta, self.segments, x0, self.estimated, coarse=self.stride > 1)
            self.error_estimate = 0.0
        elif self.workers is not None:
            done, self.error_estimate = self.workers.sensitivities(theta, self.segments, trajs, self.estimated,
                                                                   self.stride)
        else:
            done = [segment_sensitivities(self.model, theta, s, tr, self.estimated, self.stride)
                    for s, tr in zip(self.segments, trajs)]
            self.error_estimate = self.model.derivative_error
        blocks = [dY / self.sigma[None, :, None] for dY, _ in done]
        ends = [dX for _, dX in done]
        return self._assemble(blocks, ends)

    def _assemble(self, blocks, ends):
        """The residuals' Jacobian from each segment's output sensitivities
        (``blocks``) and end-state sensitivities (``ends``): dense without
        estimated states; with them, block-sparse (a segment's rows touch the
        fitted names and its own initial state; a continuity row also the
        next segment's), built as CSR at once from the blocks' arrays, the
        columns of each row in ascending order."""
        nt, ne, nseg = self.nt, self.ne, len(self.segments)
        if not ne:
            return np.concatenate([b.reshape(-1, nt) for b in blocks])
        theta_cols = np.arange(nt)
        values, columns = [], []
        for i, b in enumerate(blocks):
            flat = b.reshape(-1, nt + ne)
            values.append(flat)
            columns.append(np.broadcast_to(np.concatenate([theta_cols, nt + i * ne + np.arange(ne)]), flat.shape))
        weight = CONTINUITY_WEIGHT / self.scale_x[self.estimated]
        for i in self.continuity:
            dX = ends[i][self.estimated] / self.scale_x[self.estimated, None] * CONTINUITY_WEIGHT
            values.append(np.column_stack([dX, -weight]))
            cols = np.concatenate([theta_cols, nt + i * ne + np.arange(ne)])
            columns.append(np.column_stack([np.broadcast_to(cols, dX.shape), nt + (i + 1) * ne + np.arange(ne)]))
        widths = np.concatenate([np.full(v.shape[0], v.shape[1]) for v in values])
        indptr = np.concatenate([[0], np.cumsum(widths)])
        data = np.concatenate([v.ravel() for v in values])
        indices = np.concatenate([c.ravel() for c in columns])
        J = sparse.csr_matrix((data, indices, indptr), shape=(widths.size, nt + ne * nseg))
        J.eliminate_zeros()  # as the block matrices built it (an exact 0 is no entry)
        return J

    def _differences(self, z):
        """Central differences of the residuals (columns of the estimated
        states moved in every segment at once: a segment's residuals depend
        on its own start only), with the error estimate of h against 2h."""
        r0 = self.residuals(z)
        p = self.model.problem
        scales = np.maximum(np.abs(z), 1e-300)
        if p.defaults:
            for j, name in enumerate(p.fit):
                scales[j] = max(scales[j], abs(p.defaults[name]))
        rel_step = self.model.difference_step
        if rel_step != REL_STEP and self.ne:  # a solver's error: a state near 0 moved by its scale's step
            scales[self.nt:] = np.maximum(scales[self.nt:], np.tile(self.scale_x[self.estimated], len(self.segments)))
        groups = [[j] for j in range(self.nt)]
        groups += [[self.nt + i * self.ne + e for i in range(len(self.segments))] for e in range(self.ne)]
        J = np.zeros((r0.size, z.size))
        err = 0.0
        lower, upper = self.bounds()
        for group in groups:
            cols = {}
            for factor in (1.0, 2.0):
                h = factor * rel_step * scales[group]
                zp, zm = z.copy(), z.copy()
                zp[group] += h
                zm[group] -= h
                over, under = zp[group] > upper[group], zm[group] < lower[group]
                zp[group] = np.where(over, z[group], zp[group])
                zm[group] = np.where(under, z[group], zm[group])
                diff = self.residuals(zp) - self.residuals(zm)
                cols[factor] = (diff, zp[group] - zm[group])
            for which, j in enumerate(group):
                rows = self._rows_of(j)
                c1 = cols[1.0][0][rows] / cols[1.0][1][which]
                c2 = cols[2.0][0][rows] / cols[2.0][1][which]
                J[rows, j] = c1
                err = max(err, float(np.max(np.abs(c1 - c2), initial=0.0)))
            if group[0] >= self.nt and self.continuity:
                self._continuity_columns(J, group, *cols[1.0])
        self.error_estimate = err
        return sparse.csr_matrix(J) if self.ne else J

    def _continuity_base(self) -> int:
        return sum((s.last - s.first) for s in self.segments) * len(self.model.problem.outputs)

    def _rows_of(self, j):
        """The residual rows column ``j`` of z touches through a simulation:
        all of them for a fitted name; for a segment's estimated state, the
        segment's outputs and the continuity at its end (the continuity at
        its start holds the state itself: :meth:`_continuity_columns`)."""
        if j < self.nt:
            return slice(None)
        i = (j - self.nt) // self.ne
        ny = len(self.model.problem.outputs)
        seg = self.segments[i]
        start = sum((s.last - s.first) * ny for s in self.segments[:i])
        rows = np.arange(start, start + (seg.last - seg.first) * ny)
        if i in self.continuity:
            base = self._continuity_base() + self.continuity.index(i) * self.ne
            rows = np.concatenate([rows, np.arange(base, base + self.ne)])
        return rows

    def _continuity_columns(self, J, group, diff, dz) -> None:
        """The continuity rows of one estimated state's columns (``group``:
        that state in every segment, moved at once by ``dz``, the residuals
        moving by ``diff``). The continuity ``W (x_end(k) - x_start(k + 1)) /
        scale`` moved both ``x_start(k + 1)``, exactly (``-W / scale`` on the
        state's own row), and ``x_end(k)`` through segment ``k``'s simulation:
        the first is taken out of the difference, and is segment ``k + 1``'s
        column there."""
        e = group[0] - self.nt
        weight = CONTINUITY_WEIGHT / self.scale_x[self.estimated][e]
        base = self._continuity_base()
        for c, k in enumerate(self.continuity):
            block = np.arange(base + c * self.ne, base + (c + 1) * self.ne)
            moved = diff[block].copy()
            moved[e] += weight * dz[k + 1]
            J[block, group[k]] = moved / dz[k]
            J[block, group[k + 1]] = 0.0
            J[block[e], group[k + 1]] = -weight

    def bounds(self):
        p = self.model.problem
        lo, hi = state_bounds(self.model)
        n = len(self.segments)
        return (np.concatenate([p.lower, np.tile(lo[self.estimated], n)]),
                np.concatenate([p.upper, np.tile(hi[self.estimated], n)]))


def state_bounds(model: LogModel) -> tuple[np.ndarray, np.ndarray]:
    """Each state's ``min`` and ``max``: its variable's and, where a
    parameter starts it (``<state>_0``, Co-Simulation), that parameter's, the
    tighter of the two (the plant's ``Omega_r_1`` has none, ``Omega_r_1_0``
    has ``min = 0``: a fit that drove it to -1185 ended in the FMU's
    refusal, issue 42); ``-inf``/``inf`` where none is declared."""
    variables = model.cs.variables
    lo, hi = np.full(len(model.states), -np.inf), np.full(len(model.states), np.inf)
    for j, s in enumerate(model.states):
        for name in (s, model.setters.get(s)):
            v = variables.get(name) if name else None
            if v is not None:
                lo[j] = max(lo[j], _float(v.min, -np.inf))
                hi[j] = min(hi[j], _float(v.max, np.inf))
    return lo, hi


def _spread(values: np.ndarray) -> np.ndarray:
    s = values.std(axis=0)
    return np.where(s > 0, s, np.maximum(np.abs(values).max(axis=0), 1.0))


def fit(model: LogModel, segments: list[Segment], estimated: np.ndarray, x0_log: np.ndarray,
        noise: dict[str, float], method: str, max_iterations: int, tolerance: float,
        progress: Callable[[int, int], None] | None = None, workers: int = 1, stride: int = 1,
        symbolic=None) -> Fit:
    """The weighted least-squares estimate (module docstring); ``workers``
    processes share the segments (forward sensitivities only); ``stride``:
    the solver's iterations evaluate the Jacobians at every ``stride``-th row
    (:func:`~cosim.calibration.sensitivity.segment_sensitivities`), the
    statistics' Jacobian at the optimum at every row. ``symbolic``: a
    :class:`~cosim.calibration.symbolic.SymbolicModel` (``method =
    "casadi"``): the segments and their exact sensitivities from the model's
    CasADi definition, in ``workers`` threads (``stride > 1``: the first
    iterations with the sensitivities of one RK4 step a row)."""
    pool = None
    if symbolic is not None:
        pass  # its segments run in threads: no processes
    elif workers > 1 and len(segments) > 1 and method != "differences":
        pool = _Workers(model, min(workers, len(segments)))
    try:
        return _fit(model, segments, estimated, x0_log, noise, method, max_iterations, tolerance, progress, pool,
                    stride, symbolic)
    finally:
        if pool is not None:
            pool.close()


def _fit(model, segments, estimated, x0_log, noise, method, max_iterations, tolerance, progress, pool,
         stride, symbolic) -> Fit:
    p = model.problem
    rows = np.concatenate([np.arange(s.first, s.last) for s in segments])
    sigma = _spread(p.output_values[rows])
    given = np.array([o in noise for o in p.outputs])
    for i, o in enumerate(p.outputs):
        if o in noise:
            sigma[i] = noise[o]
    z = np.concatenate([p.guess, x0_log[:, estimated].ravel()])
    passes = 1 if given.all() else 2
    done = [0]
    total = max_iterations * passes

    def report(*_):
        done[0] += 1
        if progress is not None:
            progress(min(done[0], total), total)

    result, prob = None, None
    damping = INITIAL_DAMPING
    for n in range(passes):
        prob = _Problem(model, segments, estimated, x0_log, sigma, method, progress, pool, symbolic)
        lo, hi = prob.bounds()
        z = np.clip(z, lo, hi)
        scale = np.where(np.abs(z) > 0, np.abs(z), 1.0)
        # an estimated state is scaled by its state's size over the log, not by its first guess: a state logged
        # near 0 (an angle, a rate) would otherwise be scaled by its noise (the tolerances xtol and gtol are on
        # the scaled unknowns)
        scale[prob.nt:] = np.tile(prob.scale_x[estimated], len(segments))

        def jac(zz):
            report()
            return prob.jacobian(zz)

        def solve(max_nfev, tol):  # each run from the damping the last one ended with (near the optimum: small)
            return levenberg_marquardt(prob.residuals, jac, z, lo, hi, scale, prob.nt, prob.ne, ftol=tol, xtol=tol,
                                       gtol=tol, max_nfev=max_nfev, damping=damping)

        used = 0
        # the first of two passes gives the noise levels only (each output's RMS residual, wanted to a few
        # digits): it ends where the coarse Jacobians converge (1e-8), the second is the estimate. Where they do
        # not, the exact ones finish it at 1e-8: on a log the model meets exactly through the generic way's
        # Magnus step the coarse ones converged linearly (20 simulations left the 6 s log's residuals 1e-6 of
        # its spread: a second pass), the exact ones reach round-off (the first weights stay)
        weights_only = n == 0 and passes == 2
        if stride > 1:  # the coarse Jacobians bring the iterate near the optimum, the exact ones finish
            prob.stride = stride
            result = solve(min(max_iterations, COARSE_EVALUATIONS), max(tolerance, COARSE_TOLERANCE))
            z, used, damping = result.x, result.nfev, result.damping
        prob.stride = 1
        if used < max_iterations and not (weights_only and stride > 1 and result.status > 0):
            result = solve(max_iterations - used, max(tolerance, COARSE_TOLERANCE) if weights_only else tolerance)
        z, damping = result.x, result.damping
        if n == 0 and passes == 2:
            r = prob.residuals(z).copy()
            ny = len(p.outputs)
            out = r[:rows.size * ny].reshape(-1, ny) * sigma
            rms = np.sqrt(np.mean(out ** 2, axis=0))
            floor = 1e-9 * _spread(p.output_values[rows])
            if np.all(rms <= floor):  # the model meets the log (noise-free): the first weights stay
                break
            sigma = np.where(given, sigma, np.maximum(rms, floor))
    theta, x0 = prob.split(z)
    prob.stride = 1
    J = prob.jacobian(z)
    trajs = prob.simulate(z)
    resid = [tr.outputs - p.output_values[s.first:s.last] for s, tr in zip(segments, trajs)]
    n_out = rows.size * len(p.outputs)
    Jout = J[:n_out]  # sparse with estimated states: each block taken dense, never the whole (rows x unknowns)
    nt, ne = prob.nt, prob.ne
    dense = (lambda a: a.toarray()) if sparse.issparse(Jout) else (lambda a: a)  # noqa: E731
    state_blocks = []
    start = 0
    for i, s in enumerate(segments):
        n = (s.last - s.first) * len(p.outputs)
        state_blocks.append(dense(Jout[start:start + n, nt + i * ne:nt + (i + 1) * ne]) if ne else None)
        start += n
    converged = bool(result.status > 0)
    return Fit(theta, x0, estimated, sigma, resid, dense(Jout[:, :nt]), state_blocks, converged, result.message,
               prob.evaluations, float(result.cost),
               METHODS[method] + (f", run by {symbolic.source}" if symbolic is not None and
                                  symbolic.source != "compiled" else ""), prob.error_estimate,
               compile_seconds=symbolic.compile_seconds if symbolic is not None else 0.0)
