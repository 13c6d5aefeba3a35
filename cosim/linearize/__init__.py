"""Linearization of any FMU at an operating point: the A, B, C, D of a
Model Exchange FMU from its directional derivatives or central differences,
or of a sampled (Co-Simulation) FMU, as a python-control state space
(:func:`linearize_fmu`), and the operating point of a run
(:func:`operating_point_of_run`).

May import the foundation modules, :mod:`cosim.fmi`, :mod:`cosim.loop` and
:mod:`cosim.scenario`.
"""
from ..surface import lazy_surface

_SURFACE = {
    "Linearization": "linearization",
    "LinearizationError": "linearization",
    "linearize_fmu": "linearization",
    "save_linearization": "linearization",
    "operating_point_of_run": "linearization",
    "METHODS": "linearization",
}
__all__ = list(_SURFACE)
__getattr__, __dir__ = lazy_surface(__name__, _SURFACE)
