"""The calibration's pipeline: :func:`calibrate` reads the FMU, binds its
variables to the log, splits it into segments, fits them and computes the
statistics, the warnings and the held-out prediction (the modules it runs in
order are listed in :mod:`cosim.calibration`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from ..errors import ScenarioError
from ..fmi.fmu import FmuComponent
from ..names import nearest_told
from .columns import CalibrationSettings, ColumnMap, read_column_map, read_settings
from .diagnostics import Diagnostic, diagnose
from .frames import MIRROR_ITERATIONS, convert, mirror_check
from .log import Log, read_log
from .problem import Problem, bind_problem
from .segments import Segment, split
from .statistics import Statistics, residual_statistics, statistics

__all__ = ["Calibration", "calibrate"]


@dataclass
class Calibration:
    """A calibration's result: the problem, the fit, the statistics, the
    prediction of the held-out part."""

    problem: Problem
    settings: CalibrationSettings
    segments: list
    held_out: Segment | None
    fit: object  # cosim.calibration.solve.Fit
    stats: Statistics
    residuals: dict
    prediction: dict | None  # {"times", "logged", "predicted", "rms"} of the held-out part
    instance: str | None = None
    diagnostics: list[Diagnostic] = field(default_factory=list)  # the warnings (cosim.calibration.diagnostics)

    @property
    def converged(self) -> bool:
        return self.fit.converged

    def estimates(self) -> dict[str, float | None]:
        """Fitted name -> value (``None`` where not identifiable; an estimate at its bound has its value)."""
        return {n: (float(v) if ok else None) for n, v, ok in
                zip(self.problem.fit, self.fit.theta, self.stats.identifiable)}


def calibrate(log: Log | str | Path, fmu: str | Path, settings: CalibrationSettings,
              column_map: ColumnMap | None = None, instance: str | None = None,
              extra_columns: Mapping[str, str] | None = None, fixed: Mapping[str, float] | None = None,
              progress: Callable[[int, int], None] | None = None) -> Calibration:
    """Fit ``settings.fit`` of the FMU at ``fmu`` to ``log`` (module docstring).

    ``instance``: the name whose columns the log holds as
    ``<instance>.<variable>`` (the project's results); ``extra_columns``:
    input -> column known from elsewhere (a scenario's connections);
    ``fixed``: values set before the settings' ``fix`` (a scenario's
    parameters of the instance)."""
    from .model import LogModel
    from .solve import fit as solve

    if not isinstance(log, Log):
        log = read_log(log, column_map)
    if settings.start is not None or settings.stop is not None:
        log = log.window(settings.start, settings.stop)
    if fixed:
        settings = settings.model_copy(update={"fix": {**{k: v for k, v in fixed.items() if k not in settings.fit},
                                                       **settings.fix}})
    cs = _component(fmu, settings, instance)
    try:
        read, stated = log, column_map
        log, column_map = convert(log, column_map, lambda name: _parameter(cs, settings, name))
        states = _states(cs)
        problem = bind_problem(cs, log, settings, column_map, instance, extra_columns, states)
        model = LogModel(problem, settings.initial_parameters)
        try:
            method, symbolic = settings.jacobian, None
            if method in ("auto", "casadi"):
                symbolic = _symbolic(cs, model, settings.workers)
                if isinstance(symbolic, str):
                    if method == "casadi":
                        raise ScenarioError(f"jacobian = 'casadi': {Path(fmu).name}: {symbolic}")
                    symbolic = None
                else:
                    method = "casadi"
            if method == "auto":
                method = "derivatives" if model.has_derivatives else "differences"
            elif method == "derivatives" and not model.has_derivatives:
                raise ScenarioError(f"jacobian = 'derivatives': {Path(fmu).name} provides no directional derivatives "
                                    f"(or no Model Exchange interface); use 'differences'")
            segments, held_out = split(log.times, settings.segment, settings.holdout)
            logged = np.array([s in problem.state_columns for s in states], dtype=bool)
            estimated = np.ones(len(states), bool) if settings.initial_states == "estimated" else ~logged
            x0 = np.tile(model.initial_guess(), (len(segments), 1))
            for i, seg in enumerate(segments):
                for j, s in enumerate(states):
                    if logged[j]:
                        x0[i, j] = problem.output_values[seg.first, problem.state_columns[s]]
            result = solve(model, segments, estimated, x0, dict(settings.noise), method, settings.max_iterations,
                           _tolerance(cs, settings), progress, settings.workers, settings.jacobian_stride, symbolic)
            weighted = np.concatenate([(r / result.sigma).ravel() for r in result.residuals])
            stats = statistics(problem.fit, result.theta, result.jacobian, weighted, result.jacobian_state_blocks,
                               int(estimated.sum()) * len(segments), settings.identifiability, problem.lower,
                               problem.upper, len(problem.outputs), [r.size for r in result.residuals])
            residuals = residual_statistics(problem.outputs, np.concatenate(result.residuals), result.sigma,
                                            [len(r) for r in result.residuals], settings.whiteness_lags)
            prediction = _predict(model, result, segments, held_out, logged, problem) if held_out is not None else None
        finally:
            model.close()
    finally:
        cs.close()
    cal = Calibration(problem, settings, segments, held_out, result, stats, residuals, prediction, instance)
    cal.diagnostics.extend(diagnose(cal, column_map))
    if any(d.kind == "residuals-not-white" for d in cal.diagnostics):  # correlated: the sandwich's intervals
        stats.use_robust()
    if stated is not None and stated.mirror_check:  # the map's mirrors refitted briefly from the same guesses
        brief = settings.model_copy(update={"max_iterations": MIRROR_ITERATIONS,
                                            "noise": dict(zip(problem.outputs, map(float, result.sigma)))})
        cal.diagnostics += mirror_check(result.cost, stated, lambda m: calibrate(read, fmu, brief, m, instance,
                                                                                 extra_columns))
    return cal


def _parameter(cs: FmuComponent, settings: CalibrationSettings, name: str) -> float:
    """The value of the FMU parameter ``name`` a column map names (a rotor's
    angle, a top speed): fixed, else its start value; not a fitted one."""
    if name in settings.fit:
        raise ScenarioError(f"column map: names {name}, which is fitted; the log's reading cannot depend on it "
                            f"(fix it: --fix {name}=...)")
    if name in settings.fix:
        return float(settings.fix[name])
    v = cs.variables.get(name)
    if v is None or v.causality != "parameter":
        raise ScenarioError(f"column map: {name!r} is not a parameter of {cs.path.name}"
                            + nearest_told(name, cs.variables))
    try:
        return float(v.start)
    except (TypeError, ValueError):
        raise ScenarioError(f"column map: {name} of {cs.path.name} has no numeric start value; fix it") from None


def _component(fmu: str | Path, settings: CalibrationSettings, instance: str | None) -> FmuComponent:
    """The instance that makes the trajectories, in the interface the
    settings ask (``"auto"``: Model Exchange where the FMU has it, integrated
    to the solver's tolerance, except an FMU of ours, whose Co-Simulation is
    its CasADi definition's RK4 steps, exact and fast by :mod:`.symbolic`;
    Co-Simulation for an FMU without Model Exchange); a Model Exchange one
    integrated by the master's solver (``settings.solver``, CVODE at
    :data:`~cosim.calibration.columns.TOLERANCE` unless given). An interface
    the FMU lacks is its :class:`~cosim.errors.FmuLoadError`, in one line."""
    from ..fmi.model_exchange import SolverSettings
    from .columns import TOLERANCE

    given = settings.solver.model_dump() if settings.solver is not None else {}
    solver = SolverSettings(**(given | {"relative_tolerance": given.get("relative_tolerance") or TOLERANCE}))
    interface = None if settings.interface == "auto" else settings.interface
    comp = FmuComponent(instance or "calibrated", fmu, interface=interface, solver=solver)
    if interface is None and comp.interface == "CoSimulation" and comp.model_description.modelExchange is not None:
        if _definition(comp) is None:  # not ours: its Co-Simulation is often a crude fixed step (docs)
            comp.close()
            comp = FmuComponent(instance or "calibrated", fmu, interface="ModelExchange", solver=solver)
    if settings.solver is not None and comp.interface != "ModelExchange":
        comp.close()
        raise ScenarioError(f"solver: {Path(fmu).name} runs in Co-Simulation here (its own integrator); a solver is "
                            f"for interface = 'ModelExchange'")
    return comp


def _tolerance(cs: FmuComponent, settings: CalibrationSettings) -> float:
    """The solver's ``ftol``, ``xtol``, ``gtol``: the settings', and in Model
    Exchange with CVODE no finer than its relative tolerance: the residuals
    are computed no finer (the cost jitters between neighbouring points,
    measured 1e-5 relative at 1e-8 on VanDerPol), and iterations below it
    chase the integration's error."""
    if cs.interface == "ModelExchange" and cs.solver.method == "cvode":
        return max(settings.tolerance, cs.solver.relative_tolerance)
    return settings.tolerance


def _symbolic(cs: FmuComponent, model, workers: int):
    """The problem's :class:`~cosim.calibration.symbolic.SymbolicModel` when
    the FMU is one of ours run in Co-Simulation, else why not (a string)."""
    from .symbolic import symbolic_model

    if cs.interface != "CoSimulation":  # the CasADi way is the Co-Simulation's RK4 steps, not a Model Exchange solver
        return "run in Model Exchange here (the CasADi way reproduces its Co-Simulation)"
    definition = _definition(cs)
    if definition is None:
        return "not a model whose CasADi definition is registered (or built with other values)"
    return symbolic_model(model, definition, workers)


def _definition(cs: FmuComponent):
    """The FMU's CasADi definition when it is one of ours
    (:func:`~cosim.calibration.symbolic.definition_of`, by its GUID), else
    ``None``; an FMU another tool generated (``generationTool``, FMI 2.0 and
    3.0 section 2.2.1) is not asked for one: that asks the registry, which
    loads every plugin's models (a few tenths of a second a small fit need not pay)."""
    # the generationTool this project's FMUs state (fmu_models/export/model_description.py)
    if not (cs.model_description.generationTool or "").startswith("fnn-cosim "):
        return None
    from .symbolic import definition_of

    return definition_of(cs)


def _states(cs: FmuComponent) -> list[str]:
    """The continuous states (from the Model Exchange interface's derivatives), or none."""
    md = cs.model_description
    if md.modelExchange is None:
        return []
    return [d.variable.derivative.name for d in md.derivatives]


def _predict(model, result, segments, held_out: Segment, logged: np.ndarray, problem: Problem) -> dict:
    """The held-out part simulated with the estimates from its logged start
    (states the log lacks: where the last fitted segment ended)."""
    end = model.simulate(result.theta, segments[-1], result.x0[-1])
    x0 = end.states[-1].copy()
    for j, s in enumerate(model.states):
        if logged[j]:
            x0[j] = problem.output_values[held_out.first, problem.state_columns[s]]
    tr = model.simulate(result.theta, held_out, x0)
    logged_y = problem.output_values[held_out.first:held_out.last]
    return {"times": problem.log.times[held_out.first:held_out.last], "logged": logged_y,
            "predicted": tr.outputs, "rms": np.sqrt(np.mean((tr.outputs - logged_y) ** 2, axis=0))}
