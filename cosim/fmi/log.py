"""The FMUs' own log on the Python side: every instance logs to the logger
``cosim.fmu.<instance>``, whose level chooses what is shown (:func:`fmu_log`)
and, at debug, asks the FMU for every category
(:class:`~cosim.fmi.fmu.FmuComponent` sends the messages here)."""
from __future__ import annotations

import logging

from ..errors import ScenarioError
from ..notes import FMU_LOGGER, stderr_handler

__all__ = ["FMU_LOGGER", "LOG_LEVELS", "STATUS_LABEL", "STATUS_LEVEL", "fmu_log"]

# Every instance logs to the logger "cosim.fmu.<instance>"; its effective level chooses what is kept and
# shown (FmuComponent._log) and, at debug, asks the FMU for every category (FmuComponent._apply_log_level).
# A library logs nowhere by itself: the NullHandler keeps Python's last-resort handler from printing FMU
# warnings a run did not ask to see (fmu_log does).
logging.getLogger(FMU_LOGGER).addHandler(logging.NullHandler())
LOG_LEVELS = {"error": logging.ERROR, "warning": logging.WARNING, "info": logging.INFO, "debug": logging.DEBUG}
# FMI status (fmi2Status, fmi3Status: OK, Warning, Discard, Error, Fatal, and FMI 2.0's Pending) -> label, level
STATUS_LABEL = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")
STATUS_LEVEL = (logging.INFO, logging.WARNING, logging.WARNING, logging.ERROR, logging.CRITICAL, logging.INFO)


class _InstanceFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        instance = record.name.removeprefix(FMU_LOGGER + ".")
        return f"fnn-cosim: fmu {instance}: {record.levelname.lower()}: {record.getMessage()}"


def fmu_log(level: str, instance: str | None = None, stream=None) -> None:
    """Show the FMUs' own log messages of ``level`` (``error``,
    ``warning``, ``info``, ``debug``) and worse on ``stream`` (stderr), for
    every FMU instance or only ``instance``; at ``debug``, instances made
    afterwards ask their FMU for every log category.

    The level is the Python logger's (``cosim.fmu`` or
    ``cosim.fmu.<instance>``): an application that configures logging
    itself sets the same level on the same logger.
    """
    if level not in LOG_LEVELS:
        raise ScenarioError(f"FMU log level {level!r}: expected one of {', '.join(LOG_LEVELS)}")
    logging.getLogger(FMU_LOGGER if instance is None else f"{FMU_LOGGER}.{instance}").setLevel(LOG_LEVELS[level])
    root = logging.getLogger(FMU_LOGGER)
    shown = [h for h in root.handlers if isinstance(h.formatter, _InstanceFormatter)]
    if stream is not None or not shown:
        handler = logging.StreamHandler(stream) if stream is not None else stderr_handler()
        handler.setFormatter(_InstanceFormatter())
        for old in shown:  # one place the messages are shown
            root.removeHandler(old)
        root.addHandler(handler)
