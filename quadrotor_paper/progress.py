"""Progress of long commands, drawn by tqdm on stderr.

:func:`progress_bar` gives a callable ``update(done, total)`` (the shape the
master and the study runner report progress in) and closes the bar at the
end of the ``with`` block. Off with ``enabled=False`` (``--quiet``).
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Iterator

__all__ = ["progress_bar"]


@contextmanager
def progress_bar(label: str, total: int | None = None, enabled: bool = True,
                 unit: str = "run") -> Iterator[Callable[[int, int], None]]:
    """A tqdm bar labelled ``label``; the callable sets its position to
    ``done`` of ``total`` (the total may come with the first call)."""
    if not enabled:
        yield lambda done, total: None
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=label, unit=unit, leave=True, dynamic_ncols=True)
    try:
        def update(done: int, total: int) -> None:
            if bar.total != total:
                bar.total = total
            bar.update(done - bar.n)
        yield update
    finally:
        bar.close()
