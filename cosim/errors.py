"""The exceptions of the co-simulation master, each naming what went wrong.

All derive from :class:`CosimError`, so a caller (the CLI) can catch one type
and print the message; the messages name the connection, key, signal or FMI
call concerned, never just a status code, and fit on one line.
"""
from __future__ import annotations

import math
from pathlib import Path

__all__ = ["CosimError", "ConnectionCheckError", "ScenarioError", "DivergenceError", "FmuError", "FmuLoadError",
           "FmuCallError", "SimulationTerminated", "one_line", "shown_text", "show_folder_as"]

# A temporary folder the tool extracted an archive to -> what a message shows
# instead (the archive): a message never shows a temporary folder
# (docs/security.md). Entries leave with their folder (show_folder_as's undo).
_SHOWN: dict[str, str] = {}


def show_folder_as(folder, label: str):
    """Messages show ``label`` where they would show ``folder`` (a temporary
    extraction folder); returns the function that forgets it again."""
    key = str(folder).rstrip("/")
    _SHOWN[key] = label

    def forget() -> None:
        _SHOWN.pop(key, None)
    return forget


def _shown(text: str) -> str:
    for folder, label in _SHOWN.items():
        if folder in text:
            text = text.replace(folder, label)
    return text


def one_line(text: str) -> str:
    """``text`` with its line breaks and runs of blanks folded into single spaces."""
    return " ".join(str(text).split())


def shown_text(text: str, limit: int = 80) -> str:
    """``text`` on one line, cut to about ``limit`` characters (a key or value a message quotes, however long)."""
    text = one_line(text)
    return text if len(text) <= limit else f"{text[:limit - 3]}... ({len(text)} characters)"


class CosimError(Exception):
    """Base class of every error the master raises on purpose; its message
    shows no temporary folder (:func:`show_folder_as`, applied when it is made)."""

    def __init__(self, *args):
        super().__init__(*(_shown(a) if isinstance(a, str) else a for a in args))

    def __reduce__(self):
        # pickled whole (from a worker process, cosim.executor): its message and attributes as they are, not
        # its __init__ called again with the message alone (FmuError's takes three arguments)
        return _rebuilt, (type(self), self.args, self.__dict__)


def _rebuilt(cls: type, args: tuple, state: dict) -> CosimError:
    error = Exception.__new__(cls, *args)
    error.__dict__.update(state)
    return error


class ConnectionCheckError(CosimError):
    """A declared connection is wrong (unknown variable, causality, type, unit)."""


class ScenarioError(CosimError):
    """A scenario file is invalid: names the key, the value and what was expected."""


class DivergenceError(CosimError):
    """The run left its declared envelope or produced a non-finite value.

    Attributes ``time`` (s), ``signal`` and ``value`` name the first violation.
    """

    def __init__(self, time: float, signal: str, value: float, bounds: tuple[float, float] | None):
        self.time, self.signal, self.value, self.bounds = time, signal, value, bounds
        if bounds is None or not math.isfinite(value):
            what = "is not a finite number"
        else:
            what = f"is outside its envelope [{bounds[0]:g}, {bounds[1]:g}]"
        super().__init__(f"diverged at t = {time:.4f} s: {signal} = {value!r} {what}")


class FmuError(CosimError):
    """Something went wrong with one FMU instance.

    Attributes: ``instance`` (its name in the co-simulation), ``path`` (the
    FMU file), ``reason`` (what went wrong, one line, quoting the FMU's own
    log where it said why).
    """

    def __init__(self, instance: str, path: str | Path | None, reason: str):
        self.instance, self.path, self.reason = instance, path, one_line(reason)
        where = f"{instance} ({path})" if path is not None else instance
        super().__init__(f"{where}: {self.reason}")


class FmuLoadError(FmuError):
    """The FMU file cannot be used: not a zip archive, a broken
    modelDescription.xml, no binary for this platform, refused instantiation;
    or a setting of the instance does not fit the file (``setting``: its key
    and value, e.g. ``("seed_parameter", "u")``; ``cause``: why, without them)."""

    def __init__(self, instance: str, path: str | Path | None, reason: str,
                 setting: tuple[str, object] | None = None):
        self.setting, self.cause = setting, one_line(reason)
        super().__init__(instance, path, reason if setting is None else f"{setting[0]} = {setting[1]!r}: {reason}")


class FmuCallError(FmuError):
    """An FMI call returned an error status; carries the FMU's own log messages.

    ``variable`` and ``value`` name the parameter the FMU refused when the
    failing call set one (at start-up), else ``None``; ``log`` is what the
    FMU itself logged about it (one line, empty if it logged nothing).
    """

    def __init__(self, instance: str, path: str | Path | None, reason: str, variable: str | None = None,
                 value: float | None = None, log: str = ""):
        super().__init__(instance, path, reason)
        self.variable, self.value, self.log = variable, value, one_line(log)


class SimulationTerminated(FmuError):
    """An FMU asked to end the simulation: FMI 2.0 ``fmi2Terminated`` after a
    ``doStep`` it discarded, FMI 3.0 ``terminateSimulation``, or a Model
    Exchange FMU's event iteration or ``completedIntegratorStep``. Not a
    failure: the run ends at ``time``, the last communication point every
    FMU completed (its rows kept, status ok, the message in
    ``RunResult.terminated``)."""

    def __init__(self, instance: str, path: str | Path | None, time: float, reason: str):
        self.time = time
        super().__init__(instance, path, reason)
