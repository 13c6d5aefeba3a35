"""A log's frames, attitude and rotors as the FMU's (docs/calibration.md, "Frames").

The column map states the log's frames (``world = "NED" | "ENU"``, ``body =
"FRD" | "FLU"``), its attitude (a quaternion, either scalar order, or Euler
angles), its rotors by position and turning sense (a rotor fed by a log
rotor that turns the other way is refused: its yaw torque's sign would be
reversed) and what they hold (speeds, throttle, PWM);
``[frames]`` names the FMU variables that are world vectors, body vectors
and Z-Y-X Euler angles. :func:`convert` adds the converted columns to the
log and points the map's columns at them, so the rest of the calibration
reads a log in the FMU's NED/FRD convention. The engine knows no vehicle:
every name comes from the map (the quadrotor's built-in maps are the
application's, ``quadrotor_paper/column_maps/``).

:func:`mirror_check`: after the fit, the same log read through the map's
mirrors (body FRD <-> FLU, rotors left <-> right), refitted briefly; a
mirror that fits far better is a :class:`~cosim.calibration.diagnostics.Diagnostic`.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable, Mapping

import numpy as np

from ..errors import ConnectionCheckError, ScenarioError
from ..fmi import units as _units
from .columns import POSITIONS, Column, ColumnMap
from .diagnostics import Diagnostic
from .log import Columns, Log

__all__ = ["convert", "world_matrix", "body_matrix", "matching_first_angles", "mirror_check", "MIRROR_FACTOR",
           "MIRROR_ITERATIONS"]

# log world -> NED: v_NED = W v_log (ENU: north = y, east = x, down = -z)
_WORLD = {"NED": np.eye(3), "ENU": np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]])}
# FRD -> log body: v_log = B v_FRD (FLU: left = -right, up = -down)
_BODY = {"FRD": np.eye(3), "FLU": np.diag([1.0, -1, -1])}
MIRROR_FACTOR = 4.0  # a mirror whose cost is below 1/4 of the map's (half its RMS residual) fits "far better"
MIRROR_ITERATIONS = 8  # the mirror's refit: Jacobians, from the fit's own first guesses


def world_matrix(world: str) -> np.ndarray:
    """``W``: a vector of the log's world frame in NED, ``v_NED = W v_log``."""
    return _WORLD[world]


def body_matrix(body: str) -> np.ndarray:
    """``B``: a vector of FRD in the log's body frame, ``v_log = B v_FRD``
    (``B`` is its own inverse for both frames)."""
    return _BODY[body]


def _values(log: Log, col: Column, what: str) -> tuple[np.ndarray, str]:
    """The column ``col`` of ``log`` and its unit (declared, else the log's)."""
    if col.column not in log.columns:
        raise log.no_column(col.column, what)
    return np.asarray(log.columns[col.column], dtype=float), col.unit or log.units.get(col.column, "")


def _in(values: np.ndarray, unit: str, to: str, what: str) -> np.ndarray:
    if not unit or unit == to:
        return values
    try:
        factor, offset = _units.conversion(unit, to)
    except ConnectionCheckError:
        raise ScenarioError(f"column map: {what} in {unit!r}: not convertible to {to!r}") from None
    return values * factor + offset


def convert(log: Log, column_map: ColumnMap | None, parameter: Callable[[str], float]) -> tuple[Log, ColumnMap | None]:
    """``log`` with the columns of ``column_map``'s frames, attitude and
    rotors converted to the FMU's NED/FRD convention, and the map pointing
    at them (module docstring); ``parameter(name)``: the value of an FMU
    parameter the map names (a rotor's angle, a top speed).

    * world vectors: ``v_NED = W v_log`` (ENU: swap x and y, negate z);
    * body vectors: ``v_FRD = B v_log`` (FLU: negate y and z);
    * attitude: ``R_NED_FRD = W R_log B`` (``R_log`` the log's body-to-world
      rotation, from its quaternion or its Z-Y-X Euler angles), as Z-Y-X
      Euler angles (``R = Rz(psi) Ry(theta) Rx(phi)``, paper eq. 8) with roll
      and yaw unwrapped (``numpy.unwrap``: each step's change taken in
      ``(-pi, pi]``, from the first row's value in ``(-pi, pi]``), so a yaw
      across +-pi is continuous as the plant integrates it;
    * rotors: the log's rotor at each FMU rotor's position, its speed, or
      its throttle or PWM through the map's curve.
    """
    if column_map is None or (column_map.frames is None and column_map.attitude is None
                              and column_map.rotors is None and column_map.world == "NED"
                              and column_map.body == "FRD"):
        return log, column_map
    frames = column_map.frames
    if frames is None and (column_map.world != "NED" or column_map.body != "FRD" or column_map.attitude is not None):
        said = ("world = 'ENU'" if column_map.world != "NED" else
                "body = 'FLU'" if column_map.body != "FRD" else "[attitude]")
        raise ScenarioError(f"column map: {said} converts the FMU's vectors: name them in [frames] (world = "
                            f"[[\"x\", \"y\", \"z\"]], body = [...], euler = [roll, pitch, yaw])")
    columns = dict(column_map.columns)
    derived: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}

    def put(variable: str, values: np.ndarray, unit: str, label: str) -> None:
        name = f"{variable} ({label})"
        derived[name] = values
        units[name] = unit
        columns[variable] = _column(name, unit)

    if frames is not None:
        W, B = world_matrix(column_map.world), body_matrix(column_map.body)
        for matrix, vectors, label in ((W, frames.world, "NED"), (B, frames.body, "FRD")):
            if np.array_equal(matrix, np.eye(3)):
                continue
            for vector in vectors:
                given = [v for v in vector if v in columns]
                if not given:
                    continue
                # a component of another (ENU: north is the log's y) needs that one; a sign needs only itself
                needed = {vector[j] for i, v in enumerate(vector) if v in columns
                          for j in np.flatnonzero(matrix[i])}
                if not needed <= set(given):
                    raise ScenarioError(f"column map: [{', '.join(vector)}] is converted to {label} as a vector: "
                                        f"name every component in [columns] (missing: "
                                        f"{', '.join(v for v in vector if v in needed - set(given))})")
                read = {v: _values(log, columns[v], v) for v in given}
                if len({u for _, u in read.values()}) > 1:
                    raise ScenarioError(f"column map: [{', '.join(vector)}]: its columns' units differ "
                                        f"({', '.join(repr(u) for _, u in read.values())}); one vector, one unit")
                # B is its own inverse: v_FRD = B v_log as v_log = B v_FRD
                for i, variable in enumerate(vector):
                    if variable in read:
                        values = sum(matrix[i, j] * read[vector[j]][0] for j in np.flatnonzero(matrix[i]))
                        put(variable, values, read[variable][1], label)
        euler = frames.euler
        source = column_map.attitude
        if source is None and euler is not None and all(e in column_map.columns for e in euler) and \
                (column_map.world != "NED" or column_map.body != "FRD"):
            source = {"euler": [column_map.columns[e] for e in euler]}  # the log's Euler angles, in its frames
        elif source is not None:
            if euler is None:
                raise ScenarioError("column map: [attitude] is converted to the FMU's Euler angles: name them in "
                                    "[frames] euler = [roll, pitch, yaw]")
            twice = [e for e in euler if e in column_map.columns]
            if twice:
                raise ScenarioError(f"column map: {twice[0]} is named in [columns] and made from [attitude]; "
                                    f"give it once")
            source = {"quaternion": source.quaternion, "scalar": source.scalar} if source.quaternion else \
                {"euler": source.euler}
        if source is not None:
            angles = _euler(_rotation(log, source), W, B)
            for variable, values in zip(euler, angles):
                put(variable, values, "rad", "from the attitude")
    if column_map.rotors is not None:
        for variable, values, unit, label in _rotors(log, column_map.rotors, parameter):
            if variable in column_map.columns:
                raise ScenarioError(f"column map: {variable} is named in [columns] and in [rotors]; give it once")
            if label is None:
                columns[variable] = _column(values, unit)  # a speed: the column as it is
            else:
                put(variable, values, unit, label)
    kept = log.columns.adding(derived) if isinstance(log.columns, Columns) else {**log.columns, **derived}
    converted = replace(log, columns=kept, units={**log.units, **units})
    return converted, column_map.model_copy(update={"columns": columns, "frames": None, "attitude": None,
                                                    "rotors": None, "world": "NED", "body": "FRD"})


def _column(name: str, unit: str | None) -> Column:
    return Column(column=name, unit=unit) if unit else Column(column=name)


def _rotation(log: Log, source: Mapping):
    """The log's body-to-world rotations (scipy ``Rotation``, one a row)."""
    from scipy.spatial.transform import Rotation

    if "quaternion" in source:
        q = np.column_stack([_values(log, c, "the attitude's quaternion")[0] for c in source["quaternion"]])
        norm = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(~np.isfinite(norm) | (norm < 0.5) | (norm > 2))
        if bad.size:
            raise ScenarioError(f"{log.where()}: row {bad[0] + 1}: the quaternion "
                                f"({', '.join(c.column for c in source['quaternion'])}) = {q[bad[0]].tolist()} is "
                                f"not a rotation (its norm {norm[bad[0]]:g}, not near 1)")
        return Rotation.from_quat(q, scalar_first=source["scalar"] == "first")  # normalized by scipy
    roll, pitch, yaw = [_in(*_values(log, c, f"the attitude's {n}"), "rad", f"the attitude's {n}")
                        for c, n in zip(source["euler"], ("roll", "pitch", "yaw"))]
    return Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll]))  # intrinsic: Rz(yaw) Ry(pitch) Rx(roll)


def _euler(rotation, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rows) of ``W R_log B``, roll and yaw unwrapped."""
    from scipy.spatial.transform import Rotation

    R = W @ rotation.as_matrix() @ B
    yaw, pitch, roll = Rotation.from_matrix(R).as_euler("ZYX").T
    return np.vstack([np.unwrap(roll), pitch, np.unwrap(yaw)])


def _nearest(rotors, angle: float) -> tuple[int, float]:
    """The log rotor nearest to ``angle`` (deg from the nose towards the right): its index and its gap, deg."""
    gaps = [abs((POSITIONS[p] - angle + 180.0) % 360.0 - 180.0) for p in rotors.positions]
    k = int(np.argmin(gaps))
    return k, gaps[k]


def _places(rotors, first: float) -> list[tuple[float, int | None, bool]]:
    """(angle, log rotor or None, same spin) of each FMU rotor with its rotor 1 at ``first`` (rad): the log
    rotor within 22.5 deg (the positions' names are 45 deg apart), and whether it turns the FMU rotor's way
    (true where the map states no spins)."""
    n = len(rotors.variables)
    out = []
    for i in range(n):
        angle = np.degrees(first + i * 2 * np.pi / n) % 360.0
        k, gap = _nearest(rotors, angle)
        if gap > 22.5:
            out.append((angle, None, False))
        else:
            out.append((angle, k, rotors.spins is None or rotors.spins[k] == rotors.variable_spins[i]))
    return out


def matching_first_angles(rotors) -> list[float]:
    """The first angles (rad, in (-pi, pi], smallest magnitude first) that put every FMU rotor on a log rotor
    that turns its way: each log position tried for the FMU's rotor 1."""
    found = set()
    for p in rotors.positions:
        deg = (POSITIONS[p] + 180.0) % 360.0 - 180.0
        deg = 180.0 if deg == -180.0 else deg
        places = _places(rotors, np.radians(deg))
        if all(k is not None and same for _, k, same in places) and len({k for _, k, _ in places}) == len(places):
            found.add(deg)
    return [float(np.radians(d)) for d in sorted(found, key=lambda d: (abs(d), d))]


def _advice(rotors) -> str:
    """Where the map's first angle would match, for an error message."""
    fits = matching_first_angles(rotors)
    if not fits:
        return "; no first angle puts every FMU rotor on a log rotor of its spin"
    said = " or ".join(f"{a:.6g} rad ({np.degrees(a):g} deg)" for a in fits)
    what = f"{rotors.first_angle} = " if isinstance(rotors.first_angle, str) else "first_angle = "
    return f"; {what}{said} puts every FMU rotor on a log rotor of its spin"


def _rotors(log: Log, rotors, parameter: Callable[[str], float]):
    """(FMU variable, column or values, unit, label or None) for each of the
    FMU's rotors: the log's rotor at its position (module docstring), of its
    spin where the map states the spins."""
    first = rotors.first_angle if not isinstance(rotors.first_angle, str) else parameter(rotors.first_angle)
    where = {name: POSITIONS[name] for name in rotors.positions}
    for i, (variable, (angle, k, same)) in enumerate(zip(rotors.variables, _places(rotors, first))):
        if k is None:
            raise ScenarioError(f"column map: rotors: the FMU's {variable} sits at {angle:g} deg from the nose "
                                f"(first_angle = {rotors.first_angle!r}); no log rotor there (its: "
                                f"{', '.join(f'{p} {d} deg' for p, d in where.items())})" + _advice(rotors))
        name = rotors.positions[k]
        if not same:  # the yaw reaction's sign would be the other rotor's: a fit would bend d or Iz to match
            raise ScenarioError(f"column map: rotors: the FMU's {variable} at {angle:g} deg turns "
                                f"{rotors.variable_spins[i]}, the log's {name} rotor ({rotors.columns[k].column}) "
                                f"{rotors.spins[k]}: its yaw torque would have the wrong sign (first_angle = "
                                f"{rotors.first_angle!r} = {first:.6g} rad)" + _advice(rotors))
        col = rotors.columns[k]
        if rotors.signal == "speed":
            if col.column not in log.columns:
                _values(log, col, f"the {name} rotor")  # one line naming it
            yield variable, col.column, col.unit, None
            continue
        raw, _ = _values(log, col, f"the {name} rotor")
        u = raw if rotors.signal == "throttle" else (raw - rotors.pwm_min) / (rotors.pwm_max - rotors.pwm_min)
        u = np.clip(u, 0.0, 1.0)  # below zero throttle (a disarmed PWM) the rotor stands; above full it saturates
        if rotors.a is not None:
            speed = rotors.a * u + rotors.c * u * u
        else:
            top = rotors.omega_max if not isinstance(rotors.omega_max, str) else parameter(rotors.omega_max)
            f = rotors.thrust_model_factor
            speed = top * np.sqrt((1 - f) * u + f * u * u)  # PX4's THR_MDL_FAC: thrust ~ Omega^2
        yield variable, speed, "rad/s", f"from {col.column}"


_MIRRORED = {"front": "front", "rear": "rear", "right": "left", "left": "right", "front-right": "front-left",
             "front-left": "front-right", "rear-right": "rear-left", "rear-left": "rear-right"}
_OTHER_SPIN = {"cw": "ccw", "ccw": "cw"}


def mirrors(column_map: ColumnMap) -> list[tuple[str, str, ColumnMap]]:
    """(subject, what, the map) of each mirror of ``column_map`` that
    changes something: the body frame FRD <-> FLU where the map converts
    body vectors or an attitude, the rotors left <-> right."""
    out = []
    frames = column_map.frames
    if frames is not None and (frames.body or column_map.attitude is not None):
        other = "FLU" if column_map.body == "FRD" else "FRD"
        out.append(("body", f"body = {other!r}", column_map.model_copy(update={"body": other})))
    if column_map.rotors is not None and any(_MIRRORED[p] != p for p in column_map.rotors.positions):
        mirrored = [_MIRRORED[p] for p in column_map.rotors.positions]
        update = {"positions": mirrored}
        if column_map.rotors.spins is not None:  # a mirror image turns each rotor the other way
            update["spins"] = [_OTHER_SPIN[s] for s in column_map.rotors.spins]
        out.append(("rotors", f"the rotors mirrored left-right (positions = {mirrored})",
                    column_map.model_copy(update={"rotors": column_map.rotors.model_copy(update=update)})))
    return out


def mirror_check(cost: float, column_map: ColumnMap, refit: Callable[[ColumnMap], object]) -> list[Diagnostic]:
    """A ``"mirror-fits-better"`` diagnostic for each mirror of
    ``column_map`` (:func:`mirrors`) whose brief refit (``refit(map)``, a
    :class:`~cosim.calibration.Calibration` from the fit's first guesses,
    with its noise levels, at most :data:`MIRROR_ITERATIONS` Jacobians) ends
    at a cost below ``cost / MIRROR_FACTOR``. Not from the estimates: a
    wrong map drives them to a bound (a thrust or gain at 0), from where a
    refit scaled by them cannot move. A mirror the FMU cannot simulate says
    nothing."""
    found = []
    for subject, what, mirrored in mirrors(column_map):
        try:
            other = refit(mirrored.model_copy(update={"mirror_check": False})).fit.cost
        except ScenarioError:
            continue
        if other * MIRROR_FACTOR < cost:
            found.append(Diagnostic(
                "mirror-fits-better", f"the column map's mirror, {what}, fits far better: cost {other:.4g} against "
                f"{cost:.4g} (x{cost / max(other, 1e-300):.3g}) after a refit of at most "
                f"{MIRROR_ITERATIONS} Jacobians from the same first guesses; check the map's {subject}", subject))
    return found
