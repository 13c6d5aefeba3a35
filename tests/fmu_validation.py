"""fmpy's ``validate_fmu``, run once per FMU content and fmpy version.

fmpy checks every variable name against the structured naming convention
with an Earley parser it builds on each call: 0.6 s of CPU for one of our
FMUs, and the suite validates the same bytes many times (each model's own
test, ``build-fmu``'s test, the FMUs inside every exported archive). The
verdict is a function of the file's bytes and of fmpy, so it is kept in the
FMU cache under their digest (``<cache>/fmpy-validation/``) and shared by the
test processes and runs; a new or changed FMU is validated by fmpy as
before. A folder (an extracted FMU) is always validated afresh. fmpy also
builds the same Earley parser on every call (a quarter of its time): here
it is built once and handed to fmpy, which parses the names with it as
before (the verdicts are the same). The names themselves repeat: a model's
FMI 2.0 and 3.0 FMUs, the plant's states in every controller, every FMU of
an exported archive (the stock FMU with other start values) carry the same
names, and the parse of a name depends on the name and the grammar alone.
So each distinct name is parsed once per process and fmpy is handed the
result (the same tree, or the same exception raised again): a fresh suite
validated about a hundred distinct FMUs, each parsing all its names.

Most names need no parser at all: fmpy keeps no tree, only whether the
parse raised, and a name of the grammar's plain form (identifiers with
array indices, joined by dots, or ``der(...)`` of one) is legal by reading
the grammar. Such a name is accepted by a regular expression of that form
(``_PLAIN``), in microseconds where Earley took milliseconds (the 7 FMUs
of a ``circles_estimated`` archive validated in one process: 0.1 s of CPU
against 4.0-4.4); any other name goes to the parser, so a problem is
still worded by fmpy. The shortcut holds only for the grammar it was read
from (its digest): an fmpy with another grammar parses every name again.
"""
from __future__ import annotations

import functools
import hashlib
import re
from pathlib import Path
from unittest import mock

import fmpy
import lark
from fmpy.validation import validate_fmu as _fmpy_validate_fmu

from cosim.cache import read, write
from fmu_models.cache import cache_root

__all__ = ["validate_fmu"]

_LARK = lark.Lark  # the class itself: fmpy's name for it is patched below


# fmpy 0.3's grammar of structured names (fmpy.validation._validate_variable_names), by its digest, and the
# plain names it derives: bname as nondigit (nondigit | digit)*, arrayindices as [n(,n)*], identifier as
# bname arrayindices? joined by "." (no quoted names), name as identifier or der(identifier(,n)?)
_GRAMMAR = "4a50025cb4d0af0f"
_IDENTIFIER = r"[A-Za-z_][A-Za-z0-9_]*(?:\[[0-9]+(?:,[0-9]+)*\])?(?:\.[A-Za-z_][A-Za-z0-9_]*(?:\[[0-9]+(?:,[0-9]+)*\])?)*"
_PLAIN = re.compile(rf"{_IDENTIFIER}|der\({_IDENTIFIER}(?:,[0-9]+)?\)", re.ASCII)


class _NameParser:
    """fmpy's parser of variable names with each name's outcome kept: the
    tree it returned, or the exception it raised (raised again, so fmpy
    words the problem as before); a plain name of fmpy's grammar accepted
    unparsed (module docstring)."""

    def __init__(self, *args, **kwargs):
        self._grammar = (args, kwargs)
        self._outcomes: dict[str, tuple[bool, object]] = {}
        grammar = args[0] if args and isinstance(args[0], str) else ""
        self.plain = hashlib.sha256(grammar.encode()).hexdigest()[:16] == _GRAMMAR and kwargs == {"start": "name"}

    @functools.cached_property
    def _lark(self):  # built when a name needs it (0.3 s of CPU): a plain name does not
        args, kwargs = self._grammar
        return _LARK(*args, **kwargs)

    def parse(self, text: str, *args, **kwargs):
        if args or kwargs:  # not how fmpy calls it: no memory
            return self._lark.parse(text, *args, **kwargs)
        if self.plain and _PLAIN.fullmatch(text):
            return None  # legal: fmpy only asks whether the parse raises
        outcome = self._outcomes.get(text)
        if outcome is None:
            try:
                outcome = (True, self._lark.parse(text))
            except Exception as exc:  # noqa: BLE001  (fmpy catches every exception and reports it)
                outcome = (False, exc)
            self._outcomes[text] = outcome
        parsed, value = outcome
        if not parsed:
            raise value
        return value


_PARSER = functools.lru_cache(maxsize=4)(_NameParser)  # fmpy's grammar, built once per process


def _validated(filename: str) -> list[str]:
    with mock.patch("lark.Lark", _PARSER):  # fmpy imports it inside the call
        return _fmpy_validate_fmu(filename)


def validate_fmu(filename: str) -> list[str]:
    """The problems fmpy's ``validate_fmu`` finds in ``filename``."""
    path = Path(filename)
    if not path.is_file():
        return _validated(filename)
    digest = hashlib.sha256(fmpy.__version__.encode() + b"\0" + path.read_bytes()).hexdigest()
    verdict = read("fmpy-validation", digest, cache_root())  # checked against its key (cosim.cache)
    if isinstance(verdict, list) and all(isinstance(problem, str) for problem in verdict):
        return verdict
    problems = _validated(filename)
    write("fmpy-validation", digest, problems, cache_root())
    return problems
