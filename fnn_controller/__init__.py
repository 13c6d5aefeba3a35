"""Flight controller of the paper (Fig. 2): PD position controller in parallel
with a type-1 TSK fuzzy neural network trained online by SMC or LM laws
(section 4), and a geometric SE(3) velocity controller (section 3.2).

Every law is written once with CasADi (one source of truth for the
co-simulation, C code generation and linearization):

* :func:`position_controller_function` -- outer loop, 3 axes, with learning;
* :func:`velocity_controller_function` -- inner loop and rotor inversion;
* :func:`controller_step_function` -- both in one function, per step;
* :class:`QuadrotorController` -- the object holding the learned state,
  evaluated through ``casadi.Function.buffer()`` (a few microseconds a step).

Values the paper leaves open are documented in ``docs/controller.md``.
"""
from .step import (STATE_SIZE, FastFunction, QuadrotorController, controller_step_function,
                         initial_state, state_size)
from .fnn import FnnInit, fnn_output, firing_strength, membership, normalized_firing_strength
from .geometric import (GeometricParams, VehicleParams, initial_velocity_state, velocity_controller,
                        velocity_controller_function)
from .learning import LearningBounds, learning_step, lm_f_rate, smc_f_rate
from .position import (FNN_STATE_SIZE, PositionParams, initial_fnn_state, pd_law, position_controller,
                       position_controller_function)
from .variants import Variant, register_variant, variant, variant_names, variants

__all__ = [
    "STATE_SIZE", "FastFunction", "QuadrotorController", "controller_step_function", "initial_state",
    "state_size", "Variant", "register_variant", "variant", "variant_names", "variants",
    "FnnInit", "fnn_output", "firing_strength", "membership", "normalized_firing_strength",
    "GeometricParams", "VehicleParams", "initial_velocity_state", "velocity_controller",
    "velocity_controller_function",
    "LearningBounds", "learning_step", "lm_f_rate", "smc_f_rate",
    "FNN_STATE_SIZE", "PositionParams", "initial_fnn_state", "pd_law",
    "position_controller", "position_controller_function",
]
