"""The co-simulation loop: connections between ports checked once
(:mod:`.connection`), the plan of a run (:mod:`.plan`: blocks, ordering,
transfers), the master stepping it (:class:`Master`), in Python or in the
compiled loop (:mod:`.kernel`, ``kernel.c``), the recorder writing rows as
they come (:mod:`.recorder`), the divergence guard (:mod:`.guard`) and the
online metrics summed as the run goes (:mod:`.online`).

Owns one run of given parts. May import the foundation modules and
:mod:`cosim.fmi`; it reads no scenario file and knows no study.
"""
from ..surface import lazy_surface

_SURFACE = {
    "Master": "master",
    "RunResult": "master",
    "Connection": "connection",
    "parse_connections": "connection",
    "Plan": "plan",
    "make_plan": "plan",
    "Recorder": "recorder",
    "read_results": "recorder",
    "Guard": "guard",
}
__all__ = list(_SURFACE)
__getattr__, __dir__ = lazy_surface(__name__, _SURFACE)
