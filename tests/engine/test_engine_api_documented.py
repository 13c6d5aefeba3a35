"""The engine's entry points (listed in ``cosim``'s docstring) document
every argument they take: a name in the signature and not in the docstring
(or, for a class, in the class's docstring) fails here."""
from __future__ import annotations

import importlib
import inspect
import re

import pytest

import cosim

ENTRY_POINTS = re.findall(r":(?:func|class|meth):`(cosim\.[\w.]+)`", cosim.__doc__)


def _resolve(dotted: str):
    parts = dotted.split(".")
    for i in range(len(parts), 1, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for name in parts[i:]:
            obj = getattr(obj, name)
        return obj
    raise LookupError(dotted)


def undocumented(obj) -> list[str]:
    """The arguments of ``obj`` (a function, or a class: its ``__init__``)
    that its docstring does not name."""
    function, doc = obj, inspect.getdoc(obj) or ""
    if inspect.isclass(obj):
        function = obj.__init__
        doc += "\n" + (inspect.getdoc(function) if function.__doc__ else "")
    names = [n for n in inspect.signature(function).parameters if n not in ("self", "cls")]
    return [n for n in names if not re.search(rf"\b{re.escape(n)}\b", doc)]


def test_the_entry_points_are_listed():
    assert {"cosim.loop.Master", "cosim.loop.Master.run", "cosim.scenario.load_scenario"} <= set(ENTRY_POINTS)


@pytest.mark.parametrize("dotted", ENTRY_POINTS)
def test_every_argument_of_an_entry_point_is_documented(dotted):
    assert undocumented(_resolve(dotted)) == []


def test_an_undocumented_argument_is_found():
    def run(duration, seed=0, csv_path=None):
        """Run for ``duration`` s from ``seed``."""

    assert undocumented(run) == ["csv_path"]
