"""The reference trajectories of the paper's missions, written once in CasADi.

Each trajectory is a pure function of time and parameters giving the
reference position p*(t) (m), its time derivative v*(t) = dp*/dt (m/s) and
its second derivative a*(t) = d²p*/dt² (m/s²), world frame NED (x north,
y east, z down: altitude is -z). Only p* and v* are written by hand; a* is
CasADi's symbolic derivative of v* with respect to t (:func:`_with_acceleration`),
so it cannot disagree with them. The same CasADi expressions are

* exported as a stateless FMU (:data:`REFERENCE_HOVER`,
  :data:`REFERENCE_TWO_CIRCLES`, :data:`REFERENCE_FIGURE_EIGHT`: outputs
  ``x, y, z, vx, vy, vz, ax, ay, az``, the trajectory's settings as parameters), built and
  validated by exactly the same code as the plant, like the ``WindGust``;
* evaluated in Python by :func:`evaluate`, which calls the model's own
  ``out`` function (the one the FMU's C code is generated from) on a whole
  time grid at once; ``quadrotor_paper.trajectories`` is built on it.

Where the path changes curvature at once (the two circles' tangent point,
their start and end) a* jumps: the derivative of an ``if_else`` is the
derivative of the branch taken, so a* is the one-sided value, never an
impulse.

The parameter declarations (units, start values = the missions' defaults,
inclusive ranges) are the one place the admissible values are stated: the
FMU refuses a value outside them, and :func:`check_parameter` is the same test
for Python (with the message "must be positive" for a non-positive value of a
parameter whose floor is positive).

Piecewise parts are ``casadi.if_else``/``fmin``/``fmax`` of the time: there is
no Python branching on t, so one expression covers the whole mission.

Ranges (all inclusive, as FMI's):

* sizes (``radius``, ``half_length``, ``half_width``): [1 mm, 10 km]. The
  floor keeps out zero and the values next to it, where the path degenerates
  and ``s / radius`` blows up; 1 mm is the plant's own floor for a length (its
  arm length ``l``), orders of magnitude below any path a vehicle flies. The
  ceiling is the extent of the plant's world frame: a flat, non-rotating NED
  frame with constant gravity, a local tangent plane that 10 km from its
  origin is already 7.8 m above the Earth's surface.
* positions (``x0, y0, z0``; Hover's held point) and ``climb``: [-10 km,
  10 km], the same frame extent (``climb`` may be negative: descend first).
* speeds (``speed``, ``max_speed``): [1 mm/s, 340 m/s]. The floor keeps out
  zero (a path never flown; ``path_time`` and ``lap_time`` divide by the
  speed). The ceiling is the speed of sound at sea level: no rotorcraft flies
  near it, and the plant's incompressible drag model ends there.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Mapping

from ..export.model import FmuModel
from ..lazy_casadi import ca
from ..export.variables import Variable, output, parameter

__all__ = ["REFERENCE_HOVER", "REFERENCE_TWO_CIRCLES", "REFERENCE_FIGURE_EIGHT", "REFERENCE_MODELS",
           "OUTPUT_NAMES", "LENGTH_RANGE", "POSITION_RANGE", "SPEED_RANGE",
           "two_circles_timing", "figure_eight_timing", "evaluate", "evaluate_outputs", "check_parameter", "reference_function"]

LENGTH_RANGE = (1e-3, 1e4)  # m: sizes of a path
POSITION_RANGE = (-1e4, 1e4)  # m: points and altitude changes in the world frame
SPEED_RANGE = (1e-3, 340.0)  # m/s

_OUTPUTS = (
    output("x", "m", "reference position north (world frame, NED)"),
    output("y", "m", "reference position east (world frame, NED)"),
    output("z", "m", "reference position down (world frame, NED; altitude is -z)"),
    output("vx", "m/s", "reference velocity north, dx/dt"),
    output("vy", "m/s", "reference velocity east, dy/dt"),
    output("vz", "m/s", "reference velocity down, dz/dt"),
    output("ax", "m/s2", "reference acceleration north, d2x/dt2"),
    output("ay", "m/s2", "reference acceleration east, d2y/dt2"),
    output("az", "m/s2", "reference acceleration down, d2z/dt2"),
)
OUTPUT_NAMES: tuple[str, ...] = tuple(v.name for v in _OUTPUTS)


def _length(name, description, start):
    return parameter(name, "m", description, start, min=LENGTH_RANGE[0], max=LENGTH_RANGE[1])


def _position(name, description, start):
    return parameter(name, "m", description, start, min=POSITION_RANGE[0], max=POSITION_RANGE[1])


def _speed(name, description, start):
    return parameter(name, "m/s", description, start, min=SPEED_RANGE[0], max=SPEED_RANGE[1])


def _sqrt(x):
    """sqrt of a float (math's: the same correctly rounded double as CasADi's)
    or of a CasADi expression: timing a mission of built FMUs loads no CasADi."""
    return math.sqrt(x) if isinstance(x, (int, float)) else ca.sqrt(x)


def _outputs(p, v) -> dict[str, ca.SX]:
    return dict(zip(OUTPUT_NAMES, (*p, *v)))


def _with_acceleration(law):
    """``law(t, s)`` (giving p* and v*) with a* = dv*/dt added: the symbolic
    derivative of the written v*, so the acceleration is never a second copy
    of the path."""

    def equations(t, s):
        out = law(t, s)
        v = ca.vertcat(out["vx"], out["vy"], out["vz"])
        a = ca.jacobian(v, t)
        return {}, {**out, "ax": a[0], "ay": a[1], "az": a[2]}

    return equations


def _reference_model(identifier: str, description: str, parameters: tuple, law) -> FmuModel:
    """A reference trajectory as a stateless FMU model: the outputs p*, v*,
    a* of ``law`` (a* derived), its ``parameters``."""
    return FmuModel(identifier=identifier, description=description, variables=_OUTPUTS + parameters,
                    equations=_with_acceleration(law), initial_state=lambda s: {})


# ---- Hover ----------------------------------------------------------------------


def _hover(t, s):
    """Hold the point (x0, y0, z0): p* = (x0, y0, z0), v* = 0."""
    zero = ca.SX(0.0)
    return _outputs((s["x0"], s["y0"], s["z0"]), (zero, zero, zero))


REFERENCE_HOVER = _reference_model(
    "ReferenceHover",
    "Reference trajectory: hold a fixed position (world frame NED)",
    (
        _position("x0", "held position north", 0.0),
        _position("y0", "held position east", 0.0),
        _position("z0", "held position down (NED: -15 m is 15 m altitude)", -15.0),
    ),
    _hover,
)


# ---- two circles (paper section 5.2) -----------------------------------------------


def two_circles_timing(radius, speed, climb):
    """(slope, horizontal_speed, path_time) of the two circles: the altitude
    change per metre of horizontal path (1), the horizontal speed (m/s) that
    makes the 3-D speed ``speed``, and the time (s) to fly both circles.

    Works on floats and on CasADi symbols alike: the one definition of these
    quantities, used by the law below and by ``TwoCircles``' properties.
    """
    slope = climb / (2 * math.pi * radius)
    # products, not ** 2: CasADi squares by multiplying, Python's float ** calls pow,
    # which rounds differently in about 1 case in 1000
    horizontal_speed = speed / _sqrt(1 + slope * slope)
    path_time = 4 * math.pi * radius / horizontal_speed
    return slope, horizontal_speed, path_time


def _two_circles(t, s):
    """From the start point (x0, y0, z0): two circles of radius R tangent at
    it, both entered heading north, first clockwise seen from above (centre R
    to the east), then counter-clockwise (centre R to the west); the altitude
    rises linearly with the horizontal arc length by ``climb`` over the first
    and falls back over the second. Flown at the constant 3-D speed ``speed``
    from t = 0; before t = 0 and once both circles are flown the reference
    holds the start point (v* = 0)."""
    R, x0, y0, z0 = s["radius"], s["x0"], s["y0"], s["z0"]
    k, vh, _ = two_circles_timing(R, s["speed"], s["climb"])
    circle = 2 * math.pi * R
    distance = vh * t
    arc = ca.fmin(ca.fmax(distance, 0.0), 2 * circle)  # horizontal arc length flown
    moving = ca.logic_and(t >= 0, distance < 2 * circle)
    first = arc < circle
    # first circle: centre (x0, y0 + R), angle beta from -pi/2 increasing (clockwise from above, NED);
    # second circle: centre (x0, y0 - R), angle from +pi/2 decreasing (counter-clockwise)
    beta = ca.if_else(first, -math.pi / 2 + arc / R, math.pi / 2 - (arc - circle) / R)
    centre_y = ca.if_else(first, y0 + R, y0 - R)
    turn = ca.if_else(first, 1.0, -1.0)  # d beta / d arc * R
    altitude_gain = ca.if_else(first, k * arc, k * (2 * circle - arc))
    arc_rate = ca.if_else(moving, vh, 0.0)
    p = (x0 + R * ca.cos(beta), centre_y + R * ca.sin(beta), z0 - altitude_gain)
    v = (-ca.sin(beta) * turn * arc_rate, ca.cos(beta) * turn * arc_rate, ca.if_else(first, -k, k) * arc_rate)
    return _outputs(p, v)


REFERENCE_TWO_CIRCLES = _reference_model(
    "ReferenceTwoCircles",
    "Reference trajectory of the LM-FNN paper's simulation mission (section 5.2): two circles, "
    "clockwise climbing then counter-clockwise descending, at a constant speed; world frame NED",
    (
        _length("radius", "radius of both circles (section 5.2: 20 m diameter)", 10.0),
        _speed("speed", "constant 3-D speed along the path", 2.5),
        _position("climb", "altitude gained over the first circle and lost over the second "
                           "(negative: descend first)", 5.0),
        _position("x0", "start point north (the circles' common tangent point)", 0.0),
        _position("y0", "start point east", 0.0),
        _position("z0", "start point down (NED: -15 m is 15 m altitude)", -15.0),
    ),
    _two_circles,
)


# ---- figure-eight (paper section 6.1) -----------------------------------------------


def figure_eight_timing(max_speed, half_length, half_width):
    """(omega, lap_time): the angular rate w (rad/s) that makes the largest
    speed along the lemniscate, reached at the crossing, ``max_speed``,
    w = max_speed / sqrt(a^2 + (2 c)^2), and the time of one lap 2 pi / w (s).

    Works on floats and on CasADi symbols alike.
    """
    width = 2 * half_width
    omega = max_speed / _sqrt(half_length * half_length + width * width)
    return omega, 2 * math.pi / omega


def _figure_eight(t, s):
    """A lemniscate of Gerono at constant altitude around (x0, y0, z0):
    x = x0 + a sin(w t), y = y0 + c sin(2 w t), z = z0."""
    a, c = s["half_length"], s["half_width"]
    w, _ = figure_eight_timing(s["max_speed"], a, c)
    p = (s["x0"] + a * ca.sin(w * t), s["y0"] + c * ca.sin(2 * w * t), s["z0"])
    v = (a * w * ca.cos(w * t), 2 * c * w * ca.cos(2 * w * t), ca.SX(0.0))
    return _outputs(p, v)


REFERENCE_FIGURE_EIGHT = _reference_model(
    "ReferenceFigureEight",
    "Reference trajectory of the LM-FNN paper's experiment (section 6.1): a figure-8 "
    "(lemniscate of Gerono) at constant altitude; world frame NED",
    (
        _speed("max_speed", "largest speed along the figure-8, reached at the crossing", 1.0),
        _length("half_length", "half length a of the figure-8 along north", 2.0),
        _length("half_width", "half width c of the figure-8 along east", 1.0),
        _position("x0", "crossing point north", 0.0),
        _position("y0", "crossing point east", 0.0),
        _position("z0", "crossing point down (NED: -1.5 m is 1.5 m altitude)", -1.5),
    ),
    _figure_eight,
)

REFERENCE_MODELS: dict[str, FmuModel] = {
    m.identifier: m for m in (REFERENCE_HOVER, REFERENCE_TWO_CIRCLES, REFERENCE_FIGURE_EIGHT)
}


# ---- the Python path ------------------------------------------------------------------

_FUNCTIONS: dict[str, ca.Function] = {}


def reference_function(model: FmuModel) -> ca.Function:
    """``(t, p) -> y``: the model's ``out`` function (the one compiled into
    the FMU) without its empty state and input; y = (x, y, z, vx, vy, vz, ax, ay, az),
    p the parameter vector in table order (``model.parameter_values()``).
    Called with a 1 x n row of times it evaluates all n at once (CasADi maps
    it over the columns)."""
    if model.identifier not in _FUNCTIONS:
        out = model.functions["out"]
        t = ca.SX.sym("t")
        p = ca.SX.sym("p", len(model.parameters))
        y = out(t, ca.SX(len(model.states), 1), ca.SX(len(model.inputs), 1), p)
        _FUNCTIONS[model.identifier] = ca.Function(f"reference_{model.identifier}", [t, p], [y],
                                                   ["t", "p"], ["y"])
    return _FUNCTIONS[model.identifier]


def evaluate_outputs(model: FmuModel, t, parameters: Mapping[str, float]) -> np.ndarray:
    """Every output (:data:`OUTPUT_NAMES`: p* in m, v* in m/s, a* in m/s²)
    at the times ``t`` (s, shape (n,)), shape (n, 9), for the parameter
    values ``parameters`` (by name; the others at their start values). The
    values are not checked here: see :func:`check_parameter`."""
    import numpy as np  # here: registering the trajectories (fnn-cosim's start) loads no numpy

    t = np.atleast_1d(np.asarray(t, dtype=float)).ravel()
    if t.size == 0:
        return np.zeros((0, len(OUTPUT_NAMES)))
    p = [float(parameters.get(v.name, v.start)) for v in model.parameters]
    return np.ascontiguousarray(reference_function(model)(ca.DM(t[None, :]), ca.DM(p)).full().T)


def evaluate(model: FmuModel, t, parameters: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """(p*, v*) of shape (n, 3) each: the first six columns of :func:`evaluate_outputs`."""
    import numpy as np

    y = evaluate_outputs(model, t, parameters)
    return np.ascontiguousarray(y[:, 0:3]), np.ascontiguousarray(y[:, 3:6])


def check_parameter(variable: Variable, value: float, name: str | None = None) -> None:
    """``ValueError`` if ``value`` is outside ``variable``'s declared range:
    the FMU's own test (:meth:`Variable.check`), named ``name`` (default the
    variable's). A parameter whose floor is positive says so for a value that
    is not: "radius = -10.0 must be positive"."""
    name = variable.name if name is None else name
    if variable.min > 0 and not value > 0:
        raise ValueError(f"{name} = {value!r} must be positive")
    (variable if name == variable.name else replace(variable, name=name)).check(value)
