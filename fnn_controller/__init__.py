"""Flight controller of the paper (Fig. 2): PD position controller in parallel
with a type-1 TSK fuzzy neural network trained online by SMC or LM laws
(section 4), and a geometric SE(3) velocity controller (section 3.2).

Every law is written once with CasADi (one source of truth for the
co-simulation, C code generation and linearization):

* :func:`position_controller_function` -- outer loop, 3 axes, with learning;
* :func:`velocity_controller_function` -- inner loop and rotor inversion;
* :func:`parametric_step_function` -- both in one function, per step, the
  parameters an input: the one function the co-simulation, the controller
  FMUs and the analyses evaluate (:func:`bound_step_function`: with fixed gains);
* :class:`QuadrotorController` -- the object holding the learned state,
  evaluated through ``casadi.Function.buffer()`` (a few microseconds a step).

The laws take a :class:`Variant`; a variant's name is resolved once, by
:func:`variant`, where it enters.

Values the paper leaves open are documented in ``docs/controller.md``.
"""
from importlib import import_module

# name -> the module that defines it: imported when the name is first asked for
# (PEP 562), so that what needs no law (a variant's metadata, the parameter
# dataclasses) is read without building or importing what the laws need.
_WHERE = {
    **dict.fromkeys(("FastFunction", "QuadrotorController"), "fast"),
    **dict.fromkeys(("FnnInit", "fnn_output", "firing_strength", "membership", "normalized_firing_strength"), "fnn"),
    **dict.fromkeys(("GeometricParams", "VehicleParams", "initial_velocity_state", "velocity_controller",
                     "velocity_controller_function"), "geometric"),
    **dict.fromkeys(("LearningBounds", "learning_step", "lm_f_rate", "smc_f_rate"), "learning"),
    **dict.fromkeys(("bound_step_function", "parametric_step_function"), "parametric"),
    **dict.fromkeys(("FNN_STATE_SIZE", "initial_fnn_state", "pd_law", "position_controller",
                     "position_controller_function"), "position"),
    "PositionParams": "position_parameters",
    **dict.fromkeys(("STATE_SIZE", "initial_state", "state_size"), "step"),
    **dict.fromkeys(("DEFAULT_VARIANT", "Variant", "register_variant", "variant", "variant_names", "variants"),
                    "variants"),
}


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value  # found once
        return value
    try:  # a submodule, e.g. fnn_controller.step
        return import_module(f".{name}", __name__)
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


__all__ = [
    "STATE_SIZE", "FastFunction", "QuadrotorController", "parametric_step_function", "bound_step_function",
    "initial_state", "state_size", "DEFAULT_VARIANT", "Variant", "register_variant", "variant", "variant_names",
    "variants",
    "FnnInit", "fnn_output", "firing_strength", "membership", "normalized_firing_strength",
    "GeometricParams", "VehicleParams", "initial_velocity_state", "velocity_controller",
    "velocity_controller_function",
    "LearningBounds", "learning_step", "lm_f_rate", "smc_f_rate",
    "FNN_STATE_SIZE", "PositionParams", "initial_fnn_state", "pd_law",
    "position_controller", "position_controller_function",
]
