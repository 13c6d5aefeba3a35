"""One run with its files, and what the paper's studies measure.

Every multi-run command (``table2``, ``table3``, ``reproduce``, ``sweep``)
and every one-off analysis that flies missions is a study
(:mod:`cosim.study`) run by :func:`measure`: the engine's runner, in this
process or on Dask, recording only the signals the metrics read, each row
measured by :func:`study_metrics` (Euclidean RMSE, largest and final error
between the ``[metrics]`` signals). :func:`run_once` is the single run of
``fnn-cosim run`` and of the figures, with its results CSV.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

from cosim.errors import FmuError, ScenarioError
from cosim.scenario import Scenario, build_master, fmu_error_in_scenario
from cosim.limits import WORKER_TIMEOUT

if TYPE_CHECKING:
    from cosim.study import Study
    from cosim.study_run import StudyResult

import numpy as np

from .metrics import euclidean_error, nees, rmse, settled, wrap_angle
from .missions import controller_variant, estimation_spec, metric_signals

__all__ = ["run_once", "run_summary", "measure", "study_metrics", "STUDY_METRICS", "ESTIMATION_METRICS",
           "study_metric_names", "lean_signals", "estimation_signals", "estimation_metrics"]

# The estimate's blocks (docs/estimation.md, E15-E17): the Estimator's outputs, the truth's signals of the
# plant instance (its wind inputs for the wind), and the unit of the block's RMSE.
_BLOCKS = {
    "position": (("x", "y", "z"), ("x", "y", "z"), "m"),
    "velocity": (("u", "v", "w"), ("u", "v", "w"), "mps"),
    "attitude": (("phi", "theta", "psi"), ("phi", "theta", "psi"), "rad"),
    "wind": (("wind_x", "wind_y", "wind_z"), ("wind_x", "wind_y", "wind_z"), "mps"),
}
# the estimator's counts of refused measurements and restarts (E19-E21), their values at the end of a run
_COUNTS = ("outliers_fix", "outliers_acc", "resets_fix", "resets_acc")
ESTIMATION_METRICS = (*(f"nees_{b}" for b in _BLOCKS), "nis_fix", "nis_acc",
                      *(f"est_rmse_{b}_{unit}" for b, (_, _, unit) in _BLOCKS.items()), "est_rmse_wind_settled_mps",
                      "est_bias_position_m", "rmse_seen_m", *_COUNTS)


def run_once(scenario: Scenario, out_dir: Path | None = None, seed: int | None = None,
             progress: Callable[[int, int], None] | None = None, master=None, profile: bool = False):
    """Run ``scenario`` once; with ``out_dir``, stream ``results.csv`` there.

    Returns ``(result, summary)``: the :class:`~cosim.master.RunResult` and a
    JSON-ready summary (:func:`run_summary`).
    """
    position, reference = metric_signals(scenario)
    missing = [s for s in position + reference + estimation_signals(scenario) if s not in scenario.record]
    if missing:  # the summary's RMSE reads them from the recorded rows
        raise ScenarioError(f"metrics: {missing[0]!r} is not recorded; add it to record.signals")
    own = master is None
    master = master or build_master(scenario)
    try:
        csv = Path(out_dir) / "results.csv" if out_dir is not None else None
        result = master.run(scenario.duration, seed=scenario.seed if seed is None else seed, csv_path=csv,
                            t0=scenario.start_time, block_rows=scenario.block_rows, raise_on_error=False,
                            progress=progress, profile=profile)
    except FmuError as exc:  # could not start: a parameter refused, told with its scenario key
        raise fmu_error_in_scenario(scenario, exc) from None
    finally:
        if own:
            master.close()
    return result, run_summary(scenario, result)


def run_summary(scenario: Scenario, result) -> dict[str, Any]:
    """A run's summary: status, error, seed, variant, duration, rows, wall
    time, real-time factor, the cost per step of each phase (us, profiled
    runs) and, with ``[metrics]``, the Euclidean RMSE, largest and final error (m)
    and, when it names an estimator, :func:`estimation_metrics`."""
    summary: dict[str, Any] = {
        "scenario": scenario.name, "status": result.status, "error": result.error, "seed": result.seed,
        "variant": controller_variant(scenario),
        "duration_s": scenario.duration, "step_s": scenario.step, "rows": int(result.data.shape[0]),
        "wall_time_s": result.wall_time,
        "real_time_factor": (result.time[-1] - result.time[0]) / result.wall_time if len(result.time) > 1 else None,
    }
    if result.terminated is not None:  # an FMU ended the simulation early (not a failure)
        summary["terminated"] = result.terminated
    if result.phase_times:
        summary["cost_per_step_us"] = {k: v / max(result.n_steps, 1) * 1e6 for k, v in result.phase_times.items()}
        summary["python_loop"] = list(result.python_loop)  # why the compiled loop could not run it (empty: it could)
        summary["python_calls"] = [f"{name}: {why}" for name, why in result.python_calls.items()]
    position, reference = metric_signals(scenario)
    if position and len(result.time):
        e = euclidean_error(result, position, reference)
        summary["rmse_m"] = rmse(result, position, reference)
        summary["max_error_m"] = float(e.max()) if len(e) else None
        summary["final_error_m"] = float(e[-1]) if len(e) else None
    if estimation_spec(scenario) is not None and len(result.time):
        summary.update(estimation_metrics(scenario, result))
    if result.csv_path is not None:
        summary["results_csv"] = str(result.csv_path)
    return summary


STUDY_METRICS = ("rmse_m", "max_error_m", "final_error_m")


def study_metrics(scenario: Scenario, result) -> dict[str, Any]:
    """A study row's metrics: those of :func:`run_summary` (RMSE, max and
    final error, m; the estimate's, :func:`study_metric_names`), on whatever
    part of the run was recorded."""
    summary = run_summary(scenario, result)
    return {k: summary.get(k) for k in study_metric_names(scenario)}


def lean_signals(scenario: Scenario) -> list[str]:
    """What the metrics read: only these are recorded in studies."""
    return list(dict.fromkeys(sum(metric_signals(scenario), []) + estimation_signals(scenario)))


def study_metric_names(scenario: Scenario) -> tuple[str, ...]:
    """The metrics :func:`study_metrics` gives for ``scenario``'s rows."""
    return STUDY_METRICS + (ESTIMATION_METRICS if estimation_spec(scenario) else ())


def _covariance_name(a: str, b: str, order: tuple[str, ...]) -> str:
    if a == b:
        return f"var_{a}"
    a, b = sorted((a, b), key=order.index)
    return f"cov_{a}_{b}"


def estimation_signals(scenario: Scenario) -> list[str]:
    """The signals :func:`estimation_metrics` reads (none without ``[metrics].estimator``)."""
    spec = estimation_spec(scenario)
    if spec is None:
        return []
    estimator, truth, _ = spec
    names = []
    for estimated, true, _ in _BLOCKS.values():
        names += [f"{truth}.{n}" for n in true] + [f"{estimator}.{n}" for n in estimated]
        names += [f"{estimator}.{_covariance_name(a, b, estimated)}" for i, a in enumerate(estimated)
                  for b in estimated[i:]]
    return names + [f"{estimator}.{n}" for n in ("nis_fix", "nis_acc", "fix_used", "t_estimate", *_COUNTS)]


def _rows_at_estimate_time(result, estimator: str, step: float) -> np.ndarray:
    """Per row, the row whose time is the one the estimate describes (its
    ``t_estimate``, E23): the same row when the estimator's output is read at
    its own time, an earlier one in an importer that reads it a step later."""
    t = result.time
    return np.clip(np.rint((result[f"{estimator}.t_estimate"] - t[0]) / step).astype(int), 0, len(t) - 1)


def estimation_metrics(scenario: Scenario, result) -> dict[str, float]:
    """The estimate's consistency and accuracy over one run (docs/estimation.md,
    E15-E17): per block (position, velocity, attitude, wind) the mean NEES and
    the RMSE of the estimate (Euclidean over the block's three axes; yaw
    wrapped); the mean NIS of the fix (over the steps that used one) and of
    the drag measurement; and the wind RMSE over the rows where the true wind
    has been steady for ``settle`` s; the length of the position estimate's
    mean error (its bias) and the RMSE of reference - estimate over the whole
    run (the error the controller sees, beside ``rmse_m``, the true one).
    NEES, NIS and RMSE skip the first
    ``settle`` s (the filter's convergence from its initial guess)."""
    estimator, truth, settle = estimation_spec(scenario)
    t = result.time
    after_start = t - t[0] >= settle
    at = _rows_at_estimate_time(result, estimator, scenario.step)  # the truth at the estimate's own time
    out: dict[str, float] = {}
    for block, (estimated, true, unit) in _BLOCKS.items():
        error = np.column_stack([result[f"{estimator}.{e}"] - result[f"{truth}.{n}"][at]
                                 for e, n in zip(estimated, true)])
        if block == "attitude":
            error = wrap_angle(error)
        covariance = np.stack([np.column_stack([result[f"{estimator}.{_covariance_name(a, b, estimated)}"]
                                                for b in estimated]) for a in estimated], axis=1)
        # the wind's NEES where it is steady: a step of the gust is no random walk (E13), the filter is
        # not consistent through it by construction; its RMSE both ways
        judged = settled(t, np.column_stack([result[f"{truth}.{n}"][at] for n in true]), settle) \
            if block == "wind" else after_start
        out[f"nees_{block}"] = float(np.mean(nees(error[judged], covariance[judged])))
        out[f"est_rmse_{block}_{unit}"] = float(np.sqrt(np.mean(np.sum(error[after_start] ** 2, axis=1))))
        if block == "wind":
            out["est_rmse_wind_settled_mps"] = float(np.sqrt(np.mean(np.sum(error[judged] ** 2, axis=1))))
        if block == "position":
            # the estimate's bias: the length of its mean error; and the tracking error the controller
            # sees, reference - estimate (the FNN learns on it; E18)
            out["est_bias_position_m"] = float(np.linalg.norm(np.mean(error[after_start], axis=0)))
            _, reference = metric_signals(scenario)
            out["rmse_seen_m"] = rmse(result, [f"{estimator}.{e}" for e in estimated], reference)
    used = result[f"{estimator}.fix_used"] > 0.5
    out["nis_fix"] = float(np.mean(result[f"{estimator}.nis_fix"][used & after_start]))
    out["nis_acc"] = float(np.mean(result[f"{estimator}.nis_acc"][after_start]))
    out.update({c: float(result[f"{estimator}.{c}"][-1]) for c in _COUNTS})
    return out


def measure(study: Study, out_dir: str | Path | None = None, *, workers: int = 1, scheduler: str | None = None,
            metrics: Callable[[Scenario, Any], Mapping[str, Any]] = study_metrics,
            metric_names: Sequence[str] | None = None, record: Sequence[str] | None = None,
            progress: Callable[[int, int], None] | None = None, plots: bool = False,
            resume: bool = True, worker_timeout: float | None = WORKER_TIMEOUT) -> StudyResult:
    """Run ``study`` the paper's way: :func:`cosim.study_run.run_study`
    measuring each row with ``metrics`` and recording only what they read
    (``record``, default :func:`lean_signals`); ``metric_names`` default
    :func:`study_metric_names` of the study's scenario."""
    from cosim.study_run import run_study  # the study machinery: not loaded by a single run

    return run_study(study, out_dir, workers=workers, scheduler=scheduler, metrics=metrics,
                     metric_names=study_metric_names(study.scenario) if metric_names is None else metric_names,
                     record=record if record is not None else (lean_signals(study.scenario) or None),
                     progress=progress, plots=plots, resume=resume,
                     worker_timeout=worker_timeout)
