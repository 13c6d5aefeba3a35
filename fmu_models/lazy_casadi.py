"""CasADi, loaded when first used (the standard library's ``LazyLoader``).

Every law is CasADi, but a run of already-built FMUs evaluates none of them:
it reads variable tables, port names and parameter tables that sit beside
the laws in the same modules. Those modules import ``ca`` from here, so
importing them costs nothing until an expression is built (0.05-0.1 s of
start-up, issue 26). The first attribute read (``ca.SX``) loads CasADi
itself; ``import casadi`` anywhere after that gets the same module.
"""
from __future__ import annotations

import importlib.util
import sys

__all__ = ["ca"]


def _lazy(name: str):
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    return module


ca = _lazy("casadi")
