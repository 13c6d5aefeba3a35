"""The controller of Fig. 2 cut at the velocity command v* (eq. 26): the
outer loop and the inner loop as two functions, and two FMUs.

Why cut there: in the paper's laboratory the position controller with its
learning FNN runs on a ground computer, and the AR.Drone 2.0 closes its own
velocity and attitude loops on board; the velocity command travels over
Wi-Fi. A link's delay, loss or noise then belongs between the two loops,
where one FMU holding both (:mod:`fnn_controller.controller_fmu`) cannot place it.

* ``outer`` (ground): eqs. 12, 19, 24-26 and the learning laws of the
  variant; ``(p_ref[3], p_ref_dot[3], x[6], state[n], p[m], p_ref_ddot[3])
  -> (y[12], state_next, check)``, ``x`` the measured position and velocity
  (x y z u v w), ``y = (v_ref, tau_c, tau_n, a_ref)`` laid out as
  :data:`OUTER_OUTPUTS` (``a_ref``: the acceleration feed-forward option's
  output, 0 unless ``accel_feedforward`` > 0);
* ``inner`` (on board): eqs. 13-18 and the rotor inversion;
  ``(v_ref[3], x[9], psi_ref, state[10], p[k], a_ref[3]) -> (y[8],
  state_next, check)``, ``x`` the vehicle's u v w phi theta psi p q r,
  ``y = (Omega, wrench)`` laid out as :data:`INNER_OUTPUTS`.

Both are the functions the whole step is composed of
(:func:`~fnn_controller.parametric.outer_step_function`,
:func:`~fnn_controller.parametric.inner_step_function`, the parameters an
input): connected directly, outer then inner, they give the whole
controller's outputs exactly (tested). This module makes them FMU models.
"""
from __future__ import annotations

from functools import lru_cache

from fmu_models.lazy_casadi import ca

from fmu_models.export.model import FmuModel
from fmu_models.export.variables import discrete, input_
from fmu_models.models.quadrotor import QUADROTOR, STATE_NAMES

from .fmu_names import INNER_IDENTIFIER, outer_identifier
from .step import OUTPUTS, state_ports
from .controller_fmu import ACCELERATION_INPUTS, PARAMETERS, PSI_REF, REFERENCE_INPUTS, STATE, step_model
from .geometric import VEL_STATE_SIZE, GeometricParams, initial_velocity_state
from .parametric import (inner_parameter_table, inner_step_function, outer_initial_function,
                         outer_parameter_table, outer_step_function, geometric_structure)
from .position import fnn_state_size
from .position_parameters import PositionParams
from .variants import variant as lookup

__all__ = ["A_REF_PORTS", "OUTER_OUTPUTS", "INNER_OUTPUTS", "OUTER_MEASURED", "INNER_MEASURED", "outer_model",
           "inner_model", "outer_identifier", "INNER_IDENTIFIER"]

OUTER_MEASURED = STATE_NAMES[0:6]   # x y z u v w: the motion-capture feed
INNER_MEASURED = STATE_NAMES[3:12]  # u v w phi theta psi p q r: the vehicle's own estimate
A_REF_PORTS = tuple((f"a_ref_{a}", "m/s2", f"acceleration fed forward to the velocity loop along {a}: "
                     "accel_feedforward d2p*/dt2 (0 with the option off)") for a in "xyz")
OUTER_OUTPUTS = tuple(o for o in OUTPUTS if o[0].startswith(("v_ref_", "tau_c_", "tau_n_"))) + A_REF_PORTS
INNER_OUTPUTS = tuple(o for o in OUTPUTS if o not in OUTER_OUTPUTS)
_AXES = "xyz"


def _plant_inputs(names) -> tuple:
    return tuple(input_(v.name, v.unit, f"measured plant state: {v.description}")
                 for v in (QUADROTOR.variable(n) for n in names))


@lru_cache(maxsize=None)
def outer_model(variant: str, position: PositionParams = PositionParams()) -> FmuModel:
    """The outer loop of ``variant`` as an FMU model (ground station):
    inputs the reference (and its acceleration, start 0) and the measured
    x y z u v w, outputs v*, tau_c, tau_n, a_ref; parameters its table and
    ``seed`` (f_ij(0)); locals the learned state of each axis."""
    inputs = (*(input_(n, u, t) for n, u, t in REFERENCE_INPUTS), *_plant_inputs(OUTER_MEASURED),
              *(input_(n, u, t) for n, u, t in ACCELERATION_INPUTS))
    arguments = (tuple(f"{a}_ref" for a in _AXES), tuple(f"v{a}_ref" for a in _AXES), OUTER_MEASURED, STATE,
                 PARAMETERS, tuple(n for n, _, _ in ACCELERATION_INPUTS))
    v = lookup(variant)
    states = tuple(discrete(n, u, t) for n, u, t in state_ports(v)[:fnn_state_size(v)])
    return step_model(
        outer_identifier(variant),
        f"{v.label} position controller of the LM-FNN paper (eqs. 12, 19, 24-26 and its learning laws), the "
        f"outer loop alone: v* to an on-board velocity controller; sampled at dt, z down",
        inputs, arguments, outer_step_function(variant), OUTER_OUTPUTS, outer_parameter_table(variant, position),
        states, outer_initial_function(variant), n_random=3 * v.n_random)


@lru_cache(maxsize=None)
def inner_model(geometric: GeometricParams = GeometricParams()) -> FmuModel:
    """The inner loop as an FMU model (on board): inputs v*, the
    vehicle's u v w phi theta psi p q r and a_ref (start 0), outputs the
    rotor speeds and the wrench of eq. 18; parameters the geometric gains and
    the nominal vehicle, psi_ref (the commanded yaw psi*, held for the run); it
    draws nothing, so it has no seed."""
    v_ref = tuple(n for n, _, _ in OUTER_OUTPUTS[:3])
    inputs = (*(input_(n, u, t) for n, u, t in OUTER_OUTPUTS[:3]), *_plant_inputs(INNER_MEASURED),
              *(input_(n, u, t + "; start 0: none") for n, u, t in A_REF_PORTS), PSI_REF)
    arguments = (v_ref, INNER_MEASURED, ("psi_ref",), STATE, PARAMETERS, tuple(n for n, _, _ in A_REF_PORTS))
    states = tuple(discrete(n, u, t) for n, u, t in state_ports(lookup("pd"))[-VEL_STATE_SIZE:])  # any variant's
    return step_model(
        INNER_IDENTIFIER,
        "geometric SE(3) velocity controller of the LM-FNN paper (eqs. 13-18) with rotor-speed inversion, the "
        "inner loop alone (on board): tracks v*; sampled at dt, z axis down",
        inputs, arguments, inner_step_function(geometric_structure(geometric)),
        INNER_OUTPUTS, inner_parameter_table(geometric), states,
        lambda p, r: ca.DM(initial_velocity_state()))  # R*_prev = identity, not primed
