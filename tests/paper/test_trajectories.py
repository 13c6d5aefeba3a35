"""Contract test for every trajectory, and known answers for the paper's missions."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from quadrotor_paper.trajectories import TRAJECTORIES, FigureEight, ReferenceComponent, TwoCircles, make_trajectory


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
    np.testing.assert_allclose(ref.step(37, 0.37, None), np.concatenate([p[0], v[0]]))
    with pytest.raises(KeyError, match="no parameter"):
        ref.set_parameters({"radius_m": 1.0})
