"""Linear stability analysis of the PD baseline with python-control, checked
against the nonlinear co-simulation (``docs/stability.md``).

Modules, one job each:

* :mod:`~cosim.stability.operating_points` -- trimmed steady flights
  (CasADi rootfinders on the plant and controller functions);
* :mod:`~cosim.stability.linearize` -- Jacobians of the plant (CasADi or the
  FMU's directional derivatives) and of the controller's CasADi functions;
* :mod:`~cosim.stability.loops` -- the loops as ``control.interconnect``
  systems, continuous or sampled (ZOH, optional delay), and broken loops;
* :mod:`~cosim.stability.analysis` -- poles, damping, margins, gain sweep,
  ramp and circle errors;
* :mod:`~cosim.stability.validation` -- the same steps in the co-simulation;
* :mod:`~cosim.stability.finite_time` -- the learning laws' bounds (eqs. 53,
  66, 70) on recorded runs;
* :mod:`~cosim.stability.study`, :mod:`~cosim.stability.report`,
  :mod:`~cosim.stability.cli` -- all of it, the report, the command.
"""
from .analysis import (GainSweep, LoopMargins, PoleReport, analyze, circle_error, closed_loop_poles,
                       critical_gain_factor, gain_sweep, loop_margins, ramp_error)
from .linearize import (linearize_controller, linearize_controller_step, linearize_plant, linearize_plant_fmu,
                        linearize_position_controller, linearize_velocity_controller)
from .loops import LoopModel
from .operating_points import (OperatingPoint, default_operating_points, forward_flight, hover, operating_point,
                               trim_closed_loop, trim_plant)
from .study import StabilityStudy, run_stability_analysis, stability_study

__all__ = [
    "GainSweep", "LoopMargins", "PoleReport", "analyze", "circle_error", "closed_loop_poles",
    "critical_gain_factor", "gain_sweep", "loop_margins", "ramp_error",
    "linearize_controller", "linearize_controller_step", "linearize_plant", "linearize_plant_fmu",
    "linearize_position_controller", "linearize_velocity_controller",
    "LoopModel",
    "OperatingPoint", "default_operating_points", "forward_flight", "hover", "operating_point",
    "trim_closed_loop", "trim_plant",
    "StabilityStudy", "run_stability_analysis", "stability_study",
]
