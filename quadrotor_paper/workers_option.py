"""``--workers N``: the local worker processes of every ``fnn-cosim`` command
that flies many runs (:mod:`quadrotor_paper.commands`).

A local cluster gets from 1 to as many workers as the machine has cores
(``os.cpu_count()``; at least 2, the tables' default, which a one-core
machine still runs): the runs are CPU-bound, so a worker beyond the cores
adds a process (and its memory: about 100 MB each) and no speed, and 0 or
a negative count means nothing. Such a count is refused in one line, not
quietly changed; a bigger cluster is one given by ``--scheduler ADDRESS``.
"""
from __future__ import annotations

import argparse
import os

__all__ = ["worker_count", "default_workers", "TABLE_WORKERS"]

TABLE_WORKERS = 2  # the tables' and reproduce's default: their runs are short, two workers keep them busy


def _cores() -> int:
    return os.cpu_count() or 1


def _most() -> int:
    return max(TABLE_WORKERS, _cores())


def worker_count(text: str) -> int:
    """The ``type`` of ``--workers``: a whole number from 1 to the cores (at least 2)."""
    from cosim.errors import shown_text

    try:
        n = int(text)
    except ValueError:  # not a whole number, or beyond Python's digits
        n = 0
    if not 1 <= n <= _most():
        raise argparse.ArgumentTypeError(f"{shown_text(repr(text))}: expected a whole number from 1 to {_most()} "
                                         f"(the cores of this machine; a bigger cluster: --scheduler ADDRESS)")
    return n


def default_workers(wanted: int | None, default: int | None = None) -> int:
    """``wanted`` (checked by :func:`worker_count`), else ``default`` (at most
    the cores), else one per core."""
    if wanted is not None:
        return wanted
    return min(default, _cores()) if default is not None else _cores()
