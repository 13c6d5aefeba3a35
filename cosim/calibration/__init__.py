"""Calibration of an FMU from recorded data (docs/calibration.md).

The engine's one way to fit an FMU's parameters (and constant unknown
inputs, and initial states) to a log; it knows no model. Modules, one job
each:

* :mod:`~cosim.calibration.columns`: the column map and the settings (the files a user writes);
* :mod:`~cosim.calibration.log`: the log read and checked (CSV, Parquet, ULog);
* :mod:`~cosim.calibration.frames`: the log's frames, attitude and rotors as the FMU's; the map's mirrors checked;
* :mod:`~cosim.calibration.problem`: the FMU's variables bound to the log's columns;
* :mod:`~cosim.calibration.segments`: multiple shooting's segments and the held-out part;
* :mod:`~cosim.calibration.model`: the trajectories (Co-Simulation, or Model Exchange through the master's solver) and the right-hand side's Jacobians (Model Exchange);
* :mod:`~cosim.calibration.sensitivity`: the forward sensitivities along a segment;
* :mod:`~cosim.calibration.symbolic`: segments and exact sensitivities from the model's own CasADi definition (FMUs of ours);
* :mod:`~cosim.calibration.solve`: the weighted least-squares problem over the segments;
* :mod:`~cosim.calibration.marquardt`: its solver, Levenberg-Marquardt with the segments' states eliminated (Schur complement);
* :mod:`~cosim.calibration.statistics`: standard errors, intervals, correlation, identifiability, residuals;
* :mod:`~cosim.calibration.diagnostics`: the warnings (the model does not fit the log);
* :mod:`~cosim.calibration.outputs`: ``calibration.json``, ``parameters.ssv``, the TOML override, ``report.md``.

:func:`calibrate` (:mod:`~cosim.calibration.pipeline`) runs them in order and returns a :class:`Calibration`.

May import every other part of the engine (it is the top layer: it flies
FMUs, reads scenarios and summarizes like a study); nothing imports it.
"""
from ..surface import lazy_surface

_SURFACE = {
    "Calibration": "pipeline",
    "calibrate": "pipeline",
    "CalibrationSettings": "columns",
    "ColumnMap": "columns",
    "read_column_map": "columns",
    "read_settings": "columns",
    "read_log": "log",
    "Log": "log",
    "Diagnostic": "diagnostics",
}
__all__ = list(_SURFACE)
__getattr__, __dir__ = lazy_surface(__name__, _SURFACE)
