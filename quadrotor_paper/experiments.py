"""Runs and sweeps: one scenario run with its files, the sweeps behind
Table 2 and Table 3, and the metrics of a study's rows.

A sweep is a list of jobs run through the engine's runner
(:mod:`cosim.dask_runner`: in this process for one worker, else on Dask);
each worker builds one master per variant and option row (extracting and
instantiating its FMUs once) and runs its share of the jobs, resetting
between runs. A
job is (variant, wind speed, seed) and optionally an option row
(:mod:`quadrotor_paper.options`: the variant with scenario overrides); its
result is the RMSE, the status and the wall time.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from cosim.errors import FmuError
from cosim.study import interval95
from cosim.scenario import Scenario, apply_overrides, build_master, fmu_error_in_scenario, parse_scenario

from .metrics import euclidean_error, rmse
from .missions import controller_variant, metric_signals, wind_parameter

__all__ = ["Job", "run_once", "sweep", "cells", "table_metrics", "study_metrics", "STUDY_METRICS",
           "lean_signals"]


@dataclass(frozen=True)
class Job:
    variant: str
    wind: float | None  # m/s; None keeps the scenario's
    seed: int
    option: str | None = None  # an option row (its variant is ``variant``); None: the variant's own row

    @classmethod
    def of_option(cls, name: str, wind: float | None, seed: int) -> "Job":
        from .options import option

        return cls(option(name).variant, wind, seed, name)

    @property
    def row(self) -> str:
        """The table row: the option's name, else the variant's."""
        return self.option or self.variant


def _task_overrides(scenario: Scenario, job: Job) -> dict[str, Any]:
    """The scenario overrides of ``job``: its variant (the controller FMU's
    model, so no run-level parameter), and the option's for an option row."""
    if job.option is None:
        return {"controller.variant": job.variant}
    from .options import option, scenario_overrides

    return {"controller.variant": job.variant, **scenario_overrides(option(job.option), scenario)}


def _parameters(scenario: Scenario, job: Job) -> dict[str, Any]:
    params: dict[str, Any] = {}
    if job.wind is not None:
        params[wind_parameter(scenario, "speed")] = job.wind
    return params


def run_once(scenario: Scenario, out_dir: Path | None = None, seed: int | None = None,
             variant: str | None = None, progress: Callable[[int, int], None] | None = None, master=None,
             profile: bool = False):
    """Run ``scenario`` once; with ``out_dir``, stream ``results.csv`` there.

    Returns ``(result, summary)``: the :class:`~cosim.master.RunResult` and a
    JSON-ready summary (status, error, RMSE, max error, wall time, real-time
    factor and, with ``profile``, the cost per step of each phase in
    microseconds).
    """
    own = master is None
    if variant:  # the controller's variant is its FMU's model: a scenario override
        scenario = parse_scenario(apply_overrides(scenario.raw, {"controller.variant": variant}),
                                  source=scenario.source)
    master = master or build_master(scenario)
    try:
        csv = Path(out_dir) / "results.csv" if out_dir is not None else None
        result = master.run(scenario.duration, seed=scenario.seed if seed is None else seed,
                            csv_path=csv, t0=scenario.start_time, block_rows=scenario.block_rows,
                            raise_on_error=False, progress=progress, profile=profile)
    except FmuError as exc:  # could not start: a parameter refused, told with its scenario key
        raise fmu_error_in_scenario(scenario, exc) from None
    finally:
        if own:
            master.close()
    return result, summarize(scenario, result, variant)


def summarize(scenario: Scenario, result, variant: str | None = None) -> dict[str, Any]:
    summary: dict[str, Any] = {
        "scenario": scenario.name, "status": result.status, "error": result.error, "seed": result.seed,
        "variant": variant or controller_variant(scenario),
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


# ---- sweeps -------------------------------------------------------------------------

def table_metrics(scenario: Scenario, result) -> dict[str, Any]:
    """A table's cell value: the RMSE between the ``[metrics]`` signals (on
    the workers; ``None`` unless the run finished ``ok``)."""
    return {"rmse_m": rmse(result, *metric_signals(scenario)) if result.status == "ok" else None}


STUDY_METRICS = ("rmse_m", "max_error_m", "final_error_m")


def study_metrics(scenario: Scenario, result) -> dict[str, Any]:
    """A study row's metrics: those of :func:`summarize` (RMSE, max and final
    error, m), on whatever part of the run was recorded."""
    summary = summarize(scenario, result)
    return {k: summary.get(k) for k in STUDY_METRICS}


def lean_signals(scenario: Scenario) -> list[str]:
    """What the metrics read: only these are recorded in sweeps and studies."""
    return list(dict.fromkeys(sum(metric_signals(scenario), [])))


def sweep(scenario: Scenario, jobs: Sequence[Job], workers: int = 2,
          progress: Callable[[dict[str, Any]], None] | None = None, scheduler: str | None = None
          ) -> list[dict[str, Any]]:
    """Run every job; results in the order of ``jobs``.

    Only the metric signals are recorded (no CSV). The runs go through
    :func:`cosim.dask_runner.run_tasks`: ``workers = 1`` (and no
    ``scheduler``) runs in this process, else a Dask ``LocalCluster`` of
    ``workers`` processes (or the cluster at ``scheduler``); each worker
    builds one master per variant (a scenario override: the controller
    FMU's model) and option row, and reuses it across wind speeds (a
    run-level parameter) and seeds.
    """
    from cosim.dask_runner import Task, run_tasks

    lean = parse_scenario(apply_overrides(scenario.raw, {"record.signals": lean_signals(scenario)}),
                          source=scenario.source)
    tasks = (Task(i, _task_overrides(lean, job), _parameters(lean, job), job.seed) for i, job in enumerate(jobs))
    results: list[dict[str, Any] | None] = [None] * len(jobs)
    for rec in run_tasks(lean, tasks, workers=workers, scheduler=scheduler, metrics=table_metrics):
        job = jobs[rec["key"]]
        results[rec["key"]] = res = {
            "variant": job.variant, "row": job.row, "wind_m_s": job.wind, "seed": job.seed, "status": rec["status"],
            "error": rec["error"], "rmse_m": rec["metrics"].get("rmse_m"), "wall_time_s": rec["wall_time_s"],
            "pid": rec["pid"]}
        if progress:
            progress(res)
    return results  # type: ignore[return-value]


def cells(results: Iterable[dict[str, Any]], key: str = "wind_m_s") -> dict[str, dict[Any, dict[str, Any]]]:
    """Group job results by row (the variant, or the option row) and ``key``: mean, sample std (ddof = 1),
    the 95 % t interval of the mean (``ci95``, from 2 runs), number of runs,
    number failed, and every run's RMSE."""
    grouped: dict[str, dict[Any, list[dict[str, Any]]]] = {}
    for r in results:
        grouped.setdefault(r.get("row", r["variant"]), {}).setdefault(r[key], []).append(r)
    out: dict[str, dict[Any, dict[str, Any]]] = {}
    for variant, by in grouped.items():
        out[variant] = {}
        for k, runs in by.items():
            values = np.array([r["rmse_m"] for r in runs if r["rmse_m"] is not None], dtype=float)
            out[variant][k] = {
                "mean": float(values.mean()) if values.size else None,
                "std": float(values.std(ddof=1)) if values.size > 1 else 0.0 if values.size else None,
                "ci95": interval95(values),
                "runs": len(runs), "failed": sum(r["status"] != "ok" for r in runs),
                "rmse": [r["rmse_m"] for r in sorted(runs, key=lambda r: r["seed"])],
                "seeds": sorted(r["seed"] for r in runs),
                "errors": [r["error"] for r in runs if r["error"]],
            }
    return out


def write_json(path: Path, data: Any) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, default=_json_default))
    return path


def _json_default(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")

