"""Toys for the engine's own tests: two tiny FMUs and a few Python components.

Nothing here knows the quadrotor, the wind gust or the flight controller; the
engine (:mod:`cosim`) is exercised on models whose answers can be derived by
hand.

The FMUs are built by ``fmu_models``' exporter. ``ToyFirstOrderLag``::

    dy/dt = (k u - y) / tau,      y(t0) = y_0,      rate = dy/dt (an output)

With ``u`` held constant over ``[t, t + h]`` the exact solution is

    y(t + h) = k u + (y(t) - k u) exp(-h / tau),

which the FMU's internal RK4 (``internal_step``) reproduces to round-off for
``h / tau`` small per internal step. ``ToyRunningSum`` (sampled-data, its sum
``s`` a local variable): ``y_n = s_n + u_n``, ``s_{n+1} = s_n + u_n``.

The Python components (:class:`Constant`, :class:`Step`, :class:`PController`
(publishing the internal signal ``error``),
:class:`Gain`, :class:`Probe` (no outputs), :class:`Failing`) take run-level
parameters and return to their base values when a run gives none.

:func:`register_toys` registers toy component kinds, an alias section, a
section and the toy FMU model in :mod:`cosim.scenario.registry`, every name prefixed
``toy_`` so nothing can clash with an application's registrations.
"""
from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
import pytest

from pydantic import Field, create_model

from cosim.scenario import registry
from cosim.component import PythonComponent, ports
from cosim.errors import ScenarioError
from cosim.scenario.definition import check_fmu_parameters
from cosim.scenario.schema import Number, Table
from fmu_models.export.build import cached_fmu
from fmu_models.export.model import FmuModel, Sampled
from fmu_models.export.variables import discrete, input_, output, parameter, state

__all__ = ["LAG", "LAG_TAU", "LAG_K", "lag_fmu_path", "lag_step", "lag_fmu2", "lag_fmu3", "RUNNING_SUM", "sum_fmu_path", "Constant", "Step",
           "PController", "Gain", "Probe", "Failing", "make_gain", "register_toys", "BUILDS"]

# ---- the toy FMU ----------------------------------------------------------------------------

LAG_TAU = 0.5  # s, default time constant
LAG_K = 2.0  # default gain

LAG = FmuModel(
    identifier="ToyFirstOrderLag",
    description="Toy first-order lag dy/dt = (k u - y) / tau for the engine's tests",
    variables=(
        state("y", "m", "lag output"),
        input_("u", "m", "lag input", start=0.0),
        output("rate", "m/s", "dy/dt = (k u - y) / tau"),
        parameter("tau", "s", "time constant", LAG_TAU, min=1e-3),
        parameter("k", "1", "static gain", LAG_K),
        parameter("y_0", "m", "initial value of y", 0.0),
    ),
    equations=lambda t, v: ({"y": (v["k"] * v["u"] - v["y"]) / v["tau"]},
                            {"rate": (v["k"] * v["u"] - v["y"]) / v["tau"]}),
    initial_state=lambda v: {"y": v["y_0"]},
)


@functools.lru_cache(maxsize=None)
def lag_fmu_path(fmi_version: int) -> Path:
    """The toy FMU file (content-addressed cache: built once, then reused)."""
    return cached_fmu(LAG, fmi_version)


# A sampled-data toy with a local variable: its running sum s is a discrete
# state (an FMI local), y = s + u has direct feedthrough, and doStep makes
# s_{n+1} = s_n + u_n. With s_0 = 0, s at t_n is the sum of the inputs before t_n.
RUNNING_SUM = FmuModel(
    identifier="ToyRunningSum",
    description="Toy sampled-data running sum s_{n+1} = s_n + u_n, y = s + u, for the engine's tests",
    variables=(
        input_("u", "m", "summed input", start=0.0),
        output("y", "m", "s + u"),
        parameter("dt", "s", "sample period", 0.01, min=1e-6),
        parameter("s_0", "m", "initial sum", 0.0),
        discrete("s", "m", "the running sum (a local variable)"),
    ),
    sampled=Sampled(update=lambda t, v: ({"y": v["s"] + v["u"]}, {"s": v["s"] + v["u"]}),
                    initial=lambda v, r: {"s": v["s_0"]}, n_random=0, seed=None, sample_period="dt"),
)


@functools.lru_cache(maxsize=None)
def sum_fmu_path(fmi_version: int) -> Path:
    """The running-sum toy FMU file."""
    return cached_fmu(RUNNING_SUM, fmi_version)


def lag_step(y: float, u: float, h: float, tau: float = LAG_TAU, k: float = LAG_K) -> float:
    """Exact y(t + h) of the lag from y(t) with u held over the step."""
    return k * u + (y - k * u) * math.exp(-h / tau)


@pytest.fixture(scope="session")
def lag_fmu2() -> Path:
    return lag_fmu_path(2)


@pytest.fixture(scope="session")
def lag_fmu3() -> Path:
    return lag_fmu_path(3)


# ---- toy Python components ---------------------------------------------------------------

class _Toy(PythonComponent):
    """A component with named float parameters: base values at construction,
    run-level overrides per run (unknown names refused)."""

    defaults: dict[str, float] = {}

    def __init__(self, name: str, **base: float):
        super().__init__(name)
        unknown = set(base) - set(self.defaults)
        if unknown:
            raise TypeError(f"{type(self).__name__} takes no parameter(s) {sorted(unknown)}")
        self.base = {**self.defaults, **{k: float(v) for k, v in base.items()}}
        self.p = dict(self.base)
        self.starts: list[tuple[float, float, int, int]] = []

    def set_parameters(self, values: Mapping[str, Any]) -> None:
        unknown = set(values) - set(self.defaults)
        if unknown:
            raise KeyError(f"component {self.name!r} has no parameter(s) {sorted(unknown)}")
        self.p = {**self.base, **{k: float(v) for k, v in values.items()}}

    def start(self, t0: float, h: float, n_steps: int, seed: int) -> None:
        self.starts.append((t0, h, n_steps, seed))


class Constant(_Toy):
    """out = value."""

    outputs = ports(("out", "m"))
    defaults = {"value": 1.0}

    def step(self, n, t, u):
        return np.array([self.p["value"]])


class Step(_Toy):
    """out = before for t < at, after from t = at on (1 ns tolerance)."""

    outputs = ports(("out", "m"))
    defaults = {"before": 0.0, "after": 1.0, "at": 0.0}

    def step(self, n, t, u):
        return np.array([self.p["after"] if t >= self.p["at"] - 1e-9 else self.p["before"]])


class PController(_Toy):
    """u = kp (r - y): direct feedthrough from y. Publishes the internal
    signal ``error`` = r - y (recordable and boundable, not connectable) and
    counts the calls of :meth:`internal_values`."""

    inputs = ports(("r", "m"), ("y", "m"))
    outputs = ports(("u", "m"))
    internals = ports(("error", "m"))
    defaults = {"kp": 1.0}

    def __init__(self, name: str, **base: float):
        super().__init__(name, **base)
        self.error = np.zeros(1)
        self.internal_reads = 0

    def step(self, n, t, u):
        self.error[0] = u[0] - u[1]
        return np.array([self.p["kp"] * self.error[0]])

    def internal_values(self):
        self.internal_reads += 1
        return self.error


class Gain(_Toy):
    """y = gain * u; ports without units (the unit check is skipped)."""

    inputs = ports("u")
    outputs = ports("y")
    defaults = {"gain": 1.0}

    def step(self, n, t, u):
        return self.p["gain"] * u


class Probe(_Toy):
    """No outputs: remembers (n, t, inputs) of every call; ``hook(n, t, u)``
    is called too if given."""

    inputs = ports(("y", "m"))
    outputs = ()

    def __init__(self, name: str, hook: Callable[[int, float, np.ndarray], None] | None = None):
        super().__init__(name)
        self.hook = hook
        self.calls: list[tuple[int, float, np.ndarray]] = []

    def start(self, t0, h, n_steps, seed):
        super().start(t0, h, n_steps, seed)
        self.calls = []

    def step(self, n, t, u):
        self.calls.append((n, t, np.array(u, dtype=float)))
        if self.hook is not None:
            self.hook(n, t, u)
        return np.empty(0)


class Failing(_Toy):
    """out = 1 until ``at``, then raises (mode 'raise') or outputs NaN or +inf."""

    outputs = ports(("out", "m"))
    defaults = {"at": 0.5}

    def __init__(self, name: str, mode: str = "raise", **base: float):
        super().__init__(name, **base)
        self.mode = mode

    def step(self, n, t, u):
        if t >= self.p["at"] - 1e-9:
            if self.mode == "raise":
                raise RuntimeError(f"toy failure at n = {n}")
            return np.array([math.nan if self.mode == "nan" else math.inf])
        return np.array([1.0])


def make_gain(name: str, **parameters: float) -> Gain:
    """A factory for ``[components.X] factory = "toy_models:make_gain"``."""
    return Gain(name, **parameters)


# ---- toy registrations ------------------------------------------------------------------------

BUILDS: list[int] = []  # FMI versions the registered toy model was built for, in order


def _numbers_only(cls) -> type[Table]:
    """The table of a toy kind: its defaults' names, each a number."""
    return create_model(f"{cls.__name__}Table", __base__=Table,
                        **{key: (Number, Field(default)) for key, default in cls.defaults.items()})


def _builder(cls) -> Callable[[str, Mapping[str, Any], registry.BuildContext], PythonComponent]:
    def build(name: str, params: Mapping[str, Any], context: registry.BuildContext) -> PythonComponent:
        return cls(name, **params)
    return build


class ToySumFmu(Table):
    """``[components.X] kind = "toy_sum_fmu", dt = 0.02``: the running sum as an FMU a kind builds."""

    fmi_version: int = 2
    dt: Number = None


def _build_sum_fmu(name: str, params: Mapping[str, Any], context: registry.BuildContext):
    from cosim.fmi.fmu import FmuComponent

    table = dict(params)
    parameters = {"dt": float(table["dt"])} if table.get("dt") is not None else {}
    return FmuComponent(name, sum_fmu_path(int(table.get("fmi_version", 2))), parameters=parameters)


def _build_lag(fmi_version: int) -> Path:
    BUILDS.append(fmi_version)
    return lag_fmu_path(fmi_version)


def _check_lag_parameter(name: str, value: float) -> None:
    var = LAG.variable(name)  # KeyError naming the variable
    if var.causality not in ("parameter", "input"):
        raise KeyError(f"{name!r} is a {var.causality} of {LAG.identifier}, not a parameter")
    var.check(value)  # ValueError naming the variable and its range


class ToyLag(Table):
    """``[toy_lag] fmu = "Lag", time_constant = 0.25, gain = 3.0``: sets the FMU's tau and k."""

    fmu: str = "Lag"
    time_constant: Number = None
    gain: Number = None


def _apply_toy_lag(where: str, table: ToyLag, fmus: dict[str, dict[str, Any]]) -> dict[str, Any]:
    if table.fmu not in fmus:
        raise ScenarioError(f"{where}.fmu = {table.fmu!r}: no such FMU; FMUs are: {', '.join(fmus)}")
    params = {name: getattr(table, key) for key, name in (("time_constant", "tau"), ("gain", "k"))
              if key in table.model_fields_set}
    check_fmu_parameters(f"{where}", fmus[table.fmu], params)
    fmus[table.fmu]["parameters"].update({k: float(v) for k, v in params.items()})
    return {"fmu": table.fmu, **params}


def register_toys() -> None:
    """Register the toy kinds, sections and model (once per process).

    Kinds ``toy_constant`` and ``toy_step`` share the alias section
    ``[toy_source]`` (instance ``source``); ``toy_p_controller`` has the
    alias ``[toy_controller]`` (instance ``ctrl``); ``toy_gain`` has none.
    Section ``[toy_lag]`` sets the lag's parameters; model
    ``toy_FirstOrderLag`` builds the toy FMU on demand.
    """
    registry.register_component_kind(registry.ComponentKind(
        "toy_constant", _builder(Constant), functools.partial(_numbers_only, Constant), "toy constant source",
        alias="toy_source", instance="source"))
    registry.register_component_kind(registry.ComponentKind(
        "toy_step", _builder(Step), functools.partial(_numbers_only, Step), "toy step source", alias="toy_source", instance="source"))
    registry.register_component_kind(registry.ComponentKind(
        "toy_p_controller", _builder(PController), functools.partial(_numbers_only, PController), "toy P controller",
        alias="toy_controller", instance="ctrl"))
    registry.register_component_kind(registry.ComponentKind(
        "toy_gain", _builder(Gain), functools.partial(_numbers_only, Gain), "toy gain"))
    registry.register_component_kind(registry.ComponentKind(
        "toy_sum_fmu", _build_sum_fmu, lambda: ToySumFmu, "toy running sum a kind builds as its FMU"))
    registry.register_section(registry.Section("toy_lag", lambda: ToyLag, _apply_toy_lag,
                                               "toy shorthand for the lag's parameters"))
    registry.register_fmu_model(registry.RegisteredModel("toy_FirstOrderLag", _build_lag, _check_lag_parameter))


# ---- a scenario of the toys ---------------------------------------------------------------------

# the P loop of the toy models by their registered kinds (the test's registry), its [record] to add
LOOP = """
name = "toy_loop"
connections = ["source.out -> ctrl.r", "Lag.y -> ctrl.y", "ctrl.u -> Lag.u"]

[simulation]
duration = 1.0
step = 0.1

[fmus.Lag]
model = "toy_FirstOrderLag"

[toy_source]
kind = "toy_constant"
value = 1.0

[toy_controller]
kp = 1.5

[toy_lag]
fmu = "Lag"
time_constant = 0.25

"""

# the P loop of the toy models as a scenario whose FMU is given by path (format it with lag=...):
# what a Dask worker finds without the test's registry (the components by factory)
LOOP_BY_PATH = """
name = "toy_loop_by_path"
connections = ["source.out -> ctrl.r", "Lag.y -> ctrl.y", "ctrl.u -> Lag.u"]
[simulation]
duration = 1.0
step = 0.1
[fmus.Lag]
path = "{lag}"
parameters = {{ tau = 0.25 }}
[components.source]
factory = "toy_models:Constant"
[components.ctrl]
factory = "toy_models:PController"
kp = 1.5
[record]
signals = ["Lag.y"]
"""
