"""CasADi, loaded when first used.

Every law is CasADi, but a run of already-built FMUs evaluates none of them:
it reads variable tables, port names and parameter tables that sit beside
the laws in the same modules. Those modules import ``ca`` from here, so
importing them costs nothing until an expression is built (0.05-0.1 s of
start-up, issue 26). The first attribute read (``ca.SX``) imports CasADi;
``import casadi`` anywhere gets the same module.

``ca`` is a stand-in that imports CasADi by the ordinary import (safe from
any thread) rather than the standard library's ``LazyLoader``: models are
built side by side in threads (:func:`cosim.scenario.registry.build_fmu_models`), and
under Python 3.11 a second thread reading a ``LazyLoader`` module while the
first loads it finds it half made (``module 'casadi' has no attribute 'SX'``).
"""
from __future__ import annotations

import importlib

__all__ = ["ca"]


class _Casadi:
    """The ``casadi`` module, imported at the first attribute read."""

    __slots__ = ()

    def __getattr__(self, name: str):
        return getattr(_casadi(), name)

    def __repr__(self) -> str:
        return "<casadi, imported when first used>"


_MODULE = None


def _casadi():
    global _MODULE
    if _MODULE is None:
        _MODULE = importlib.import_module("casadi")  # the import system's per-module lock: one thread loads it
    return _MODULE


ca = _Casadi()
