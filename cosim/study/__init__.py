"""Studies: many runs of one scenario (cases, random draws, grids), declared
in a TOML file (:mod:`.definition`: :func:`load_study`), flown on an
executor -- threads, processes or a Dask cluster -- by :mod:`.runner`,
written row by row and resumed (:func:`run_study`, :mod:`.run`), summarized
(:mod:`.summary`) and drawn (:mod:`.plots`).

May import the foundation modules, :mod:`cosim.fmi`, :mod:`cosim.loop` and
:mod:`cosim.scenario`.
"""
from ..surface import lazy_surface

_SURFACE = {
    "Study": "definition",
    "Run": "definition",
    "load_study": "definition",
    "parse_study": "definition",
    "run_study": "run",
    "StudyResult": "run",
    "read_runs": "run",
    "summarize": "summary",
    "plot_study": "plots",
}
__all__ = list(_SURFACE)
__getattr__, __dir__ = lazy_surface(__name__, _SURFACE)
