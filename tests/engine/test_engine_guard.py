"""cosim.loop.guard on its own: every watched signal finite, bounded ones inside
their envelope, the first violation named in the DivergenceError."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.errors import CosimError, DivergenceError
from cosim.loop.guard import UNBOUNDED, Guard

NAMES = ["a", "b", "c"]


@pytest.fixture
def guard():
    return Guard(NAMES, {"b": (0.0, 2.0), "c": (-5.0, -1.0)})


def violation(guard, t, values) -> DivergenceError:
    values = np.array(values, dtype=float)
    assert not guard.ok(values)
    with pytest.raises(DivergenceError) as info:
        guard.raise_violation(t, values)
    return info.value


# ---- finite ----------------------------------------------------------------------------------

def test_finite_values_pass_unbounded_signals():
    g = Guard(["a", "b"], {})
    assert g.ok(np.array([0.0, -1e299]))
    assert g.ok(np.array([1e299, 5.0]))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_values_fail(bad):
    g = Guard(["a", "b"], {})
    assert not g.ok(np.array([1.0, bad]))
    exc = violation(g, 0.5, [1.0, bad])
    assert exc.signal == "b" and exc.bounds is None and exc.time == 0.5
    assert str(exc) == f"diverged at t = 0.5000 s: b = {bad!r} is not a finite number"


def test_a_finite_value_beyond_the_default_bound_counts_as_diverged():
    """Unbounded signals get the finite bound 1e300 (module docstring)."""
    g = Guard(["a"], {})
    exc = violation(g, 2.0, [1e301])
    assert exc.bounds == (-UNBOUNDED, UNBOUNDED)
    assert str(exc) == "diverged at t = 2.0000 s: a = 1e+301 is outside its envelope [-1e+300, 1e+300]"


# ---- envelope --------------------------------------------------------------------------------

def test_inside_the_envelope_passes(guard):
    assert guard.ok(np.array([1e6, 1.0, -3.0]))
    assert guard.ok(np.array([-1e6, 1.999, -4.999]))


@pytest.mark.parametrize("values, signal, value, bounds", [
    ([0.0, 2.5, -3.0], "b", 2.5, (0.0, 2.0)),
    ([0.0, -0.001, -3.0], "b", -0.001, (0.0, 2.0)),
    ([0.0, 1.0, 0.0], "c", 0.0, (-5.0, -1.0)),
    ([0.0, 1.0, -6.0], "c", -6.0, (-5.0, -1.0)),
])
def test_outside_the_envelope_fails_naming_signal_value_and_bounds(guard, values, signal, value, bounds):
    exc = violation(guard, 1.25, values)
    assert (exc.time, exc.signal, exc.value, exc.bounds) == (1.25, signal, value, bounds)
    assert str(exc) == (f"diverged at t = 1.2500 s: {signal} = {value!r} is outside its envelope "
                        f"[{bounds[0]:g}, {bounds[1]:g}]")


def test_nan_in_a_bounded_signal_is_told_as_not_finite(guard):
    exc = violation(guard, 3.0, [0.0, math.nan, -3.0])
    assert exc.signal == "b" and exc.bounds == (0.0, 2.0) and math.isnan(exc.value)
    assert str(exc) == "diverged at t = 3.0000 s: b = nan is not a finite number"


def test_the_first_violation_in_watch_order_is_named(guard):
    assert violation(guard, 0.0, [math.nan, 5.0, 0.0]).signal == "a"
    assert violation(guard, 0.0, [0.0, 5.0, math.inf]).signal == "b"
    assert violation(guard, 0.0, [0.0, 1.0, math.inf]).signal == "c"


def test_the_error_is_a_cosim_error_on_one_line(guard):
    exc = violation(guard, 0.01, [0.0, 9.0, -3.0])
    assert isinstance(exc, CosimError) and "\n" not in str(exc)


def test_bounds_on_unwatched_signals_are_refused():
    with pytest.raises(KeyError, match="bounds given for unwatched signals \\['z'\\]"):
        Guard(["a"], {"z": (0.0, 1.0)})


@pytest.mark.parametrize("low, high", [(1.0, 1.0), (2.0, 1.0)])
def test_an_empty_envelope_is_refused(low, high):
    with pytest.raises(ValueError, match=f"envelope of a: low {low} must be below high {high}"):
        Guard(["a"], {"a": (low, high)})


def test_no_watched_signals_is_always_ok():
    assert Guard([], {}).ok(np.array([]))


# ---- documented right behaviour the engine misses --------------------------------------------

def test_a_one_sided_envelope_is_enforced():
    g = Guard(["a"], {"a": (-math.inf, 1.0)})
    assert g.ok(np.array([0.5]))
    assert not g.ok(np.array([2.0]))


def test_an_envelope_with_bounds_of_very_different_size_is_enforced():
    g = Guard(["a"], {"a": (-1e20, 1.0)})
    assert not g.ok(np.array([1.5]))


def test_the_envelope_bounds_are_inside_it():
    g = Guard(["a"], {"a": (0.1, 0.3)})
    assert g.ok(np.array([0.1])) and g.ok(np.array([0.3]))
