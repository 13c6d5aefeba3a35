"""SSP archives (System Structure and Parameterization, SSP 1.0/2.0): read
into a scenario, nested systems and Model Exchange components included
(:func:`load_ssp`, :mod:`.archive`), and a scenario written as an archive
other tools fly (:func:`export_ssp`, :mod:`.export`). The SSV parameter
sets both use are a scenario's (:mod:`cosim.scenario.parameter_set`).

May import the foundation modules, :mod:`cosim.fmi`, :mod:`cosim.loop` and
:mod:`cosim.scenario`.
"""
from ..surface import lazy_surface

_SURFACE = {
    "load_ssp": "archive",
    "export_ssp": "export",
    "ssd_schema_errors": "archive",
}
__all__ = list(_SURFACE)
__getattr__, __dir__ = lazy_surface(__name__, _SURFACE)
