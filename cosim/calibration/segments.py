"""Multiple shooting: the log's rows cut into segments, each simulated from its own start.

A segment covers rows ``first .. last - 1`` (its residuals) and is simulated
one step further, to row ``last``, where the next segment starts: the state
it reaches there is what continuity compares with the next segment's start
(for states the log lacks, :mod:`cosim.calibration.solve`). Each segment
starts from the logged state (``initial_states = "recorded"``) or from an
estimated one. A short segment keeps an open-loop-unstable plant, driven by
recorded inputs, near the log: its error grows only over the segment.

The held-out part (the last ``holdout`` seconds) is one more segment, not
fitted: it is predicted with the estimates (the report's prediction).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ScenarioError

__all__ = ["Segment", "split"]


@dataclass(frozen=True)
class Segment:
    """Rows ``first`` (its start) to ``last`` (exclusive: the next segment's
    start, simulated to for continuity; ``last == rows`` for the log's end)."""

    index: int
    first: int
    last: int

    @property
    def rows(self) -> range:
        return range(self.first, self.last)


def split(times: np.ndarray, length: float | None, holdout: float | None) -> tuple[list[Segment], Segment | None]:
    """The fitted segments and the held-out one (``None`` if none).

    ``length``: seconds a segment (default: the whole fitted part);
    ``holdout``: seconds at the end not fitted (default: the last segment
    when there are at least three, else none; 0: none)."""
    n = times.size
    t0, t_end = float(times[0]), float(times[-1])
    span = t_end - t0
    if length is not None and length <= 0:
        raise ScenarioError(f"--segment {length!r}: must be positive")
    if length is not None and length > span + 1e-9:
        length = None
    starts = [0]
    if length is not None:
        k = 1
        while True:
            i = int(np.searchsorted(times, t0 + k * length - 1e-9))
            if i >= n - 1:
                break
            if i > starts[-1]:
                starts.append(i)
            k += 1
    if holdout is None:
        held = len(starts) >= 3
        cut = starts[-1] if held else n
    elif holdout == 0:
        cut = n
    else:
        cut = int(np.searchsorted(times, t_end - holdout - 1e-9))
        if cut <= 1:
            raise ScenarioError(f"holdout {holdout:g} s: leaves nothing to fit in a log of {span:g} s")
    fitted = [s for s in starts if s < cut - 1] or [0]
    segments = [Segment(i, a, b) for i, (a, b) in enumerate(zip(fitted, fitted[1:] + [cut]))]
    if segments[-1].last < cut:
        segments[-1] = Segment(segments[-1].index, segments[-1].first, cut)
    held_out = Segment(len(segments), cut, n) if cut < n - 1 else None
    return segments, held_out
