"""A package's public names, each imported from its module on first use.

Every sub-package of the engine names its surface in its ``__init__`` as
``{name: module}`` and hands it to :func:`lazy_surface`: ``from
cosim.study import run_study`` works, and importing a package costs nothing
until a name is used (a run imports only the modules it needs,
tests/paper/test_run_startup.py).
"""
from __future__ import annotations

import importlib
from typing import Any, Callable, Mapping

__all__ = ["lazy_surface"]


def lazy_surface(package: str, surface: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package`` whose public ``surface``
    maps each name to the module (relative to the package) defining it
    (PEP 562)."""

    def __getattr__(name: str) -> Any:
        module = surface.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{module}"), name)

    def __dir__() -> list[str]:
        return sorted(surface)

    return __getattr__, __dir__
