"""Studies: one base scenario run over named cases, a grid, random draws and seeds.

A study is the one way this engine runs many simulations (``docs/studies.md``)::

    scenario = "circles"                  # required: a shipped scenario name or a path
                                          #   (relative to the study file)
    name = "wind_and_mass"                # default: the file name
    description = "..."

    [set]                                 # dotted scenario keys set for every run
    "simulation.duration" = 20.0

    [cases."pd+lm"]                       # a registered case (cosim.registry.register_case), as is;
    [cases.lm-bl]                         #   e.g. an application's controller variants and option rows
    seeds = 3                             # this case's seeds (else the study's)
    [cases.stiff]                         # an inline case: its own overrides and added connections
    label = "PD+LM, kp 4"
    set = { "controller.variant" = "pd+lm", "controller.position.kp" = 4.0 }
    connect = ["reference.{ax,ay,az} -> controller.{ax_ref,ay_ref,az_ref}"]

    [sweep]
    seeds = 10                            # simulation seeds 0..9 for each run, or a list [0, 4, 7];
                                          #   default: the scenario's seed only
    [sweep.grid]                          # the cartesian product of the lists
    "wind.speed" = [1.0, 3.0, 5.0]

    [sweep.random]                        # `samples` draws of every key, crossed with the grid
    samples = 20
    seed = 0                              # numpy.random.default_rng(seed), keys drawn in file order
    "fmus.Quadrotor.parameters.m" = { uniform = [0.856, 1.284] }   # [low, high)
    "wind.turbulence" = { normal = [0.5, 0.1] }                      # [mean, std]
    "trajectory.speed" = { choice = [2.0, 2.5] }                     # [values...]

A :class:`Run` is (case, grid point, random sample, seed); the plan is
ordered case, grid point, sample, seed and is generated lazily
(:func:`runs`), run by run, so a study of any size is planned in constant
memory and resumed by index. The same draws are crossed with every case and
grid point (common random numbers).

Errors in the study file are :class:`~cosim.errors.ScenarioError` naming the
key, e.g. ``sweep.random."wind.speed".uniform = [3, 1]: expected [low, high]
with low < high``.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from . import registry
from .registry import Case, with_connections
from .config import check_number
from .errors import CosimError, ScenarioError
from .scenario import (Scenario, apply_overrides, load_scenario, parse_scenario, read_toml, refuse_unknown,
                       scenario_path, string, strings, table)

__all__ = ["Case", "Study", "Run", "parse_study", "load_study", "runs", "plan", "count", "cells", "cell_of",
           "with_connections", "DISTRIBUTIONS", "MAX_RUNS"]

DISTRIBUTIONS = ("uniform", "normal", "choice")
MAX_RUNS = 1_000_000  # a study's runs: its runs.csv and its summary grow with them (docs/studies.md)
_TOP = {"scenario", "name", "description", "set", "sweep", "cases"}
_SWEEP = {"grid", "random", "seeds"}
_CASE = {"label", "set", "connect", "seeds"}


@dataclass(frozen=True)
class Study:
    """A validated study: the base scenario (``[set]`` applied) and its sweep."""

    name: str
    description: str
    scenario: Scenario
    cases: tuple[Case, ...] = ()
    grid: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    random: Mapping[str, tuple[str, tuple[Any, ...]]] = field(default_factory=dict)
    samples: int = 0
    random_seed: int = 0
    seeds: tuple[int, ...] | None = None  # None: the scenario's own seed
    source: Path | None = None

    @property
    def keys(self) -> list[str]:
        """The swept keys, grid first, in file order."""
        return list(self.grid) + [k for k in self.random if k not in self.grid]

    def case_seeds(self, case: Case | None) -> tuple[int, ...]:
        if case is not None and case.seeds is not None:
            return case.seeds
        return self.seeds if self.seeds is not None else (self.scenario.seed,)

    def definition(self) -> dict[str, Any]:
        """Everything the plan and the runs depend on, as JSON-ready data."""
        return {"scenario": self.scenario.raw, "scenario_file": str(self.scenario.source or ""),
                "cases": [c.describe() for c in self.cases], "grid": {k: list(v) for k, v in self.grid.items()},
                "random": {k: [kind, list(args)] for k, (kind, args) in self.random.items()},
                "samples": self.samples, "random_seed": self.random_seed,
                "seeds": None if self.seeds is None else list(self.seeds)}

    @property
    def fingerprint(self) -> str:
        """A hash of :meth:`definition`: a results folder holds the runs of one fingerprint."""
        text = json.dumps(self.definition(), sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def replace(self, **changes) -> "Study":
        return replace(self, **changes)


@dataclass(frozen=True)
class Run:
    """One run of a study: ``index`` in the plan, its case (``None`` for a
    study without cases), grid ``point`` (values in key order), random
    ``sample`` (``None`` without draws), ``seed`` and the swept ``values``
    (grid and drawn keys)."""

    index: int
    case: str | None
    point: tuple
    sample: int | None
    seed: int
    values: Mapping[str, Any]
    overrides: Mapping[str, Any]  # every dotted key this run sets on the base scenario: the case's, then values

    @property
    def cell(self) -> tuple:
        """What the summary groups by: the case and the grid point."""
        return (self.case,) + self.point


# ---- reading ------------------------------------------------------------------------------

def _q(key: str) -> str:
    return f'"{key}"' if "." in key else key


def _count(where: str, value: Any, positive: bool = False) -> int:
    """A whole number >= 0 (``positive``: >= 1), or the scenario's error naming ``where``."""
    return int(check_number(where, value, integer=True, positive=positive, nonnegative=not positive))


def _seeds(where: str, value: Any) -> tuple[int, ...]:
    """``N`` (seeds 0..N-1) or a list of distinct seeds."""
    from .fmu_component import SEED_LIMIT

    if isinstance(value, list):
        seeds = tuple(_count(f"{where}[{i}]", s) for i, s in enumerate(value))
        if not seeds or len(set(seeds)) != len(seeds):
            raise ScenarioError(f"{where} = {value!r}: expected distinct seeds, at least one")
    else:
        n = _count(where, value, positive=True)
        if n > MAX_RUNS:
            raise ScenarioError(f"{where} = {value!r}: at most {MAX_RUNS} runs a study")
        seeds = tuple(range(n))
    if max(seeds) > SEED_LIMIT:
        raise ScenarioError(f"{where} = {value!r}: a seed is at most 2^53 = {SEED_LIMIT}")
    return seeds


def _distribution(where: str, spec: Any) -> tuple[str, tuple[Any, ...]]:
    if not isinstance(spec, Mapping) or len(spec) != 1 or next(iter(spec)) not in DISTRIBUTIONS:
        raise ScenarioError(f"{where} = {spec!r}: expected one of {{ uniform = [low, high] }}, "
                            f"{{ normal = [mean, std] }}, {{ choice = [values...] }}")
    kind, args = next(iter(spec.items()))
    where = f"{where}.{kind}"
    if kind == "choice":
        if not isinstance(args, list) or not args:
            raise ScenarioError(f"{where} = {args!r}: expected a non-empty list of values")
        return kind, tuple(args)
    if not isinstance(args, list) or len(args) != 2:
        raise ScenarioError(f"{where} = {args!r}: expected [{'low, high' if kind == 'uniform' else 'mean, std'}]")
    a, b = (float(check_number(f"{where}[{i}]", v)) for i, v in enumerate(args))
    if kind == "uniform" and not a < b:
        raise ScenarioError(f"{where} = {args!r}: expected [low, high] with low < high")
    if kind == "normal" and b < 0:
        raise ScenarioError(f"{where} = {args!r}: expected [mean, std] with std >= 0")
    return kind, (a, b)


def _check(where: str, base: Scenario, overrides: Mapping[str, Any]) -> None:
    """Refuse overrides the scenario does not take, naming the study key."""
    try:
        parse_scenario(apply_overrides(dict(base.raw), overrides), source=base.source)
    except CosimError as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def _case(where: str, name: str, spec: Any) -> Case:
    """A ``[cases.NAME]`` table: a registered case (its ``seeds`` may be
    given) or an inline one (``set`` and/or ``connect``)."""
    spec = table(where, spec)
    refuse_unknown(f"{where}.", spec, _CASE)
    known = registry.cases().get(name)
    seeds = _seeds(f"{where}.seeds", spec["seeds"]) if "seeds" in spec else None
    if known is not None:
        for key in ("set", "connect", "label"):
            if key in spec:
                raise ScenarioError(f"{where}.{key}: {name!r} is a registered case (its own settings); "
                                    f"give an inline case another name")
        return replace(known, seeds=seeds if seeds is not None else known.seeds)
    if "set" not in spec and "connect" not in spec:
        cases = ", ".join(registry.cases()) or "(none registered)"
        raise ScenarioError(f"{where}: not a registered case ({cases}); an inline case gives 'set' or 'connect'")
    return Case(name, table(f"{where}.set", spec.get("set", {})),
                tuple(strings(f"{where}.connect", spec.get("connect", []))),
                string(f"{where}.label", spec.get("label", name)), seeds)


def _scenario_file(raw: Mapping[str, Any], source: Path | None) -> Path:
    if "scenario" not in raw or not isinstance(raw["scenario"], str):
        raise ScenarioError(f"scenario = {raw.get('scenario')!r}: required, a shipped scenario name or a file path")
    path = Path(raw["scenario"])
    if not path.is_absolute() and source is not None and (source.parent / path).exists():
        path = source.parent / path
    try:
        return scenario_path(path if path.exists() else raw["scenario"])
    except ScenarioError as exc:
        raise ScenarioError(f"scenario = {raw['scenario']!r}: {exc}") from None


def parse_study(raw: Mapping[str, Any], source: Path | None = None, base: Scenario | None = None) -> Study:
    """Validate a study given as a mapping (a parsed TOML document).

    ``base`` replaces the scenario the study names (``scenario`` may then be
    left out), e.g. to fly a shipped study on another mission."""
    raw = dict(raw)
    refuse_unknown("", raw, _TOP)
    name = string("name", raw.get("name", source.stem if source else "study"))
    if not name:
        raise ScenarioError("name = '': expected a non-empty string")
    description = string("description", raw.get("description", ""))
    fixed = table("set", raw.get("set", {}))
    scenario_file = _scenario_file(raw, source) if base is None else None
    try:
        if scenario_file is not None:
            base = load_scenario(scenario_file, dict(fixed))
        elif fixed:
            base = parse_scenario(apply_overrides(base.raw, dict(fixed)), source=base.source)
    except ScenarioError as exc:
        raise ScenarioError(f"set: {exc}") from None

    cases = tuple(_case(f"cases.{_q(n)}", n, spec) for n, spec in table("cases", raw.get("cases", {})).items())
    for case in cases:
        _check(f"cases.{_q(case.name)}", base, case.applied_to(base.raw))

    sweep = table("sweep", raw.get("sweep", {}))
    refuse_unknown("sweep.", sweep, _SWEEP)
    seeds = _seeds("sweep.seeds", sweep["seeds"]) if "seeds" in sweep else None
    if seeds is not None:
        _check("sweep.seeds", base, {"simulation.seed": seeds[0]})

    grid: dict[str, tuple[Any, ...]] = {}
    case_keys = {k: c.name for c in cases for k in c.overrides}
    for key, values in table("sweep.grid", sweep.get("grid", {})).items():
        where = f"sweep.grid.{_q(key)}"
        if key == "simulation.seed":
            raise ScenarioError(f"{where}: sweep seeds with sweep.seeds")
        if key in case_keys:
            raise ScenarioError(f"{where}: also set by case {case_keys[key]!r}; a key is set in one place")
        if not isinstance(values, list) or not values:
            raise ScenarioError(f"{where} = {values!r}: expected a non-empty list of values")
        for value in values:
            _check(where, base, {key: value})
        grid[key] = tuple(values)

    random: dict[str, tuple[str, tuple[Any, ...]]] = {}
    samples = random_seed = 0
    rand = sweep.get("random")
    if rand is not None:
        rand = table("sweep.random", rand)
        if "samples" not in rand:
            raise ScenarioError("sweep.random.samples: required, the number of draws")
        samples = _count("sweep.random.samples", rand["samples"], positive=True)
        random_seed = _count("sweep.random.seed", rand.get("seed", 0))
        for key, spec in rand.items():
            if key in ("samples", "seed"):
                continue
            where = f"sweep.random.{_q(key)}"
            if key in grid:
                raise ScenarioError(f"{where}: already swept in sweep.grid")
            if key == "simulation.seed":
                raise ScenarioError(f"{where}: sweep seeds with sweep.seeds")
            if key in case_keys:
                raise ScenarioError(f"{where}: also set by case {case_keys[key]!r}; a key is set in one place")
            random[key] = _distribution(where, spec)
            kind, args = random[key]
            for value in (args if kind == "choice" else args[:1]):
                _check(where, base, {key: value})
        if not random:
            raise ScenarioError("sweep.random: no key to draw (add e.g. \"wind.speed\" = { uniform = [1.0, 5.0] })")
    study = Study(name=name, description=description, scenario=base, cases=cases, grid=grid, random=random,
                  samples=samples, random_seed=random_seed, seeds=seeds, source=source)
    total = count(study)
    if total > MAX_RUNS:
        raise ScenarioError(f"study {name!r}: {total} runs; at most {MAX_RUNS} a study (split it, or sweep "
                            f"fewer values)")
    return study


def load_study(path: str | Path, base: Scenario | None = None) -> Study:
    path = Path(path)
    if not path.exists():
        raise ScenarioError(f"study {str(path)!r}: no such file")
    return parse_study(read_toml(path), source=path, base=base)


# ---- the plan -----------------------------------------------------------------------------

def _draws(study: Study) -> Iterator[dict[str, Any]]:
    """The random draws, one per sample, from a fresh generator: the same
    numbers every time, in constant memory (keys in file order)."""
    rng = np.random.default_rng(study.random_seed)
    for _ in range(study.samples):
        draw = {}
        for key, (kind, args) in study.random.items():
            if kind == "uniform":
                draw[key] = float(rng.uniform(args[0], args[1]))
            elif kind == "normal":
                draw[key] = float(rng.normal(args[0], args[1]))
            else:
                draw[key] = args[int(rng.integers(len(args)))]
        yield draw


def count(study: Study) -> int:
    """The number of runs of the study, without planning them."""
    points = math.prod(len(v) for v in study.grid.values())
    samples = study.samples or 1
    cases = study.cases or (None,)
    return sum(points * samples * len(study.case_seeds(c)) for c in cases)


def runs(study: Study, start: int = 0) -> Iterator[Run]:
    """Every run of the study from index ``start`` on, ordered case, grid
    point, sample, seed; generated one at a time."""
    index = 0
    for case in study.cases or (None,):
        fixed = case.applied_to(study.scenario.raw) if case is not None else {}
        seeds = study.case_seeds(case)
        for point in itertools.product(*study.grid.values()):
            values = dict(zip(study.grid, point))
            draws = enumerate(_draws(study)) if study.random else [(None, {})]
            for sample, draw in draws:
                swept = {**values, **draw}
                for seed in seeds:
                    if index >= start:
                        yield Run(index, case.name if case is not None else None, point, sample, seed, swept,
                                  {**fixed, **swept})
                    index += 1


def plan(study: Study) -> list[Run]:
    """The whole plan as a list (for small studies and tests; :func:`runs` streams it)."""
    return list(runs(study))


def cells(study: Study) -> list[tuple[Case | None, dict[str, Any]]]:
    """Every cell of the study (what the summary groups by: a case and a grid
    point), in plan order: ``(case, {grid key: value})``."""
    points = [dict(zip(study.grid, p)) for p in itertools.product(*study.grid.values())]
    return [(case, point) for case in study.cases or (None,) for point in points]


def cell_of(study: Study, index: int) -> int:
    """The number of the cell (in :func:`cells`' order) of run ``index``,
    computed from the plan's shape, without generating it."""
    n_points = math.prod(len(v) for v in study.grid.values())
    offset = index
    for c, case in enumerate(study.cases or (None,)):
        per_point = (study.samples or 1) * len(study.case_seeds(case))
        if offset < n_points * per_point:
            return c * n_points + offset // per_point
        offset -= n_points * per_point
    raise IndexError(f"run {index}: the study {study.name!r} has {count(study)} runs")
