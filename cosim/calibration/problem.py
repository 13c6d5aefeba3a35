"""The calibration problem: an FMU's variables bound to a log's columns.

From the FMU's modelDescription, the log and the user's choices it decides,
once, and refuses in one line (:class:`~cosim.errors.ScenarioError`):

* **inputs** driven by the log: every input of the FMU a column holds (by
  the column map, or by name: ``x`` or ``<instance>.x`` as the project's
  results write it), converted to the input's unit; an input no column holds
  keeps its start value, or is **fitted** as an unknown constant when named
  in ``fit``;
* **outputs** compared with the log: the outputs (and states) a column
  holds, or those the settings name;
* **fitted** names: parameters of the FMU (not ``constant``, not also fixed)
  and inputs; their bounds from the variable's ``min``/``max`` (or the
  settings'), their first guess from the start value (or the settings');
* **fixed** values: parameters set to a value.

A unit a column declares that is not the variable's quantity is refused;
the same quantity in another unit is converted (``deg`` -> ``rad``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ..errors import ConnectionCheckError, ScenarioError, shown_text
from ..fmi import units as _units
from ..names import nearest_told, split_variable
from .log import Log

__all__ = ["Problem", "bind_problem", "log_instance"]


@dataclass(frozen=True, eq=False)
class Problem:
    """What is fitted to what (module docstring). Arrays are over the log's rows."""

    fmu: object  # cosim.fmi.fmu.FmuComponent (Co-Simulation), read-only here
    log: Log
    inputs: list[str]  # FMU inputs driven by the log
    input_values: np.ndarray  # rows x inputs, in the inputs' units
    outputs: list[str]  # FMU outputs compared
    output_values: np.ndarray  # rows x outputs
    fit: list[str]  # fitted names, parameters first then inputs
    fit_inputs: list[str]  # the fitted names that are inputs
    guess: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    fixed: dict[str, float]
    states: list[str]  # the FMU's continuous states (Model Exchange), or []
    state_columns: dict[str, int] = field(default_factory=dict)  # state -> its column among outputs, if logged
    units: dict[str, str] = field(default_factory=dict)
    defaults: dict[str, float] = field(default_factory=dict)  # the FMU's start value of each fitted name


def _float(value, default: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return default
    return v if np.isfinite(v) else default


def _convert(log: Log, column: str, declared: str | None, variable, where: str) -> np.ndarray:
    values = log.columns[column]
    src = declared if declared is not None else log.units.get(column, "")
    dst = getattr(variable, "unit", None) or ""
    if not src or not dst or src == dst:
        return values
    try:
        factor, offset = _units.conversion(src, dst)
    except ConnectionCheckError:
        raise ScenarioError(f"{where}: column {column} in {src!r} does not match {variable.name}'s unit "
                            f"{dst!r} (not one quantity)") from None
    return values * factor + offset


def _columns_of(log: Log, fmu, column_map, instance: str | None, extra: Mapping[str, str]) -> dict[str, tuple]:
    """FMU variable -> (column, declared unit or None)."""
    where = log.where()
    found: dict[str, tuple] = {}
    if column_map is not None:
        for name, col in column_map.columns.items():
            if name not in fmu.variables:
                raise ScenarioError(f"column map: {name!r} is not a variable of {fmu.path.name}"
                                    + nearest_told(name, fmu.variables))
            if col.column not in log.columns:
                raise log.no_column(col.column, name)
            found[name] = (col.column, col.unit)
    for name, column in extra.items():  # e.g. a scenario's connections: input -> the source's column
        if name not in found and column in log.columns:
            found[name] = (column, None)
    if instance is None:
        instance = log_instance(log, fmu.variables)
    for column in log.columns:
        name = column
        if name not in fmu.variables:
            split = split_variable(column, fmu.variables)
            if split is not None and split[0] == instance:
                name = split[1]
        if name in fmu.variables and name not in found:
            found[name] = (column, None)
    return found


def log_instance(log: Log, variables) -> str | None:
    """The prefix of the log's columns that names the most of the FMU's
    ``variables`` (``<instance>.<variable>``, the project's results), or
    ``None`` (none, or a tie)."""
    counts: dict[str, int] = {}
    for c in log.columns:
        split = split_variable(c, variables)
        if split is not None:
            counts[split[0]] = counts.get(split[0], 0) + 1
    ranked = sorted(counts.items(), key=lambda kv: -kv[1])
    if ranked and (len(ranked) == 1 or ranked[0][1] > ranked[1][1]):
        return ranked[0][0]
    return None


def bind_problem(fmu, log: Log, settings, column_map=None, instance: str | None = None,
                 extra_columns: Mapping[str, str] | None = None, states: Sequence[str] = ()) -> Problem:
    """The :class:`Problem` of fitting ``settings.fit`` of ``fmu`` to ``log``
    (module docstring). ``extra_columns``: input -> column, known from
    elsewhere (a scenario's connections); ``states``: the FMU's continuous
    states (from its Model Exchange interface)."""
    name = fmu.path.name
    variables = fmu.variables
    fit = list(dict.fromkeys(settings.fit))
    if not fit:
        raise ScenarioError("--fit: name at least one parameter to fit")
    fixed = dict(settings.fix)
    for key in fixed:
        v = variables.get(key)
        if v is None:
            raise ScenarioError(f"--fix {key}: {name} has no such parameter")
        if v.causality != "parameter" or v.variability == "constant":
            raise ScenarioError(f"--fix {key}: a {v.variability} {v.causality} of {name}, not a parameter one may set")
    for key in fit:
        v = variables.get(key)
        if v is None:
            known = ", ".join(x.name for x in fmu.model_description.modelVariables if x.causality == "parameter")
            raise ScenarioError(f"--fit {key}: {name} has no such parameter (its parameters: {shown_text(known, 200)})")
        if key in fixed:
            raise ScenarioError(f"--fit {key}: it is fixed (--fix {key}={fixed[key]:g}); fit it or fix it")
        if v.causality not in ("parameter", "input") or v.variability == "constant":
            raise ScenarioError(f"--fit {key}: a {v.variability} {v.causality} of {name}, not a parameter one may "
                                f"fit (parameters, and inputs as unknown constants)")
        if v.type not in ("Real", "Float64", "Float32"):
            raise ScenarioError(f"--fit {key}: a {v.type} variable; only real numbers are fitted")
    columns = _columns_of(log, fmu, column_map, instance, dict(extra_columns or {}))
    where = log.where()
    inputs = [p.name for p in fmu.inputs if p.name in columns and p.name not in fit]
    for key in fit:
        if variables[key].causality == "input" and key in columns:
            raise ScenarioError(f"--fit {key}: the log holds it (column {columns[key][0]}); an input is fitted "
                                f"only where the log lacks it")
    out_names = [p.name for p in fmu.outputs]
    if settings.outputs is not None:
        for o in settings.outputs:
            if o not in variables:
                raise ScenarioError(f"outputs: {o!r} is not a variable of {name}")
            if o not in columns:
                raise ScenarioError(f"outputs: {o!r}: the log holds no column for it")
        outputs = list(settings.outputs)
    else:
        outputs = [o for o in out_names if o in columns]
        outputs += [s for s in states if s in columns and s not in outputs]
    if not outputs:
        raise ScenarioError(f"{where}: holds none of {name}'s outputs (give a column map with --columns); "
                            f"its outputs: {shown_text(', '.join(out_names), 200)}")
    for o in settings.noise:
        if o not in outputs:
            raise ScenarioError(f"noise.{o}: not one of the outputs compared ({', '.join(outputs)})")
    log.check([columns[n][0] for n in inputs + outputs])
    u = np.column_stack([_convert(log, *columns[n], variables[n], where) for n in inputs]) if inputs else \
        np.zeros((log.times.size, 0))
    y = np.column_stack([_convert(log, *columns[n], variables[n], where) for n in outputs])
    params = [k for k in fit if variables[k].causality == "parameter"]
    fit_inputs = [k for k in fit if variables[k].causality == "input"]
    fit = params + fit_inputs
    guess, lower, upper, defaults = [], [], [], {}
    for key in fit:
        v = variables[key]
        start = _float(v.start, 0.0)
        defaults[key] = start
        g = float(settings.guess.get(key, start))
        lo, hi = _float(v.min, -np.inf), _float(v.max, np.inf)
        if key in settings.bounds:
            pair = settings.bounds[key]
            if len(pair) != 2 or not pair[0] < pair[1]:
                raise ScenarioError(f"bounds.{key} = {pair!r}: expected [min, max] with min < max")
            lo, hi = max(lo, pair[0]), min(hi, pair[1])
        if not lo <= g <= hi:
            raise ScenarioError(f"guess {key} = {g!r}: outside its bounds [{lo:g}, {hi:g}]")
        if lo == g and np.isfinite(lo):  # the solver starts strictly inside its bounds
            g = lo + 1e-9 * max(abs(lo), 1.0) if hi > lo else g
        guess.append(g)
        lower.append(lo)
        upper.append(hi)
    for key in settings.guess:
        if key not in fit:
            raise ScenarioError(f"guess {key}: not a fitted name (--fit {', '.join(fit)})")
    state_columns = {s: outputs.index(s) for s in states if s in outputs}
    units = {n: getattr(variables[n], "unit", None) or "" for n in fit + outputs + inputs}
    return Problem(fmu, log, inputs, u, outputs, y, fit, fit_inputs, np.array(guess), np.array(lower),
                   np.array(upper), fixed, list(states), state_columns, units, defaults)
