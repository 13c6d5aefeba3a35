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
from typing import Any, Callable, Mapping, Sequence

from cosim.errors import FmuError, ScenarioError
from cosim.scenario import Scenario, build_master, fmu_error_in_scenario
from cosim.study import Study
from cosim.limits import WORKER_TIMEOUT
from cosim.study_run import StudyResult, run_study

from .metrics import euclidean_error, rmse
from .missions import controller_variant, metric_signals

__all__ = ["run_once", "run_summary", "measure", "study_metrics", "STUDY_METRICS", "lean_signals"]


def run_once(scenario: Scenario, out_dir: Path | None = None, seed: int | None = None,
             progress: Callable[[int, int], None] | None = None, master=None, profile: bool = False):
    """Run ``scenario`` once; with ``out_dir``, stream ``results.csv`` there.

    Returns ``(result, summary)``: the :class:`~cosim.master.RunResult` and a
    JSON-ready summary (:func:`run_summary`).
    """
    position, reference = metric_signals(scenario)
    missing = [s for s in position + reference if s not in scenario.record]
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
    runs) and, with ``[metrics]``, the Euclidean RMSE, largest and final error (m)."""
    summary: dict[str, Any] = {
        "scenario": scenario.name, "status": result.status, "error": result.error, "seed": result.seed,
        "variant": controller_variant(scenario),
        "duration_s": scenario.duration, "step_s": scenario.step, "rows": int(result.data.shape[0]),
        "wall_time_s": result.wall_time,
        "real_time_factor": (result.time[-1] - result.time[0]) / result.wall_time if len(result.time) > 1 else None,
    }
    if result.phase_times:
        summary["cost_per_step_us"] = {k: v / max(result.n_steps, 1) * 1e6 for k, v in result.phase_times.items()}
    position, reference = metric_signals(scenario)
    if position and len(result.time):
        e = euclidean_error(result, position, reference)
        summary["rmse_m"] = rmse(result, position, reference)
        summary["max_error_m"] = float(e.max()) if len(e) else None
        summary["final_error_m"] = float(e[-1]) if len(e) else None
    if result.csv_path is not None:
        summary["results_csv"] = str(result.csv_path)
    return summary


STUDY_METRICS = ("rmse_m", "max_error_m", "final_error_m")


def study_metrics(scenario: Scenario, result) -> dict[str, Any]:
    """A study row's metrics: those of :func:`run_summary` (RMSE, max and
    final error, m), on whatever part of the run was recorded."""
    summary = run_summary(scenario, result)
    return {k: summary.get(k) for k in STUDY_METRICS}


def lean_signals(scenario: Scenario) -> list[str]:
    """What the metrics read: only these are recorded in studies."""
    return list(dict.fromkeys(sum(metric_signals(scenario), [])))


def measure(study: Study, out_dir: str | Path | None = None, *, workers: int = 1, scheduler: str | None = None,
            metrics: Callable[[Scenario, Any], Mapping[str, Any]] = study_metrics,
            metric_names: Sequence[str] = STUDY_METRICS, record: Sequence[str] | None = None,
            progress: Callable[[int, int], None] | None = None, plots: bool = False,
            resume: bool = True, worker_timeout: float | None = WORKER_TIMEOUT) -> StudyResult:
    """Run ``study`` the paper's way: :func:`cosim.study_run.run_study`
    measuring each row with ``metrics`` and recording only what they read
    (``record``, default :func:`lean_signals`)."""
    return run_study(study, out_dir, workers=workers, scheduler=scheduler, metrics=metrics,
                     metric_names=metric_names, record=record if record is not None
                     else (lean_signals(study.scenario) or None), progress=progress, plots=plots, resume=resume,
                     worker_timeout=worker_timeout)
