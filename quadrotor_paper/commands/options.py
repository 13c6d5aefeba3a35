"""The options the commands share (:mod:`quadrotor_paper.commands`), each
read and refused in one line the same way wherever it is taken:

* ``--set KEY=VALUE``: dotted scenario keys and their values
  (:func:`overrides`), and ``NAME=VALUE`` pairs of an FMU's variables
  (``linearize``'s ``--parameter``, ``calibrate``'s ``--fix``:
  :func:`named_values`);
* ``--workers N``: the local worker processes of every command that flies
  many runs (:func:`worker_count`, :func:`default_workers`). A local cluster
  gets from 1 to as many workers as the machine has cores
  (``os.cpu_count()``; at least 2, the tables' default, which a one-core
  machine still runs): the runs are CPU-bound, so a worker beyond the cores
  adds a process (and its memory: about 100 MB each) and no speed, and 0 or
  a negative count means nothing. Such a count is refused in one line, not
  quietly changed; a bigger cluster is one given by ``--scheduler ADDRESS``;
* ``--fmu-log [INSTANCE=]LEVEL``: every command that runs FMUs
  (:func:`fmu_log_option`), and its effect (:func:`apply_fmu_log`,
  :func:`cosim.fmi.log.fmu_log`).

Imported by the command line's start: it imports the standard library only
(what an option needs of the engine, when the option is read).
"""
from __future__ import annotations

import argparse
import math
import os
from typing import Any, Sequence

__all__ = ["overrides", "named_values", "worker_count", "default_workers", "TABLE_WORKERS", "fmu_log_option",
           "apply_fmu_log"]


# ---- --set and NAME=VALUE ----------------------------------------------------------------------

def overrides(pairs: Sequence[str]) -> dict[str, Any]:
    """``--set KEY=VALUE`` pairs as dotted keys and values, each checked as a
    document's key and value are (:func:`cosim.scenario.definition.dotted_key`,
    :func:`cosim.files.toml_value`): a bare word is text."""
    from cosim.errors import ScenarioError, shown_text
    from cosim.files import toml_value
    from cosim.scenario.definition import dotted_key

    from cosim.names import partition_top

    out = {}
    for pair in pairs:  # the first = outside a quoted FMI name ('a=b') ends the key
        key, eq, value = partition_top(pair, "=")
        if not eq or not key.strip():
            raise ScenarioError(f"--set {shown_text(pair)!r}: expected KEY=VALUE, e.g. --set wind.speed=5")
        key = key.strip()
        parts = dotted_key(key, f"--set {shown_text(key)!r}")
        out[key] = toml_value(value.strip(), f"--set {shown_text(key)}", len(parts))
    return out


def named_values(pairs: Sequence[str], option: str) -> dict[str, float]:
    """``NAME=VALUE`` pairs of ``option``, every value a finite number (one line otherwise)."""
    from cosim.errors import ScenarioError, shown_text
    from cosim.names import partition_top

    out = {}
    for pair in pairs:  # a variable name as FMI writes it: x[1], der(x), 'a=b' (cosim.names)
        name, eq, text = partition_top(pair, "=")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not eq or not name.strip() or not math.isfinite(value):
            raise ScenarioError(f"{option} {shown_text(pair)!r}: expected NAME=VALUE with a finite number, e.g. "
                                f"{option} m=1.2")
        out[name.strip()] = value
    return out


# ---- --workers ----------------------------------------------------------------------------------

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


# ---- --fmu-log ----------------------------------------------------------------------------------

def fmu_log_option(parser) -> None:
    """``--fmu-log [INSTANCE=]LEVEL`` (repeatable): show the FMUs' own log
    messages of LEVEL and worse on stderr, and ask the FMUs for the log
    categories of that level (:func:`cosim.fmi.log.fmu_log`)."""
    parser.add_argument("--fmu-log", action="append", default=[], metavar="[INSTANCE=]LEVEL",
                        help="show the FMUs' own log (error, warning, info, debug; default: none shown, errors "
                             "quote it), for every FMU or one instance (repeatable); with --workers > 1 it "
                             "applies to the FMUs run in this process")


def apply_fmu_log(values: Sequence[str]) -> None:
    """Each ``[INSTANCE=]LEVEL`` given: that level for that instance's FMU
    log (every instance without one); an unknown level is one line."""
    if not values:  # none asked for: the logging module stays unloaded (cosim.fmi.fmu)
        return
    from cosim.errors import ScenarioError
    from cosim.fmi.log import LOG_LEVELS, fmu_log

    for value in values:
        instance, _, level = value.rpartition("=")
        if level.strip() not in LOG_LEVELS:
            raise ScenarioError(f"--fmu-log {value}: expected [INSTANCE=]LEVEL, LEVEL one of {', '.join(LOG_LEVELS)}")
        fmu_log(level.strip(), instance.strip() or None)
