"""One run with its files, and what the paper's studies measure.

Every multi-run command (``table2``, ``table3``, ``reproduce``, ``sweep``)
and every one-off analysis that flies missions is a study
(:mod:`cosim.study.definition`) run by :func:`measure`: the engine's runner, in this
process or on Dask, recording only the signals the metrics read, each row
measured by :func:`study_metrics` (Euclidean RMSE, largest and final error
between the ``[metrics]`` signals). :func:`run_once` is the single run of
``fnn-cosim run`` and of the figures, with its results CSV; :func:`run_with_files`
the whole of ``fnn-cosim run``'s (summary, figures, learned state).

Both take the metrics as the rows stream (:class:`~quadrotor_paper.run_metrics.RunMetrics`,
an observer of the run): a run's memory does not grow with its duration; a
single run keeps at most :data:`PLOT_ROWS` rows (evenly thinned, for its
plots), a study's runs none.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

from cosim.errors import FmuError, ScenarioError
from cosim.scenario.definition import Scenario, dotted_key
from cosim.scenario.assembly import build_master, fmu_error_in_scenario
from cosim.limits import WORKER_TIMEOUT

if TYPE_CHECKING:
    from cosim.study.definition import Study
    from cosim.study.run import StudyResult

from fmu_models.models.estimator_outputs import COUNTS

from .controller_component import controller_variant
from .sections import estimation_spec, metric_signals
from .run_metrics import BLOCKS, RunMetrics

__all__ = ["run_once", "run_with_files", "results_room", "run_summary", "measure", "study_metrics", "STUDY_METRICS",
           "ESTIMATION_METRICS", "study_metric_names", "lean_signals", "estimation_signals", "estimation_metrics",
           "PLOT_ROWS", "threads_safe"]

ESTIMATION_METRICS = (*(f"nees_{b}" for b in BLOCKS), "nis_fix", "nis_acc",
                      *(f"est_rmse_{b}_{unit}" for b, (_, _, unit) in BLOCKS.items()), "est_rmse_wind_settled_mps",
                      "est_bias_position_m", "rmse_seen_m", *COUNTS)
PLOT_ROWS = 10_000  # rows a single run keeps for its plots: every row of a 100 s mission at 10 ms, then thinned


def run_once(scenario: Scenario, out_dir: Path | None = None, seed: int | None = None,
             progress: Callable[[int, int], None] | None = None, master=None, profile: bool = False,
             keep: int | None = PLOT_ROWS, record_every: int = 1):
    """Run ``scenario`` once; with ``out_dir``, stream ``results.csv`` there
    (every ``record_every``-th row).

    Returns ``(result, summary)``: the :class:`~cosim.loop.master.RunResult`
    (keeping ``keep`` rows: ``Master.run``) and a JSON-ready summary
    (:func:`run_summary`), its metrics taken over every row as they streamed.
    """
    if scenario.record is not None:  # refused before any FMU is loaded
        _check_recorded(scenario, scenario.record)
    own = master is None
    master = master or build_master(scenario)
    metrics = RunMetrics(scenario)
    try:
        if scenario.record is None:  # every output is recorded: the master knows which
            _check_recorded(scenario, master.record_columns)
        csv = Path(out_dir) / "results.csv" if out_dir is not None else None
        result = master.run(scenario.duration, seed=scenario.seed if seed is None else seed, csv_path=csv,
                            t0=scenario.start_time, block_rows=scenario.block_rows, raise_on_error=False,
                            progress=progress, profile=profile, keep=keep, observers=[metrics],
                            record_every=record_every)
    except FmuError as exc:  # could not start: a parameter refused, told with its scenario key
        raise fmu_error_in_scenario(scenario, exc) from None
    finally:
        if own:
            master.close()
    return result, run_summary(scenario, result, metrics)


def run_with_files(scenario: Scenario, master, out: Path, *, record_every: int = 1, profile: bool = False,
                   save_learned: Path | None = None, resumed_from: str | None = None, plots: bool = True,
                   quiet: bool = False) -> tuple[dict[str, Any], list[str], str | None]:
    """The run of ``fnn-cosim run``: ``scenario`` flown once by ``master``
    (built, every input taken) into the folder ``out`` (checked): its
    ``results.csv`` (every ``record_every``-th row, streamed), ``summary.json``,
    the figures (``plots``, a run of more than one row), ``summary.md``, and
    with ``save_learned`` the controller's learned state after the run
    (:func:`~quadrotor_paper.learned.save_learned`; ``resumed_from``: the
    file it started from, named in the summary). ``master`` is closed once
    the run and its learned state are done, before the figures.

    What results.csv will take is checked against the room on ``out``'s
    file system before the run (:func:`results_room`); a state that cannot
    be saved loses nothing else: the run's results are written first.
    ``quiet``: no progress bar, no note. Returns the summary, the lines of
    ``summary.md`` and the run's failure (its error, else the learned
    state's; ``None``: none)."""
    from cosim.errors import CosimError, one_line
    from cosim.files import write_json

    from .progress import progress_bar
    from .run_summary import summary_lines

    if save_learned is not None:
        from .learned import learned_variant, save_learned as save

        if "controller" not in master.components:
            raise ScenarioError(f"--save-learned {save_learned}: the scenario has no controller")
        learned_variant(master.components["controller"], f"--save-learned {save_learned}")
    results_room(scenario, master, out, record_every, quiet=quiet)
    with progress_bar(f"run {scenario.name}", enabled=not quiet, unit="step") as bar:
        result, summary = run_once(scenario, out, progress=bar, master=master, profile=profile,
                                   record_every=record_every)
    if resumed_from:
        summary["resumed_from"] = str(resumed_from)
    plots = plots and summary["rows"] > 1
    if plots or save_learned is not None:  # the run's results first, kept if an optional part below fails
        write_json(out / "summary.json", summary)
    learned_error = None
    if save_learned is not None:
        try:  # a state that cannot be saved (not finite after a diverged run) loses nothing else
            summary["learned_state"] = str(save(master.components["controller"], save_learned))
        except (CosimError, ValueError, OSError) as exc:
            learned_error = summary["learned_state_error"] = f"--save-learned {save_learned}: {one_line(str(exc))}"
    master.close()  # its FMU instances are done with: freed before the figures are drawn
    figures = []
    if plots:
        from .plots import run_figures  # matplotlib only when there is something to draw

        figures = run_figures(out, result, scenario)
    summary["figures"] = [str(p) for p in figures]
    write_json(out / "summary.json", summary)
    lines = summary_lines(scenario, result, summary, figures, learned_error)
    (out / "summary.md").write_text("\n".join(lines))
    failure = summary["error"] if summary["status"] != "ok" else learned_error  # the run's own first
    return summary, lines, failure


def results_room(scenario: Scenario, master, out: Path, every: int, quiet: bool = False) -> None:
    """What results.csv will take (every ``every``-th row of ``scenario``'s
    run by ``master``, :func:`cosim.loop.recorder.csv_bytes`), said before the
    run when over 100 MB (not ``quiet``), and refused when the file system
    of ``out`` cannot hold it (memory does not grow with the run: disk is
    the only bound, and it is the user's; docs/security.md)."""
    import sys

    from cosim.files import room_for
    from cosim.loop.recorder import csv_bytes

    rows = int(round(scenario.duration / scenario.step)) + 1
    written = -(-rows // every)
    need = csv_bytes(written, master.record_columns, master.plan.record_types)
    room_for(out, need, f"results.csv: {written} rows of {len(master.record_columns)} columns",
             "write every K-th row: --record-every K, or record fewer signals")
    if not quiet and need > 100e6:  # a long mission: say what it will write before it starts
        print(f"results.csv: {written} rows of {len(master.record_columns)} columns, up to {need / 1e9:.1f} GB "
              f"(--record-every K writes every K-th)", file=sys.stderr)


def _check_recorded(scenario: Scenario, recorded) -> None:
    """The summary's RMSE reads the metrics' signals from the recorded rows:
    one missing is refused."""
    position, reference = metric_signals(scenario)
    missing = [s for s in position + reference + estimation_signals(scenario) if s not in recorded]
    if missing:
        raise ScenarioError(f"metrics: {missing[0]!r} is not recorded; add it to record.signals")


def _streamed(scenario: Scenario, result) -> RunMetrics:
    """The :class:`RunMetrics` the run streamed to, or (a result that kept
    every row) one fed with its rows."""
    for observer in result.observers:
        if isinstance(observer, RunMetrics):
            return observer
    if len(result.data) != result.rows or result.stride != 1:
        raise ValueError(f"metrics of a run that kept {len(result.data)} of its {result.rows} rows: pass "
                         f"observers=[RunMetrics(scenario)] to Master.run")
    metrics = RunMetrics(scenario)
    metrics.add(result)
    return metrics


def run_summary(scenario: Scenario, result, metrics: RunMetrics | None = None) -> dict[str, Any]:
    """A run's summary: status, error, seed, variant, duration, rows, wall
    time, real-time factor, the cost per step of each phase (us, profiled
    runs) and, with ``[metrics]``, the Euclidean RMSE, largest and final error (m)
    and, when it names an estimator, :func:`estimation_metrics`: from
    ``metrics`` (taken as the run streamed), else from the observers of the
    run or its rows. An undefined metric is ``None`` (JSON ``null``)."""
    span = result.span
    summary: dict[str, Any] = {
        "scenario": scenario.name, "status": result.status, "error": result.error, "seed": result.seed,
        "variant": controller_variant(scenario),
        "duration_s": scenario.duration, "step_s": scenario.step, "rows": int(result.rows),
        "signals": len(result.columns) - 1,  # the recorded signals (time aside)
        "wall_time_s": result.wall_time,
        "real_time_factor": (span[1] - span[0]) / result.wall_time if result.rows > 1 else None,
    }
    if result.terminated is not None:  # an FMU ended the simulation early (not a failure)
        summary["terminated"] = result.terminated
    if result.phase_times:
        summary["cost_per_step_us"] = {k: v / max(result.n_steps, 1) * 1e6 for k, v in result.phase_times.items()}
        summary["python_loop"] = list(result.python_loop)  # why the compiled loop could not run it (empty: it could)
        summary["python_calls"] = [f"{name}: {why}" for name, why in result.python_calls.items()]
    summary.update((metrics or _streamed(scenario, result)).values())
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


study_metrics.observe = RunMetrics  # a study streams each run's rows to one (cosim.study.runner.execute)


def lean_signals(scenario: Scenario) -> list[str]:
    """What the metrics read: only these are recorded in studies."""
    return list(dict.fromkeys(sum(metric_signals(scenario), []) + estimation_signals(scenario)))


def study_metric_names(scenario: Scenario) -> tuple[str, ...]:
    """The metrics :func:`study_metrics` gives for ``scenario``'s rows."""
    spec = estimation_spec(scenario)
    if spec is None:
        return STUDY_METRICS
    # a filter's own counts beside the gate's (the magnetometer's refusals, E24; the motion-capture attitude's, E29)
    return STUDY_METRICS + ESTIMATION_METRICS + tuple(c for c in spec[3] if c not in COUNTS)


def estimation_signals(scenario: Scenario) -> list[str]:
    """The signals :func:`estimation_metrics` reads (none without ``[metrics].estimator``)."""
    from .run_metrics import Estimation

    spec = estimation_spec(scenario)
    return [] if spec is None else Estimation(*spec, metric_signals(scenario)[1], scenario.step).signals


def estimation_metrics(scenario: Scenario, result) -> dict[str, float | None]:
    """The estimate's consistency and accuracy over one run whose rows were
    all kept (:class:`quadrotor_paper.run_metrics.Estimation`, which states them)."""
    from .run_metrics import Estimation

    part = Estimation(*estimation_spec(scenario), metric_signals(scenario)[1], scenario.step)
    part.add(result)
    return part.values()


def measure(study: Study, out_dir: str | Path | None = None, *, workers: int = 1, scheduler: str | None = None,
            metrics: Callable[[Scenario, Any], Mapping[str, Any]] = study_metrics,
            metric_names: Sequence[str] | None = None, record: Sequence[str] | None = None,
            progress: Callable[[int, int], None] | None = None, plots: bool = False,
            resume: bool = True, worker_timeout: float | None = WORKER_TIMEOUT) -> StudyResult:
    """Run ``study`` the paper's way: :func:`cosim.study.run.run_study`
    measuring each row with ``metrics`` and recording only what they read
    (``record``, default :func:`lean_signals`); ``metric_names`` default
    :func:`study_metric_names` of the study's scenario. A local cluster is
    of threads in this process when :func:`threads_safe` says so, else of
    processes."""
    from cosim.study.run import run_study  # the study machinery: not loaded by a single run

    return run_study(study, out_dir, workers=workers, scheduler=scheduler, metrics=metrics,
                     metric_names=study_metric_names(study.scenario) if metric_names is None else metric_names,
                     record=record if record is not None else (lean_signals(study.scenario) or None),
                     progress=progress, plots=plots, resume=resume,
                     worker_timeout=worker_timeout, threads=threads_safe(study, metrics))


_FMU_VALUES = ("parameters", "start")  # what a study may change of an [fmus] entry and stay on our FMUs


def threads_safe(study: Study, metrics: Callable[[Scenario, Any], Mapping[str, Any]] = study_metrics) -> bool:
    """Whether ``study``'s runs may fly as threads of one process
    (:func:`cosim.study.runner.fly`, ``docs/studies.md``, "Threads or
    processes"): its metrics are :func:`study_metrics` (taken as the rows
    stream: a run's time is its compiled loop, which releases the GIL; an
    analysis's metrics run Python per run, which the GIL would serialize),
    every ``[fmus]`` entry is a registered model of this project in
    Co-Simulation (their C keeps no global state and is reentrant, checked
    on every built binary; a Model Exchange FMU is integrated in Python),
    and no case, grid or random key gives an FMU another file or interface.
    Anything else (an FMU file of someone's, which may keep globals or
    crash) flies in worker processes."""
    if metrics is not study_metrics:
        return False
    scenario = study.scenario
    for spec in scenario.fmus.values():
        if "model" not in spec or spec.get("interface", "CoSimulation") != "CoSimulation":
            return False
    keys = [*study.grid, *study.random, *(k for case in study.cases for k in case.overrides)]
    for key in keys:
        parts = dotted_key(key)
        if parts[0] == "fmus" and (len(parts) < 3 or parts[2] not in _FMU_VALUES):
            return False
    return True
