"""Contract test for every trajectory, known answers for the paper's missions,
and the one CasADi definition behind them (``fmu_models.models.reference``):
the numbers of the former numpy formulas, the FMU's declared ranges, and the
same reference from the exported FMU."""
from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from fmu_models.models import reference as casadi_reference
from quadrotor_paper.trajectories import (TRAJECTORIES, FigureEight, Hover, ReferenceComponent, TwoCircles,
                                          make_trajectory)


@pytest.mark.parametrize("kind", sorted(TRAJECTORIES))
def test_contract(kind):
    """Frozen dataclass, SI defaults, pure and vectorized, v* = dp*/dt."""
    cls = TRAJECTORIES[kind]
    assert dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen
    traj = cls()
    t = np.linspace(0.0, 70.0, 70001)
    p, v = traj.reference(t)
    assert p.shape == v.shape == (t.size, 3)
    assert np.all(np.isfinite(p)) and np.all(np.isfinite(v))
    p2, v2 = traj.reference(t)  # pure: same answer twice
    np.testing.assert_array_equal(p, p2)
    np.testing.assert_array_equal(v, v2)
    ps, vs = traj.reference(t[1234:1235])  # a single time gives the same row
    np.testing.assert_array_equal(ps[0], p[1234])
    # the integral of v* is p* - p*(0) (robust to kinks in v*, unlike finite
    # differences); a jump of v* inside one 1 ms interval costs at most |dv| * 1 ms
    integral = np.concatenate([np.zeros((1, 3)), np.cumsum((v[1:] + v[:-1]) / 2 * np.diff(t)[:, None], axis=0)])
    np.testing.assert_allclose(p - p[0], integral, atol=3e-3)


@pytest.mark.parametrize("kind", sorted(TRAJECTORIES))
def test_make_trajectory_refuses_unknown_parameters(kind):
    with pytest.raises(KeyError, match="has no parameter"):
        make_trajectory(kind, wobble=1.0)


def test_two_circles_known_answers():
    tc = TwoCircles()
    t = np.linspace(0.0, tc.path_time, 20001)
    p, v = tc.reference(t)
    speed = np.linalg.norm(v, axis=1)
    np.testing.assert_allclose(speed[:-1], 2.5, rtol=1e-12)  # constant 2.5 m/s until the end
    np.testing.assert_allclose(p[0], [0, 0, -15], atol=1e-12)
    np.testing.assert_allclose(p[-1], [0, 0, -15], atol=1e-9)  # back at the start
    first = t < tc.path_time / 2
    # horizontal distance to each circle's centre is the radius, 10 m (20 m diameter)
    np.testing.assert_allclose(np.hypot(p[first, 0], p[first, 1] - 10), 10, rtol=1e-12)
    np.testing.assert_allclose(np.hypot(p[~first, 0], p[~first, 1] + 10), 10, rtol=1e-12)
    # clockwise seen from above (NED: heading increases) first, then counter-clockwise
    heading_rate = v[:-1, 0] * np.gradient(v[:-1, 1]) - v[:-1, 1] * np.gradient(v[:-1, 0])
    assert np.all(heading_rate[first[:-1]][5:-5] > 0) and np.all(heading_rate[~first[:-1]][5:-5] < 0)
    assert -p[:, 2].max() == pytest.approx(15.0) and -p[:, 2].min() == pytest.approx(20.0, abs=1e-6)
    assert tc.path_time == pytest.approx(4 * math.pi * 10 * math.sqrt(1 + (5 / (20 * math.pi)) ** 2) / 2.5)
    # after the path: hold the start point
    p_end, v_end = tc.reference(np.array([tc.path_time + 1.0, 60.0]))
    np.testing.assert_allclose(p_end, [[0, 0, -15]] * 2, atol=1e-9)
    np.testing.assert_array_equal(v_end, 0.0)


def test_figure_eight_known_answers():
    fe = FigureEight()
    t = np.linspace(0.0, fe.lap_time, 100001)
    p, v = fe.reference(t)
    assert np.linalg.norm(v, axis=1).max() == pytest.approx(1.0, rel=1e-9)  # maximum speed 1 m/s
    np.testing.assert_allclose(p.max(axis=0)[:2], [2.0, 1.0], rtol=1e-6)
    np.testing.assert_allclose(p[-1], p[0], atol=1e-9)  # closed after one lap
    np.testing.assert_array_equal(p[:, 2], -1.5)


def test_reference_component_reads_the_precomputed_grid():
    ref = ReferenceComponent(TwoCircles())
    ref.set_parameters({"speed": 1.0})
    ref.start(0.0, 0.01, 100, seed=0)
    p, v = TwoCircles(speed=1.0).reference(np.array([0.37]))
    a = TwoCircles(speed=1.0).acceleration(np.array([0.37]))
    np.testing.assert_allclose(ref.step(37, 0.37, None), np.concatenate([p[0], v[0], a[0]]))
    assert np.hypot(a[0, 0], a[0, 1]) > 0.09  # the turn: about v_h^2 / R = 0.1 m/s^2
    with pytest.raises(KeyError, match="no parameter"):
        ref.set_parameters({"radius_m": 1.0})


# ---- one definition in CasADi: the same numbers as before, the same as the FMUs ----

CIRCLES_GRID = 0.01 * np.arange(5001)  # the circles mission: 0..50 s, h = 0.01 s
FIGURE8_GRID = 0.01 * np.arange(6001)  # the figure-8 mission: 0..60 s

TWO_CIRCLES_CASES = [{}, {"speed": 1.0}, {"radius": 3.0, "speed": 1.7, "climb": -2.0, "x0": 1.0, "y0": -2.0, "z0": -7.0},
                     {"radius": 25.0, "speed": 6.0, "climb": 0.0}, {"radius": 0.5, "speed": 0.3, "climb": 12.0}]
FIGURE_EIGHT_CASES = [{}, {"max_speed": 1.3, "half_length": 3.1, "half_width": 0.7, "z0": -2.0},
                      {"max_speed": 0.4, "half_length": 1.0, "half_width": 2.5, "x0": -1.0, "y0": 0.5},
                      {"max_speed": 3.0, "half_length": 0.2, "half_width": 0.05}]
HOVER_CASES = [{}, {"x": 1.5, "y": -2.0, "z": -3.0}]
CASES = ([("two_circles", c, CIRCLES_GRID) for c in TWO_CIRCLES_CASES]
         + [("figure_eight", c, FIGURE8_GRID) for c in FIGURE_EIGHT_CASES]
         + [("hover", c, CIRCLES_GRID) for c in HOVER_CASES])
# the FMU of each kind, and the FMU parameter of each dataclass field where the names differ
FMU_OF = {"hover": casadi_reference.REFERENCE_HOVER, "two_circles": casadi_reference.REFERENCE_TWO_CIRCLES,
          "figure_eight": casadi_reference.REFERENCE_FIGURE_EIGHT}
RENAMED = {"hover": {"x": "x0", "y": "y0", "z": "z0"}}


def _numpy_reference(kind, params, t):
    """The numpy formulas of this module before the CasADi definition (commit
    43e2e1f), kept verbatim as the oracle that the numbers did not change."""
    traj = make_trajectory(kind, **params)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if kind == "hover":
        p = np.tile([traj.x, traj.y, traj.z], (t.size, 1))
        return p, np.zeros_like(p)
    if kind == "figure_eight":
        a, c = traj.half_length, traj.half_width
        w = traj.max_speed / math.hypot(a, 2 * c)
        p = np.column_stack([traj.x0 + a * np.sin(w * t), traj.y0 + c * np.sin(2 * w * t), np.full_like(t, traj.z0)])
        v = np.column_stack([a * w * np.cos(w * t), 2 * c * w * np.cos(2 * w * t), np.zeros_like(t)])
        return p, v
    R = traj.radius
    k = traj.climb / (2 * math.pi * R)
    vh = traj.speed / math.sqrt(1 + k ** 2)
    circle = 2 * math.pi * R
    s = np.clip(vh * t, 0.0, 2 * circle)
    moving = (t >= 0) & (vh * t < 2 * circle)
    first = s < circle
    beta = np.where(first, -math.pi / 2 + s / R, math.pi / 2 - (s - circle) / R)
    centre_y = np.where(first, traj.y0 + R, traj.y0 - R)
    turn = np.where(first, 1.0, -1.0)
    x = traj.x0 + R * np.cos(beta)
    y = centre_y + R * np.sin(beta)
    z = traj.z0 - np.where(first, k * s, k * (2 * circle - s))
    sdot = np.where(moving, vh, 0.0)
    v = np.column_stack([-np.sin(beta) * turn * sdot, np.cos(beta) * turn * sdot, np.where(first, -k, k) * sdot])
    return np.column_stack([x, y, z]), v


@pytest.mark.parametrize("kind, params, t", CASES)
def test_numbers_unchanged_on_the_mission_grids(kind, params, t):
    """The CasADi definition gives the numpy formulas' numbers on the whole
    mission (and before it, and after the path), to 1e-12 m and m/s; in fact
    bit for bit on this machine."""
    t = np.concatenate([[-1.0, -1e-9], t, [t[-1] + 30.0]])
    p, v = make_trajectory(kind, **params).reference(t)
    p_old, v_old = _numpy_reference(kind, params, t)
    np.testing.assert_allclose(p, p_old, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v, v_old, rtol=0, atol=1e-12)


def test_derived_times_unchanged():
    """path_time, slope, horizontal_speed, omega and lap_time (now written once
    with the law) against the former formulas, to the last bit or two."""
    for params in TWO_CIRCLES_CASES:
        tc = TwoCircles(**params)
        k = tc.climb / (2 * math.pi * tc.radius)
        vh = tc.speed / math.sqrt(1 + k ** 2)
        assert tc.slope == k
        assert tc.horizontal_speed == pytest.approx(vh, rel=5e-16, abs=0)
        assert tc.path_time == pytest.approx(4 * math.pi * tc.radius / vh, rel=5e-16, abs=0)
    assert TwoCircles().path_time == pytest.approx(50.42, abs=0.005)
    for params in FIGURE_EIGHT_CASES:
        fe = FigureEight(**params)
        w = fe.max_speed / math.hypot(fe.half_length, 2 * fe.half_width)
        assert fe.omega == pytest.approx(w, rel=5e-16, abs=0)
        assert fe.lap_time == pytest.approx(2 * math.pi / w, rel=5e-16, abs=0)
    assert FigureEight().lap_time == pytest.approx(17.8, abs=0.05)


@pytest.mark.parametrize("kind", sorted(TRAJECTORIES))
def test_vectorized_equals_one_time_at_a_time(kind):
    """The grid evaluation (the CasADi function mapped over a row of times) is
    the same as calling the FMU model's out function at each time alone."""
    traj = TRAJECTORIES[kind]()
    model = FMU_OF[kind]
    t = np.array([-0.5, 0.0, 0.37, 12.5, 25.21, 25.22, 50.41, 50.43, 59.99])
    p, v = traj.reference(t)
    out = model.functions["out"]
    values = {RENAMED.get(kind, {}).get(f.name, f.name): getattr(traj, f.name) for f in dataclasses.fields(traj)}
    parameters = model.parameter_values(**values)
    a = traj.acceleration(t)
    for i, ti in enumerate(t):
        y = np.array(out(ti, [], [], parameters)).ravel()
        np.testing.assert_array_equal(np.concatenate([p[i], v[i], a[i]]), y)
    ps, vs = traj.reference(0.37)  # a scalar time is a grid of one
    assert ps.shape == vs.shape == (1, 3)
    pe, ve = traj.reference(np.array([]))
    assert pe.shape == ve.shape == (0, 3)


@pytest.mark.parametrize("kind", sorted(TRAJECTORIES))
def test_fields_are_the_fmu_parameters_with_its_ranges(kind):
    """One declaration: each field is a parameter of the kind's FMU model with
    the field's default as its start value, and the dataclass accepts exactly
    the FMU's inclusive range (the bound itself, not the next double beyond)."""
    cls, model = TRAJECTORIES[kind], FMU_OF[kind]
    renamed = RENAMED.get(kind, {})
    names = [renamed.get(f.name, f.name) for f in dataclasses.fields(cls)]
    assert names == [v.name for v in model.parameters if v.name != "internal_step"]
    for f in dataclasses.fields(cls):
        variable = model.variable(renamed.get(f.name, f.name))
        assert variable.causality == "parameter" and variable.start == f.default and variable.unit in ("m", "m/s")
        assert math.isfinite(variable.min) and math.isfinite(variable.max)
        for bound, outward in ((variable.min, -math.inf), (variable.max, math.inf)):
            cls(**{f.name: bound})
            beyond = float(np.nextafter(bound, outward))
            with pytest.raises(ValueError, match=f"^{f.name} = "):
                cls(**{f.name: beyond})
        with pytest.raises(ValueError, match=f"^{f.name} = nan "):
            cls(**{f.name: float("nan")})


@pytest.mark.parametrize("kind, name", [("two_circles", "radius"), ("two_circles", "speed"),
                                        ("figure_eight", "max_speed"), ("figure_eight", "half_length"),
                                        ("figure_eight", "half_width")])
def test_non_positive_sizes_and_speeds_keep_their_message(kind, name):
    for value in (-10.0, 0.0):
        with pytest.raises(ValueError, match=re.escape(f"{name} = {value!r} must be positive")):
            make_trajectory(kind, **{name: value})
    floor = FMU_OF[kind].variable(name).min
    assert floor > 0
    with pytest.raises(ValueError, match=re.escape(f"{name} = {floor / 2!r} m")):  # positive, below the floor
        make_trajectory(kind, **{name: floor / 2})
    make_trajectory(kind, **{name: floor})


def test_out_of_range_positions_are_refused_by_name():
    with pytest.raises(ValueError, match=re.escape("z = 20000.0 m is outside its range [-10000.0, 10000.0]")):
        Hover(z=2e4)
    with pytest.raises(ValueError, match=re.escape("climb = -20000.0 m is outside its range")):
        TwoCircles(climb=-2e4)
    with pytest.raises(ValueError, match=re.escape("speed = 400.0 m/s is outside its range [0.001, 340.0]")):
        TwoCircles(speed=400.0)


@pytest.fixture(scope="module")
def reference_fmus():
    from fmu_models.export.build import cached_fmu

    return {kind: cached_fmu(model, 2) for kind, model in FMU_OF.items()}


@pytest.mark.parametrize("kind, params, t", [c for c in CASES if c[1] in (TWO_CIRCLES_CASES[2], FIGURE_EIGHT_CASES[1],
                                                                            HOVER_CASES[1], {})])
def test_the_fmu_flies_the_same_reference(reference_fmus, kind, params, t):
    """The exported FMU (FMI 2.0 co-simulation, run by fmpy over the whole
    mission) gives the dataclass's reference at every communication point."""
    import fmpy

    renamed = RENAMED.get(kind, {})
    start_values = {renamed.get(k, k): v for k, v in params.items()}
    r = fmpy.simulate_fmu(str(reference_fmus[kind]), stop_time=float(t[-1]), output_interval=0.01,
                          start_values=start_values, validate=False,
                          output=["x", "y", "z", "vx", "vy", "vz"])
    np.testing.assert_array_equal(r["time"], t)
    p, v = make_trajectory(kind, **params).reference(r["time"])
    fmu = np.column_stack([r[name] for name in ("x", "y", "z", "vx", "vy", "vz")])
    np.testing.assert_allclose(fmu, np.hstack([p, v]), rtol=0, atol=1e-12)
