"""Reference trajectories: pure functions of time giving p*(t) and dp*/dt.

The contract (checked for every entry of :data:`TRAJECTORIES` by a test):
a trajectory is a frozen dataclass with parameters in SI units and a method
``reference(t) -> (p, v)`` taking an array of times (s) of shape (n,) and
returning positions p* (m) and their time derivatives v* = dp*/dt (m/s), both
of shape (n, 3), world frame NED (z down: altitude is -z), and a method
``acceleration(t)`` giving d²p*/dt² (m/s², shape (n, 3)). It is pure and
vectorized, so the master evaluates it once for the whole time grid of a run.
The controller needs v* for de/dt = v* - v (eq. 12 differentiated), and a*
for its acceleration feed-forward option (``docs/controller.md``).

The three trajectories here are written once, in CasADi, in
:mod:`fmu_models.models.reference`, which also exports each as a stateless
FMU (``ReferenceHover``, ``ReferenceTwoCircles``, ``ReferenceFigureEight``):
``reference(t)`` evaluates that definition (the FMU model's own ``out``
function) on the whole time grid at once, and the parameters' admissible
ranges are the FMU's declared ones, checked when a dataclass is made. A
scenario's ``[trajectory]`` flies the FMU (``model`` with
``fmu_parameters()``, :mod:`quadrotor_paper.components`); the dataclasses
serve the analyses that need p*(t) itself (plots, the stability package).

:class:`ReferenceComponent` runs any object of this contract as a Python
component of the master: a trajectory that has no FMU, such as the
stability package's :class:`~quadrotor_paper.stability.validation.Ramp`.

The paper's §5.2 and §6.1 describe their missions in one paragraph each; the
choices made here to pin them down are listed in ``docs/cosim.md``.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar, Mapping

from cosim.component import Port, PythonComponent
from fmu_models.models import reference as _reference

__all__ = ["Hover", "TwoCircles", "FigureEight", "TRAJECTORIES", "make_trajectory", "ReferenceComponent",
           "REFERENCE_OUTPUTS"]


class _CasadiReference:
    """What the three dataclasses share: their fields are the parameters of
    the FMU model ``model`` (``_renamed`` maps a field to its FMU parameter
    where the names differ), checked against its declared ranges when an
    instance is made, and ``reference(t)`` evaluates that model's CasADi
    definition."""

    model: ClassVar[Any]
    _renamed: ClassVar[Mapping[str, str]] = {}

    def __post_init__(self) -> None:
        for f in fields(self):
            variable = self.model.variable(self._renamed.get(f.name, f.name))
            _reference.check_parameter(variable, getattr(self, f.name), name=f.name)

    @classmethod
    def fmu_name(cls, field: str) -> str:
        """The FMU ``model``'s name of the parameter ``field``."""
        return cls._renamed.get(field, field)

    def fmu_parameters(self) -> dict[str, float]:
        """The parameter values of the FMU ``model``, by their FMU names."""
        return {self.fmu_name(f.name): getattr(self, f.name) for f in fields(self)}

    def reference(self, t):
        return _reference.evaluate(self.model, t, self.fmu_parameters())

    def acceleration(self, t) -> np.ndarray:
        """d²p*/dt² (m/s², shape (n, 3)) at the times ``t``: the symbolic
        derivative of the same CasADi v* (``fmu_models.models.reference``)."""
        import numpy as np  # here: registering the trajectories (fnn-cosim's start) loads no numpy

        return np.ascontiguousarray(_reference.evaluate_outputs(self.model, t, self.fmu_parameters())[:, 6:9])


@dataclass(frozen=True)
class Hover(_CasadiReference):
    """Hold a fixed position: p* = (x, y, z), v* = 0."""

    x: float = 0.0  # m
    y: float = 0.0  # m
    z: float = -15.0  # m (NED: 15 m altitude)

    model: ClassVar[Any] = _reference.REFERENCE_HOVER
    _renamed: ClassVar[Mapping[str, str]] = {"x": "x0", "y": "y0", "z": "z0"}  # x, y, z are its outputs


@dataclass(frozen=True)
class TwoCircles(_CasadiReference):
    """The simulation mission of §5.2: two circles, clockwise then
    counter-clockwise, climbing then descending, at a constant speed.

    From the start point (x0, y0, z0) the path is two circles of radius R
    tangent at the start, both entered heading north: first clockwise seen
    from above (centre R to the east), then counter-clockwise (centre R to the
    west); a figure-of-eight made of two full circles. The altitude rises
    linearly with the horizontal arc length by ``climb`` over the first circle
    and falls back over the second, so the path ends where it began. The
    reference moves along it at the constant 3-D speed ``speed`` (time-based,
    starting at t = 0 from the start point) and holds the start point once
    the path is complete (after ``path_time`` = 50.42 s with the defaults).
    """

    radius: float = 10.0  # m (20 m diameter)
    speed: float = 2.5  # m/s, constant along the path
    climb: float = 5.0  # m, altitude gained over the first circle
    x0: float = 0.0  # m
    y0: float = 0.0  # m
    z0: float = -15.0  # m (NED: hover at 15 m)

    model: ClassVar[Any] = _reference.REFERENCE_TWO_CIRCLES

    @property
    def slope(self) -> float:
        """Altitude change per metre of horizontal path (1)."""
        return _reference.two_circles_timing(self.radius, self.speed, self.climb)[0]

    @property
    def horizontal_speed(self) -> float:
        return _reference.two_circles_timing(self.radius, self.speed, self.climb)[1]

    @property
    def path_time(self) -> float:
        """Time (s) to fly both circles."""
        return _reference.two_circles_timing(self.radius, self.speed, self.climb)[2]


@dataclass(frozen=True)
class FigureEight(_CasadiReference):
    """The '8'-shaped time-based trajectory of the experiment, §6.1.

    A lemniscate of Gerono at constant altitude,
    x = x0 + a sin(w t), y = y0 + c sin(2 w t), z = z0,
    with w chosen so that the largest speed along it (reached at the crossing,
    where both terms peak) is ``max_speed``: w = max_speed / sqrt(a² + 4 c²).
    The defaults (4 m × 2 m at 1.5 m altitude) fit the 3 m × 5 m flight area
    of the paper's laboratory; one lap takes 17.8 s.
    """

    max_speed: float = 1.0  # m/s
    half_length: float = 2.0  # m, a
    half_width: float = 1.0  # m, c
    x0: float = 0.0  # m
    y0: float = 0.0  # m
    z0: float = -1.5  # m (NED: 1.5 m altitude)

    model: ClassVar[Any] = _reference.REFERENCE_FIGURE_EIGHT

    @property
    def omega(self) -> float:
        return _reference.figure_eight_timing(self.max_speed, self.half_length, self.half_width)[0]

    @property
    def lap_time(self) -> float:
        return _reference.figure_eight_timing(self.max_speed, self.half_length, self.half_width)[1]


TRAJECTORIES: dict[str, type] = {"hover": Hover, "two_circles": TwoCircles, "figure_eight": FigureEight}


def make_trajectory(kind: str, **parameters: Any):
    """A trajectory from its kind and parameters; errors name the bad key."""
    try:
        cls = TRAJECTORIES[kind]
    except KeyError:
        raise KeyError(f"unknown trajectory kind {kind!r}; known: {', '.join(TRAJECTORIES)}") from None
    known = {f.name for f in fields(cls)}
    unknown = set(parameters) - known
    if unknown:
        raise KeyError(f"trajectory {kind!r} has no parameter(s) {sorted(unknown)}; it has: {', '.join(sorted(known))}")
    return cls(**parameters)


REFERENCE_OUTPUTS = (
    Port("x", "m", description="reference position north"),
    Port("y", "m", description="reference position east"),
    Port("z", "m", description="reference position down"),
    Port("vx", "m/s", description="reference velocity north, dx*/dt"),
    Port("vy", "m/s", description="reference velocity east, dy*/dt"),
    Port("vz", "m/s", description="reference velocity down, dz*/dt"),
    Port("ax", "m/s2", description="reference acceleration north, d2x*/dt2"),
    Port("ay", "m/s2", description="reference acceleration east, d2y*/dt2"),
    Port("az", "m/s2", description="reference acceleration down, d2z*/dt2"),
)


class ReferenceComponent(PythonComponent):
    """The trajectory as a component without inputs: evaluated on the time
    grid ``t0 + n h`` a block of :data:`BLOCK` points at a time (vectorized,
    in memory that does not grow with the run), then read row by row."""

    outputs = REFERENCE_OUTPUTS
    BLOCK = 1000  # points evaluated at once

    def __init__(self, trajectory, name: str = "reference"):
        import numpy as np

        super().__init__(name)
        self.trajectory = trajectory
        self._table = np.zeros((1, len(REFERENCE_OUTPUTS)))
        self._first = 0

    def set_parameters(self, values: Mapping[str, Any]) -> None:
        if values:
            params = {f.name: getattr(self.trajectory, f.name) for f in fields(self.trajectory)}
            unknown = set(values) - set(params)
            if unknown:
                raise KeyError(f"trajectory of {self.name!r} has no parameter(s) {sorted(unknown)}")
            self.trajectory = type(self.trajectory)(**{**params, **values})

    def start(self, t0: float, h: float, n_steps: int, seed: int) -> None:
        self._t0, self._h, self._last = t0, h, n_steps
        self._fill(0)

    def _fill(self, first: int) -> None:
        import numpy as np

        n = np.arange(first, min(first + self.BLOCK, self._last + 1))
        t = self._t0 + self._h * n  # the master's own t_n, from the step counter
        p, v = self.trajectory.reference(t)
        self._table = np.ascontiguousarray(np.hstack([p, v, self.trajectory.acceleration(t)]))
        self._first = first

    def step(self, n: int, t: float, u: np.ndarray) -> np.ndarray:
        if not self._first <= n < self._first + len(self._table):
            self._fill(n)
        return self._table[n - self._first]
