"""Linear stability analysis of the PD baseline with python-control, checked
against the nonlinear co-simulation (``docs/stability.md``).

Modules, one job each:

* :mod:`~quadrotor_paper.stability.operating_points` -- trimmed steady flights
  (CasADi rootfinders on the plant and controller functions);
* :mod:`~quadrotor_paper.stability.linearize` -- Jacobians of the plant (CasADi or the
  FMU's directional derivatives) and of the controller's CasADi functions;
* :mod:`~quadrotor_paper.stability.loops` -- the loops as ``control.interconnect``
  systems, continuous or sampled (ZOH, optional delay), and broken loops;
* :mod:`~quadrotor_paper.stability.analysis` -- poles, damping, margins, gain sweep,
  ramp and circle errors;
* :mod:`~quadrotor_paper.stability.validation` -- the same steps in the co-simulation;
* :mod:`~quadrotor_paper.stability.fmu_loop` -- the sampled loop from the FMUs, at a trimmed
  point or at a run's snapshot; :mod:`~quadrotor_paper.stability.along_flight` -- the
  learning loop of every variant along the missions, checked by perturbations;
* :mod:`~quadrotor_paper.stability.study`, :mod:`~quadrotor_paper.stability.report`
  -- all of it (with the learning laws' bounds, eqs. 53, 66, 70, on recorded
  runs: :mod:`quadrotor_paper.learning_claims`), the report; the command is
  :mod:`quadrotor_paper.commands.stability`.

The names below load their module on first use, so that ``fnn-cosim`` can
add the ``stability`` subcommand without paying for them in every other
command. python-control (with the scipy.signal and matplotlib.pyplot it
imports, 2-3 s of CPU) is imported by the functions that make a linear
system, not with the modules (as ``cosim.linearize.linearization``): importing them, e.g.
a test worker collecting the suite, does not load it (tests/test_imports.py).
"""
from importlib import import_module

_EXPORTS = {
    "analysis": ("GainSweep", "LoopMargins", "PoleReport", "analyze", "circle_error", "closed_loop_poles",
                 "critical_gain_factor", "gain_sweep", "loop_margins", "ramp_error", "feedforward_comparison"),
    "linearize": ("linearize_controller", "linearize_controller_step", "linearize_plant", "linearize_plant_fmu",
                  "linearize_position_controller", "linearize_velocity_controller", "linearize_feedforward"),
    "fmu_loop": ("FmuLoop", "fmu_closed_loop", "snapshot_loop", "join_loop", "inert_states"),
    "along_flight": ("AlongFlight", "AlongFlightRun", "along_flight", "along_flight_study"),
    "loops": ("LoopModel",),
    "operating_points": ("OperatingPoint", "default_operating_points", "forward_flight", "hover", "operating_point",
                         "trim_closed_loop", "trim_plant"),
    "study": ("StabilityStudy", "StabilitySettings", "run_stability_analysis", "stability_study"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = list(_MODULE_OF)


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
