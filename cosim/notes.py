"""Notes: what the engine decided on the user's behalf, at info level.

A default the user did not give (an SSP archive's communication step), an
element passed over (an SSP annotation this reader does not know, a
connector with nothing beyond it), a unit taken as another (a rate without
its radian) is said once, at info level, to the logger of the module that
decided it (``cosim.ssp.archive``, ``cosim.loop.connection``): an application that
configures logging sees it there. The command line shows the notes on
stderr as ``note: ...`` lines once the run's inputs are taken
(:func:`show_on_stderr`, :func:`release`; ``--quiet`` hides them): a
refused input stays one line, its error's. ``logging`` is imported only when a note is made, so a run with
nothing to note loads none (tests/paper/test_run_startup.py).
"""
from __future__ import annotations

__all__ = ["note", "show_on_stderr", "release", "FMU_LOGGER", "stderr_handler"]

# The engine logs to "cosim" and its submodules; the FMUs' own log goes to "cosim.fmu.<instance>"
# (cosim.fmi.log), which a note's handler leaves out.
FMU_LOGGER = "cosim.fmu"

_ON_STDERR = False
_HANDLER = None
_HELD: list[str] | None = None  # notes made before release(): shown only if the run starts


def show_on_stderr(on: bool = True, hold: bool = True) -> None:
    """Notes made from now on also go to stderr (the command line's
    choice); with ``hold``, kept until :func:`release`, so an input refused
    before the run stays one line on stderr, the error's."""
    global _ON_STDERR, _HELD
    _ON_STDERR = on
    _HELD = [] if on and hold else None


def release() -> None:
    """The notes held so far to stderr (the inputs were taken: the run
    starts), and the next ones as they come."""
    global _HELD
    held, _HELD = _HELD, None
    if held:
        import sys

        for line in held:
            print(line, file=sys.stderr)


def note(logger: str, message: str, *args) -> None:
    """``message % args`` at info level to the logger ``logger``."""
    import logging

    log = logging.getLogger(logger)
    if _HELD is not None:
        _HELD.append("note: " + message % args)
    elif _ON_STDERR:
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

    handler = stderr_handler()
    handler.setFormatter(logging.Formatter("note: %(message)s"))
    handler.addFilter(lambda record: _ON_STDERR and not record.name.startswith(FMU_LOGGER))  # the latest choice
    logging.getLogger("cosim").addHandler(handler)
    _HANDLER = handler



_STDERR_CLASS = None


def stderr_handler():
    """A logging handler writing to the ``sys.stderr`` of the moment (a test
    or an application may replace it after the handler is made); its class
    is made on first use, so a run with nothing to log imports no
    ``logging``. The notes and the FMUs' log (:mod:`cosim.fmi.log`) use it."""
    global _STDERR_CLASS
    if _STDERR_CLASS is None:
        import logging

        class StderrHandler(logging.StreamHandler):
            @property
            def stream(self):
                import sys

                return sys.stderr

            @stream.setter
            def stream(self, value):  # StreamHandler.__init__ sets it; the property always answers sys.stderr
                pass

        _STDERR_CLASS = StderrHandler
    return _STDERR_CLASS()
