"""Studies: one base scenario run over named cases, a grid, random draws and seeds.

A study is the one way this engine runs many simulations (``docs/studies.md``)::

    scenario = "circles"                  # required: a shipped scenario name or a path
                                          #   (relative to the study file)
    name = "wind_and_mass"                # default: the file name
    description = "..."

    [set]                                 # dotted scenario keys set for every run
    "simulation.duration" = 20.0

    [cases."pd+lm"]                       # a registered case (cosim.scenario.registry.register_case), as is;
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
from typing import Annotated, Any, Iterator, Mapping, Sequence

import numpy as np

from ..scenario import registry
from ..scenario.registry import Case, with_connections
from pydantic import BeforeValidator, Field, WithJsonSchema, model_validator

from ..errors import CosimError, ScenarioError
from ..files import read_toml
from ..limits import MAX_RUNS
from ..scenario.definition import Scenario, apply_overrides, parse_scenario, scenario_path
from ..scenario.schema import Count, NonNegativeInt, Strings, Table, json_schema, numbers, refuse, validate

__all__ = ["Case", "Study", "Run", "StudyFile", "parse_study", "load_study", "shipped_studies", "study_path", "study_json_schema", "runs", "plan",
           "count", "cells", "cell_of", "with_connections", "DISTRIBUTIONS", "MAX_RUNS"]

DISTRIBUTIONS = ("uniform", "normal", "choice")


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


# ---- the study file: its declaration -------------------------------------------------------------

def _seeds_value(value: Any) -> Any:
    """``N`` (seeds 0..N-1) or a list of distinct seeds, each in [0, 2^53]."""
    from ..limits import SEED_LIMIT

    if isinstance(value, list):
        for i, s in enumerate(value):
            if isinstance(s, bool) or not isinstance(s, int):
                raise refuse("expected an integer", key=f"[{i}]", value=s)
            if not 0 <= s <= SEED_LIMIT:
                raise refuse(f"a seed is an integer in [0, 2^53 = {SEED_LIMIT}]", key=f"[{i}]", value=s)
        if not value or len(set(value)) != len(value):
            raise refuse("expected distinct seeds, at least one", value=value)
        return tuple(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise refuse("expected a number of seeds or a list of seeds", value=value)
    if value < 1:
        raise refuse("must be positive", value=value)
    if value > MAX_RUNS:
        raise refuse(f"at most {MAX_RUNS} runs a study", value=value)
    return tuple(range(value))


Seeds = Annotated[Any, BeforeValidator(_seeds_value),
                  WithJsonSchema({"oneOf": [{"type": "integer", "minimum": 1, "maximum": MAX_RUNS,
                                             "description": "N: seeds 0..N-1"},
                                            {"type": "array", "items": {"type": "integer", "minimum": 0},
                                             "minItems": 1, "uniqueItems": True}]})]


class Distribution(Table):
    """A drawn key: exactly one of ``uniform = [low, high]`` (low < high),
    ``normal = [mean, std]`` (std >= 0), ``choice = [values...]``."""

    uniform: numbers(2) = Field(None, description="[low, high): rng.uniform(low, high)")
    normal: numbers(2) = Field(None, description="[mean, std]: rng.normal(mean, std)")
    choice: list[Any] = Field(None, min_length=1, description="[values...]: equally likely")

    @model_validator(mode="before")
    @classmethod
    def _a_table_of_known_keys(cls, data: Any) -> Any:
        if not isinstance(data, Mapping) or len(data) != 1 or next(iter(data)) not in DISTRIBUTIONS:
            raise refuse("expected one of { uniform = [low, high] }, { normal = [mean, std] }, "
                         "{ choice = [values...] }", value=data)
        kind, args = next(iter(data.items()))
        if kind == "choice" and (not isinstance(args, list) or not args):
            raise refuse("expected a non-empty list of values", key=kind, value=args)
        if kind != "choice" and (not isinstance(args, list) or len(args) != 2):
            raise refuse(f"expected [{'low, high' if kind == 'uniform' else 'mean, std'}]", key=kind, value=args)
        return data

    @model_validator(mode="after")
    def _ordered(self):
        if self.uniform is not None and not self.uniform[0] < self.uniform[1]:
            raise refuse("expected [low, high] with low < high", key="uniform", value=self.uniform)
        if self.normal is not None and self.normal[1] < 0:
            raise refuse("expected [mean, std] with std >= 0", key="normal", value=self.normal)
        return self

    @property
    def kind(self) -> tuple[str, tuple[Any, ...]]:
        """(kind, arguments)."""
        kind = next(iter(self.model_fields_set))
        return kind, tuple(getattr(self, kind))


class RandomSweep(Table):
    """``[sweep.random]``: ``samples`` draws of every other key (a dotted
    scenario key -> its :class:`Distribution`), crossed with the cases and the grid."""

    model_config = {**Table.model_config, "extra": "allow"}
    __pydantic_extra__: dict[str, Distribution]
    samples: Count = Field(..., description="the number of draws")
    seed: NonNegativeInt = Field(0, description="numpy.random.default_rng(seed); the keys drawn in file order")

    @model_validator(mode="before")
    @classmethod
    def _a_table_of_known_keys(cls, data: Any) -> Any:  # every other key is a drawn scenario key
        if not isinstance(data, Mapping):
            raise refuse("expected a table", value=data)
        if "samples" not in data:
            raise refuse("required, the number of draws", key="samples")
        if not set(data) - {"samples", "seed"}:
            raise refuse("no key to draw (add e.g. \"wind.speed\" = { uniform = [1.0, 5.0] })")
        return data


def _grid_values(value: Any) -> Any:
    if not isinstance(value, list) or not value:
        raise refuse("expected a non-empty list of values", value=value)
    seen = set()
    for v in value:  # a value twice would run twice and count as two independent samples of one cell
        number = isinstance(v, (int, float)) and not isinstance(v, bool)
        canonical = json.dumps(float(v) if number else v, sort_keys=True, default=str)
        if canonical in seen:
            raise refuse(f"{v!r} is given twice; a grid value is one point", value=value)
        seen.add(canonical)
    return value


class Sweep(Table):
    """``[sweep]``: seeds, a grid and random draws."""

    seeds: Seeds = Field(None, description="N (seeds 0..N-1) or a list; default: the scenario's own seed")
    grid: dict[str, Annotated[list[Any], BeforeValidator(_grid_values)]] = Field(
        default_factory=dict, description="dotted scenario key -> its values; the cartesian product")
    random: RandomSweep = Field(None)


class CaseTable(Table):
    """``[cases.<name>]``: a registered case (only its ``seeds`` may be given)
    or an inline one (``set`` and/or ``connect``)."""

    label: Annotated[str, Field(strict=True)] = Field(None, description="the case's name in tables and plots")
    set: dict[str, Any] = Field(None, description="dotted scenario keys this case sets")
    connect: Strings = Field(None, description="connections added to the scenario's")
    seeds: Seeds = Field(None, description="this case's seeds (default: the study's)")


class StudyFile(Table):
    """A study file (``docs/studies.md``)."""

    scenario: Annotated[str, Field(strict=True)] = Field(
        None, description="required: a shipped scenario's name, or a path relative to this file")
    name: Annotated[str, Field(strict=True, min_length=1)] = Field(None, description="default: the file's name")
    description: Annotated[str, Field(strict=True)] = ""
    set: dict[str, Any] = Field(default_factory=dict, description="dotted scenario keys set for every run")
    cases: dict[str, CaseTable] = Field(default_factory=dict, description="named sets of overrides: the rows")
    sweep: Sweep = Field(default_factory=Sweep)


def study_json_schema() -> dict[str, Any]:
    """The JSON Schema of a study file (``fnn-cosim schema study``)."""
    return json_schema(StudyFile, "fnn-cosim study",
                       "A study: a scenario over named cases, a grid, random draws and seeds (docs/studies.md)")


# ---- reading ------------------------------------------------------------------------------

def _quoted(key: str) -> str:
    return f'"{key}"' if "." in key else key


def _check(where: str, base: Scenario, overrides: Mapping[str, Any]) -> None:
    """Refuse overrides the scenario does not take, naming the study key."""
    try:
        parse_scenario(apply_overrides(dict(base.raw), overrides), source=base.source)
    except CosimError as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def _case(where: str, name: str, spec: CaseTable) -> Case:
    """A registered case (its ``seeds`` may be given) or an inline one."""
    known = registry.cases().get(name)
    given = spec.model_fields_set
    if known is not None:
        for key in ("set", "connect", "label"):
            if key in given:
                raise ScenarioError(f"{where}.{key}: {name!r} is a registered case (its own settings); "
                                    f"give an inline case another name")
        return replace(known, seeds=spec.seeds if "seeds" in given else known.seeds)
    if "set" not in given and "connect" not in given:
        cases = ", ".join(registry.cases()) or "(none registered)"
        raise ScenarioError(f"{where}: not a registered case ({cases}); an inline case gives 'set' or 'connect'")
    return Case(name, dict(spec.set or {}), tuple(spec.connect or ()), spec.label or name,
                spec.seeds if "seeds" in given else None)


def _scenario_file(name: str | None, source: Path | None) -> Path:
    if name is None:
        raise ScenarioError("scenario: required, a shipped scenario name or a file path")
    path = Path(name)
    if not path.is_absolute() and source is not None and (source.parent / path).exists():
        path = source.parent / path
    try:
        return scenario_path(path if path.exists() else name)
    except ScenarioError as exc:
        raise ScenarioError(f"scenario = {name!r}: {exc}") from None


def parse_study(raw: Mapping[str, Any], source: Path | None = None, base: Scenario | None = None) -> Study:
    """Validate a study given as a mapping (a parsed TOML document).

    ``base`` replaces the scenario the study names (``scenario`` may then be
    left out), e.g. to fly a shipped study on another mission."""
    doc = validate(StudyFile, dict(raw), quote=True)
    name = doc.name if doc.name is not None else (source.stem if source else "study")
    # a fault is named by where it is: the scenario's file, the [set] keys, or the scenario they make
    if base is None:
        path = _scenario_file(doc.scenario, source)
        document, label = read_toml(path, "scenario"), f"scenario = {doc.scenario!r}"  # its faults name the file
    else:
        path, document, label = base.source, base.raw, f"scenario {base.name!r}"
    if base is None or doc.set:
        try:
            document = apply_overrides(document, dict(doc.set))
        except ScenarioError as exc:
            raise ScenarioError(f"set: {exc}") from None
        try:
            base = parse_scenario(document, source=path)
        except ScenarioError as exc:
            key = str(exc).split(" ", 1)[0].rstrip(":")  # the key the refusal names first
            ours = any(key == k or key.startswith(f"{k}.") or k.startswith(f"{key}.") for k in doc.set)
            raise ScenarioError(f"{'set' if ours else label}: {exc}") from None

    cases = tuple(_case(f"cases.{_quoted(n)}", n, spec) for n, spec in doc.cases.items())
    for case in cases:
        _check(f"cases.{_quoted(case.name)}", base, case.applied_to(base.raw))
    case_keys = {k: c.name for c in cases for k in c.overrides}

    sweep = doc.sweep
    if sweep.seeds is not None:
        _check("sweep.seeds", base, {"simulation.seed": sweep.seeds[0]})
    grid: dict[str, tuple[Any, ...]] = {}
    for key, values in sweep.grid.items():
        where = f"sweep.grid.{_quoted(key)}"
        if key == "simulation.seed":
            raise ScenarioError(f"{where}: sweep seeds with sweep.seeds")
        if key in case_keys:
            raise ScenarioError(f"{where}: also set by case {case_keys[key]!r}; a key is set in one place")
        for value in values:
            _check(where, base, {key: value})
        grid[key] = tuple(values)

    random: dict[str, tuple[str, tuple[Any, ...]]] = {}
    rand = sweep.random
    for key, distribution in ((rand.model_extra or {}).items() if rand is not None else ()):
        where = f"sweep.random.{_quoted(key)}"
        if key in grid:
            raise ScenarioError(f"{where}: already swept in sweep.grid")
        if key == "simulation.seed":
            raise ScenarioError(f"{where}: sweep seeds with sweep.seeds")
        if key in case_keys:
            raise ScenarioError(f"{where}: also set by case {case_keys[key]!r}; a key is set in one place")
        random[key] = distribution.kind
        kind, args = random[key]
        for value in (args if kind == "choice" else args[:1]):
            _check(where, base, {key: value})
    study = Study(name=name, description=doc.description, scenario=base, cases=cases, grid=grid, random=random,
                  samples=rand.samples if rand is not None else 0, random_seed=rand.seed if rand is not None else 0,
                  seeds=sweep.seeds, source=source)
    total = count(study)
    if total > MAX_RUNS:
        raise ScenarioError(f"study {name!r}: {total} runs; at most {MAX_RUNS} a study (split it, or sweep "
                            f"fewer values)")
    return study


def shipped_studies() -> dict[str, Path]:
    """The studies of the registered folders (:func:`cosim.scenario.registry.register_studies`), by name."""
    return registry.files_by_name(registry.study_folders())


def study_path(name_or_path: str | Path) -> Path:
    """A path as given (an existing file, or any name ending in ``.toml``,
    left for the reader to refuse), or the registered study of that name."""
    path = Path(name_or_path)
    if path.exists() or path.suffix == ".toml":
        return path
    return shipped_studies().get(str(name_or_path), path)


def load_study(path: str | Path, base: Scenario | None = None) -> Study:
    """The study file at ``path`` (or a registered study's name,
    :func:`study_path`), read and checked against its scenario (the file's
    ``scenario``, or ``base`` when given: a command's scenario with its
    overrides)."""
    path = study_path(path)
    return parse_study(read_toml(path, "study"), source=path, base=base)


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
