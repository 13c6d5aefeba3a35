"""Divergence detection: every watched signal finite and inside its envelope.

One vectorized test per step, ``low <= s <= high`` over all watched signals
(bounds inclusive, compared exactly): it is false for NaN (every comparison
with NaN is) and for +-inf (every bound is finite: an infinite or missing
bound is taken as +-1e300), so the same test catches non-finite values and
envelope violations. Signals without declared bounds are only checked for
being finite numbers.
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from ..errors import DivergenceError

__all__ = ["Guard", "UNBOUNDED"]

UNBOUNDED = 1e300


class Guard:
    """Bounds on named signals.

    Parameters
    ----------
    names : names of the watched signals, in the order their values are given.
    bounds : ``name -> (low, high)`` for the signals with an envelope; the
        others are only checked to be finite.
    """

    def __init__(self, names: Sequence[str], bounds: Mapping[str, tuple[float, float]]):
        self.names = tuple(names)
        unknown = set(bounds) - set(self.names)
        if unknown:
            raise KeyError(f"bounds given for unwatched signals {sorted(unknown)}")
        lo = np.full(len(self.names), -UNBOUNDED)
        hi = np.full(len(self.names), UNBOUNDED)
        self.bounds: dict[str, tuple[float, float]] = {}
        for name, (low, high) in bounds.items():
            if not low < high:
                raise ValueError(f"envelope of {name}: low {low} must be below high {high}")
            i = self.names.index(name)
            lo[i] = max(low, -UNBOUNDED) if not math.isinf(low) else -UNBOUNDED
            hi[i] = min(high, UNBOUNDED) if not math.isinf(high) else UNBOUNDED
            self.bounds[name] = (low, high)
        self._lo, self._hi = lo, hi

    @property
    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """The inclusive bounds ``(low, high)`` of the watched signals, in order (finite)."""
        return self._lo, self._hi

    def ok(self, values: np.ndarray) -> bool:
        return bool(((values >= self._lo) & (values <= self._hi)).all())

    def raise_violation(self, t: float, values: np.ndarray) -> None:
        """Raise :class:`DivergenceError` for the first violating signal."""
        bad = ~((values >= self._lo) & (values <= self._hi))
        i = int(np.argmax(bad))
        name = self.names[i]
        value = float(values[i])
        bounds = self.bounds.get(name, (-UNBOUNDED, UNBOUNDED) if math.isfinite(value) else None)
        raise DivergenceError(t, name, value, bounds)
