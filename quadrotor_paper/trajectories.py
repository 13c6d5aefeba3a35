"""Reference trajectories: pure functions of time giving p*(t) and dp*/dt.

The contract (checked for every entry of :data:`TRAJECTORIES` by a test):
a trajectory is a frozen dataclass with parameters in SI units and a method
``reference(t) -> (p, v)`` taking an array of times (s) of shape (n,) and
returning positions p* (m) and their time derivatives v* = dp*/dt (m/s), both
of shape (n, 3), world frame NED (z down: altitude is -z). It is pure and
vectorized, so the master evaluates it once for the whole time grid of a run.
The controller needs v* for de/dt = v* - v (eq. 12 differentiated).

The paper's §5.2 and §6.1 describe their missions in one paragraph each; the
choices made here to pin them down are listed in ``docs/cosim.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping

import numpy as np

from cosim.component import Port, PythonComponent

__all__ = ["Hover", "TwoCircles", "FigureEight", "TRAJECTORIES", "make_trajectory", "ReferenceComponent",
           "REFERENCE_OUTPUTS"]


@dataclass(frozen=True)
class Hover:
    """Hold a fixed position: p* = (x, y, z), v* = 0."""

    x: float = 0.0  # m
    y: float = 0.0  # m
    z: float = -15.0  # m (NED: 15 m altitude)

    def reference(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        p = np.tile([self.x, self.y, self.z], (t.size, 1))
        return p, np.zeros_like(p)


@dataclass(frozen=True)
class TwoCircles:
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

    def __post_init__(self):
        for name in ("radius", "speed"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} = {getattr(self, name)!r} must be positive")

    @property
    def slope(self) -> float:
        """Altitude change per metre of horizontal path (1)."""
        return self.climb / (2 * math.pi * self.radius)

    @property
    def horizontal_speed(self) -> float:
        return self.speed / math.sqrt(1 + self.slope ** 2)

    @property
    def path_time(self) -> float:
        """Time (s) to fly both circles."""
        return 4 * math.pi * self.radius / self.horizontal_speed

    def reference(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        R, vh, k = self.radius, self.horizontal_speed, self.slope
        circle = 2 * math.pi * R
        s = np.clip(vh * t, 0.0, 2 * circle)  # horizontal arc length flown
        moving = (t >= 0) & (vh * t < 2 * circle)
        first = s < circle
        # first circle: centre (x0, y0 + R), angle beta from -pi/2 increasing (clockwise from above, NED)
        # second circle: centre (x0, y0 - R), angle from +pi/2 decreasing (counter-clockwise)
        beta = np.where(first, -math.pi / 2 + s / R, math.pi / 2 - (s - circle) / R)
        centre_y = np.where(first, self.y0 + R, self.y0 - R)
        turn = np.where(first, 1.0, -1.0)  # d beta / d s * R
        x = self.x0 + R * np.cos(beta)
        y = centre_y + R * np.sin(beta)
        altitude_gain = np.where(first, k * s, k * (2 * circle - s))
        z = self.z0 - altitude_gain
        sdot = np.where(moving, vh, 0.0)
        vx = -np.sin(beta) * turn * sdot
        vy = np.cos(beta) * turn * sdot
        vz = np.where(first, -k, k) * sdot
        return np.column_stack([x, y, z]), np.column_stack([vx, vy, vz])


@dataclass(frozen=True)
class FigureEight:
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

    def __post_init__(self):
        for name in ("max_speed", "half_length", "half_width"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} = {getattr(self, name)!r} must be positive")

    @property
    def omega(self) -> float:
        return self.max_speed / math.hypot(self.half_length, 2 * self.half_width)

    @property
    def lap_time(self) -> float:
        return 2 * math.pi / self.omega

    def reference(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        w, a, c = self.omega, self.half_length, self.half_width
        p = np.column_stack([self.x0 + a * np.sin(w * t), self.y0 + c * np.sin(2 * w * t),
                             np.full_like(t, self.z0)])
        v = np.column_stack([a * w * np.cos(w * t), 2 * c * w * np.cos(2 * w * t), np.zeros_like(t)])
        return p, v


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
)


class ReferenceComponent(PythonComponent):
    """The trajectory as a component without inputs: evaluated once per run on
    the time grid ``t0 + n h`` (n = 0..N), then read row by row."""

    outputs = REFERENCE_OUTPUTS

    def __init__(self, trajectory, name: str = "reference"):
        super().__init__(name)
        self.trajectory = trajectory
        self._table = np.zeros((1, 6))

    def set_parameters(self, values: Mapping[str, Any]) -> None:
        if values:
            params = {f.name: getattr(self.trajectory, f.name) for f in fields(self.trajectory)}
            unknown = set(values) - set(params)
            if unknown:
                raise KeyError(f"trajectory of {self.name!r} has no parameter(s) {sorted(unknown)}")
            self.trajectory = type(self.trajectory)(**{**params, **values})

    def start(self, t0: float, h: float, n_steps: int, seed: int) -> None:
        p, v = self.trajectory.reference(t0 + h * np.arange(n_steps + 1))
        self._table = np.ascontiguousarray(np.hstack([p, v]))

    def step(self, n: int, t: float, u: np.ndarray) -> np.ndarray:
        return self._table[n]
