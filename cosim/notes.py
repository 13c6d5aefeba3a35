"""Notes: what the engine decided on the user's behalf, at info level.

A default the user did not give (an SSP archive's communication step), an
element passed over (an SSP annotation this reader does not know, a
connector with nothing beyond it), a unit taken as another (a rate without
its radian) is said once, at info level, to the logger of the module that
decided it (``cosim.ssp``, ``cosim.connection``): an application that
configures logging sees it there. The command line shows the notes on
stderr as ``note: ...`` lines (:func:`show_on_stderr`; ``--quiet`` hides
them). ``logging`` is imported only when a note is made, so a run with
nothing to note loads none (tests/paper/test_run_startup.py).
"""
from __future__ import annotations

__all__ = ["note", "show_on_stderr"]

_ON_STDERR = False
_HANDLER = None


def show_on_stderr(on: bool = True) -> None:
    """Notes made from now on also go to stderr (the command line's choice)."""
    global _ON_STDERR
    _ON_STDERR = on


def note(logger: str, message: str, *args) -> None:
    """``message % args`` at info level to the logger ``logger``."""
    import logging

    log = logging.getLogger(logger)
    if _ON_STDERR:
        _stderr_handler()
        if log.level == logging.NOTSET:  # this logger's notes only: the FMUs' log keeps its own level
            log.setLevel(logging.INFO)
    log.info(message, *args)


def _stderr_handler() -> None:
    """One handler on the ``cosim`` logger that leaves out the FMUs' own
    log (``cosim.fmu``, which ``--fmu-log`` shows)."""
    global _HANDLER
    if _HANDLER is not None:
        return
    import logging

    from .fmu_log import FMU_LOGGER, _Stderr

    handler = _Stderr()
    handler.setFormatter(logging.Formatter("note: %(message)s"))
    handler.addFilter(lambda record: not record.name.startswith(FMU_LOGGER))
    logging.getLogger("cosim").addHandler(handler)
    _HANDLER = handler
