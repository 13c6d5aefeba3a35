"""``--fmu-log [INSTANCE=]LEVEL``: the option every ``fnn-cosim`` command
that runs FMUs takes (:mod:`quadrotor_paper.commands`), and its effect
(:func:`cosim.fmi.log.fmu_log`)."""
from __future__ import annotations

from typing import Sequence

__all__ = ["fmu_log_option", "apply_fmu_log"]


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
