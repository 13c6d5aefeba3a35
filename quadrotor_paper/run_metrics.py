"""A run's metrics, taken as its rows stream (:mod:`cosim.loop.recorder`): in
memory that does not grow with the run, and to the bits a reduction over
all its rows gives (:mod:`cosim.loop.online`), so the summary of a run equals the
one recomputed from its results file (:func:`from_results`).

:class:`RunMetrics` of a scenario is an observer of its run
(``Master.run(observers=[...])``): ``add(rows)`` for each block of rows,
:meth:`RunMetrics.values` at the end. It is made of parts, each a small
class with ``signals`` (what it reads), ``add(rows)`` and ``values()``
(name -> float, ``None`` where undefined, e.g. a mean over no rows):

* :class:`Tracking` -- ``[metrics]``: the Euclidean RMSE over every row, the
  largest and the final error (m; Tables 2-3, Fig. 9);
* :class:`Estimation` -- ``[metrics].estimator``: the estimate's NEES, NIS,
  RMSE and bias (docs/estimation.md, E15-E17).

A new metric is one more part (or one more accumulator in a part) and its
name in :data:`quadrotor_paper.experiments.STUDY_METRICS` or
:data:`quadrotor_paper.experiments.ESTIMATION_METRICS`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from cosim.loop.online import ColumnSum, Last, Maximum, Sum, finite

from fmu_models.models.estimator_outputs import COUNTS, COVARIANCE_BLOCKS, covariance_output

from .metrics import nees, squared_error, wrap_angle
from .sections import estimation_spec, metric_signals

__all__ = ["RunMetrics", "Tracking", "Estimation", "BLOCKS", "from_results"]

# The estimate's blocks (docs/estimation.md, E15-E17): the Estimator's outputs (the model's covariance
# blocks), the truth's signals of the plant instance (its wind inputs for the wind), and the unit of the
# block's RMSE.
_UNITS = {"position": "m", "velocity": "mps", "attitude": "rad", "wind": "mps"}
BLOCKS = {block: (states, states, _UNITS[block]) for block, states in COVARIANCE_BLOCKS.items()}
# rows of the truth kept to compare the estimate with the truth at the time it describes (its t_estimate,
# E23): an importer reads the estimate a step or two late; far more than any latency of a real chain
TRUTH_HISTORY = 1024


def _rms(total: Sum) -> float | None:
    """sqrt of the mean of the summed squares (an RMSE; None over no rows)."""
    mean = total.mean()
    return None if mean is None else float(np.sqrt(mean))


class Tracking:
    """Euclidean tracking error e_n = |p*(t_n) - p(t_n)| (m) over every row:
    its RMSE ``sqrt(mean_n e_n^2)`` (Tables 2 and 3), largest and final
    value; ``names`` the three metrics' names (the RMSE alone when only it
    is asked for)."""

    def __init__(self, position: Sequence[str], reference: Sequence[str],
                 names: Sequence[str] = ("rmse_m", "max_error_m", "final_error_m")):
        self.position, self.reference, self.names = list(position), list(reference), tuple(names)
        self.signals = self.position + self.reference
        self._squares, self._max, self._last = Sum(), Maximum(), Last()

    def add(self, rows) -> None:
        squares = squared_error(rows, self.position, self.reference)
        self._squares.add(squares)
        if len(self.names) > 1:
            # |e| from the squares summed once: np.linalg.norm(e, axis=1) of real values is
            # sqrt(add.reduce(e * e, axis=1)), the same bits as euclidean_error without a second pass
            norm = np.sqrt(squares)
            self._max.add(norm)
            self._last.add(norm)

    def values(self) -> dict[str, float | None]:
        out = [_rms(self._squares), self._max.value, self._last.value]
        return dict(zip(self.names, out))


class _Settled:
    """Rows at least ``settle`` s after the start and after the last change
    of a signal (:func:`quadrotor_paper.metrics.settled`), block by block."""

    def __init__(self, settle: float):
        self.settle = settle
        self._t0: float | None = None
        self._previous: np.ndarray | None = None
        self._last_change = -np.inf

    def __call__(self, time: np.ndarray, signal: np.ndarray) -> np.ndarray:
        if self._t0 is None:
            self._t0 = float(time[0])
            first = np.array([True])
        else:
            first = np.array([np.any(signal[0] != self._previous)])
        changed = np.r_[first, np.any(signal[1:] != signal[:-1], axis=1)]
        last_change = np.maximum(np.maximum.accumulate(np.where(changed, time, -np.inf)), self._last_change)
        self._previous, self._last_change = signal[-1].copy(), float(last_change[-1])
        return (time - self._t0 >= self.settle) & (time - last_change >= self.settle)


class Estimation:
    """The estimate's consistency and accuracy over one run (docs/estimation.md,
    E15-E17): per block (position, velocity, attitude, wind) the mean NEES and
    the RMSE of the estimate (Euclidean over the block's three axes; yaw
    wrapped) and the wind's degrees of freedom (``nees_wind_dof``: the
    components it estimates, 2 without a vertical wind state); the mean NIS
    of the fix (over the steps that used one) and of the drag measurement (over the rows where the true wind has been steady
    for ``settle`` s, as the wind's NEES); and the wind RMSE over those rows; the length of the position estimate's
    mean error (its bias) and the RMSE of reference - estimate over the whole
    run (the error the controller sees, beside ``rmse_m``, the true one).
    NEES, NIS and RMSE skip the first ``settle`` s (the filter's convergence
    from its initial guess). Each is ``None`` over no rows (a run shorter
    than ``settle``). The estimate is compared with the truth at the time it
    describes, its ``t_estimate`` (E23: a row ``round((t_estimate - t0) /
    step)``, the same row where the estimator's output is read at its own
    time, an earlier one in an importer that reads it a step later; the last
    :data:`TRUTH_HISTORY` rows of the truth are kept for it). Also the
    estimator's counts of refused measurements and restarts at the end of
    the run (``counts``: :data:`COUNTS`, and the magnetometer's refusals
    for the filter that has one, E19-E21)."""

    def __init__(self, estimator: str, truth: str, settle: float, counts: Sequence[str], reference: Sequence[str],
                 step: float):
        self.estimator, self.truth, self.settle, self.step = estimator, truth, settle, step
        self.signals = []
        for estimated, true, _ in BLOCKS.values():
            self.signals += [f"{truth}.{n}" for n in true] + [f"{estimator}.{n}" for n in estimated]
            self.signals += [f"{estimator}.{covariance_output(a, b, estimated)}" for i, a in enumerate(estimated)
                             for b in estimated[i:]]
        self.signals += [f"{estimator}.{n}" for n in ("nis_fix", "nis_acc", "fix_used", "t_estimate", *counts)]
        self._truth = [f"{truth}.{n}" for _, true, _ in BLOCKS.values() for n in true]
        self._history = np.zeros((0, len(self._truth)))  # the truth's last rows before the block
        self._row = 0  # the index of the block's first row in the run
        self._counts = {c: Last() for c in counts}
        self._t0: float | None = None
        self._wind_settled = _Settled(settle)
        self._nees = {b: Sum() for b in BLOCKS}
        self._squares = {b: Sum() for b in BLOCKS}
        self._wind_settled_squares = Sum()
        self._wind_dof = Maximum()
        self._bias = ColumnSum()
        self._nis_fix, self._nis_acc = Sum(), Sum()
        self._seen = Tracking([f"{estimator}.{e}" for e in BLOCKS["position"][0]], reference, ("rmse_seen_m",))

    def add(self, rows) -> None:
        estimator, truth = self.estimator, self.truth
        t = rows.time
        if self._t0 is None:
            self._t0 = float(t[0])
        after_start = t - self._t0 >= self.settle
        truth_at = self._truth_at_estimate_time(rows)
        steady = after_start
        for block, (estimated, true, _) in BLOCKS.items():
            error = np.column_stack([rows[f"{estimator}.{e}"] - truth_at[f"{truth}.{n}"]
                                     for e, n in zip(estimated, true)])
            if block == "attitude":
                error = wrap_angle(error)
            covariance = np.stack([np.column_stack([rows[f"{estimator}.{covariance_output(a, b, estimated)}"]
                                                    for b in estimated]) for a in estimated], axis=1)
            # the wind's NEES where it is steady: a step of the gust is no random walk (E13), the filter is
            # not consistent through it by construction; its RMSE both ways
            judged = self._wind_settled(t, np.column_stack([truth_at[f"{truth}.{n}"] for n in true])) \
                if block == "wind" else after_start
            self._nees[block].add(nees(error[judged], covariance[judged]))
            self._squares[block].add(np.sum(error[after_start] ** 2, axis=1))
            if block == "wind":
                self._wind_settled_squares.add(np.sum(error[judged] ** 2, axis=1))
                steady = judged
                # its degrees of freedom: the components the filter estimates (a held one, variance exactly 0, is
                # left out of the NEES: a filter without a vertical wind state has 2)
                self._wind_dof.add(np.sum(np.diagonal(covariance[judged], axis1=1, axis2=2) != 0, axis=1))
            if block == "position":  # the estimate's bias: the length of its mean error
                self._bias.add(error[after_start])
        used = rows[f"{estimator}.fix_used"] > 0.5
        self._nis_fix.add(rows[f"{estimator}.nis_fix"][used & after_start])
        # the drag measurement's NIS on the same steady rows as the wind's NEES (E17): through a step of the
        # gust the measurement is refused (its NIS in the thousands) and the wind restarts; those rows judge
        # the gate (outliers_acc, resets_acc), not the filter's consistency
        self._nis_acc.add(rows[f"{estimator}.nis_acc"][steady])
        self._seen.add(rows)  # the tracking error the controller sees, reference - estimate (E18)
        for c, last in self._counts.items():
            last.add(rows[f"{estimator}.{c}"])

    def _truth_at_estimate_time(self, rows) -> dict[str, np.ndarray]:
        """The truth's signals, row by row, at the row of the time the
        estimate describes (``t_estimate``, clipped to the rows kept)."""
        current = np.column_stack([rows[n] for n in self._truth])
        history = np.vstack([self._history, current])
        first = self._row - len(self._history)  # the run's row index of history[0]
        at = np.rint((rows[f"{self.estimator}.t_estimate"] - self._t0) / self.step).astype(np.int64)
        at = np.clip(at, first, self._row + len(current) - 1) - first
        self._history, self._row = history[-TRUTH_HISTORY:], self._row + len(current)
        picked = history[at]
        return {name: picked[:, j] for j, name in enumerate(self._truth)}

    def values(self) -> dict[str, float | None]:
        out: dict[str, float | None] = {}
        for block, (_, _, unit) in BLOCKS.items():
            out[f"nees_{block}"] = self._nees[block].mean()
            out[f"est_rmse_{block}_{unit}"] = _rms(self._squares[block])
            if block == "wind":
                out["est_rmse_wind_settled_mps"] = _rms(self._wind_settled_squares)
                out["nees_wind_dof"] = self._wind_dof.value
            if block == "position":
                bias = self._bias.mean()
                out["est_bias_position_m"] = None if bias is None else float(np.linalg.norm(bias))
                out.update(self._seen.values())
        out["nis_fix"] = self._nis_fix.mean()
        out["nis_acc"] = self._nis_acc.mean()
        out.update((c, last.value) for c, last in self._counts.items())
        return out


class RunMetrics:
    """Every metric of a run of ``scenario``, taken as its rows stream
    (the module says how): pass it to ``Master.run(observers=[...])``, then
    read :meth:`values`."""

    def __init__(self, scenario):
        position, reference = metric_signals(scenario)
        self.parts: list[Any] = [Tracking(position, reference)] if position else []
        spec = estimation_spec(scenario)
        if spec is not None:
            self.parts.append(Estimation(*spec, reference, scenario.step))
        self.signals = list(dict.fromkeys(s for part in self.parts for s in part.signals))
        self.rows = 0

    def add(self, rows) -> None:
        """The next rows (:class:`cosim.loop.recorder.Rows`, or a result that kept them all)."""
        if len(rows.time):
            self.rows += len(rows.time)
            for part in self.parts:
                part.add(rows)

    def values(self) -> dict[str, float | None]:
        """Name -> value; ``None`` where undefined (no rows, a singular
        covariance): JSON ``null``, never NaN."""
        if not self.rows:
            return {}
        return {k: finite(v) for part in self.parts for k, v in part.values().items()}


def from_results(scenario, path: str | Path, block_rows: int = 4096) -> dict[str, float | None]:
    """:meth:`RunMetrics.values` of ``scenario`` recomputed from a results
    file (:func:`cosim.loop.recorder.iter_results`): what the run's summary says."""
    from cosim.loop.recorder import iter_results

    metrics = RunMetrics(scenario)
    for rows in iter_results(path, block_rows):
        metrics.add(rows)
    return metrics.values()
