"""The controller as an FMU model: the parametric step of
:mod:`fnn_controller.parametric`, the very function the co-simulation's fast
path evaluates, as a sampled-data :class:`~fmu_models.export.model.FmuModel`
that the project's exporter turns into FMI 2.0 and FMI 3.0 Co-Simulation FMUs.

One FMU per registered variant (``ControllerPD``, ``ControllerPDSMC``,
``ControllerPDLM``, ``ControllerPDIT2SMC``, ``ControllerPDIT2LM``: the
variant's name as a C identifier, :func:`fnn_controller.fmu_names.fmu_identifier`):
a variant fixes the laws and the size of the learned
state, which FMI cannot change after instantiation, so it is the FMU's
identity rather than a parameter.

=========== ================================================================
inputs      x_ref y_ref z_ref (m), vx_ref vy_ref vz_ref (m/s),
            the 12 plant states x y z u v w phi theta psi p q r (SI), and
            ax_ref ay_ref az_ref (m/s², start 0: read only with the
            parameter ``accel_feedforward`` > 0)
outputs     Omega_1..4, v_ref_x..z, tau_c_x..z, tau_n_x..z, T, tau_phi,
            tau_theta, tau_psi (:data:`fnn_controller.step.OUTPUTS`)
parameters  every entry of :func:`~fnn_controller.parametric.parameter_table`
            (gains, learning rates, bounds, initial values, nominal vehicle)
            with unit, description and range; ``psi_ref`` (rad, the commanded
            yaw psi*, held for the run); ``seed`` (f_ij(0), the draws of
            numpy's ``default_rng(seed)``)
locals      the learned state of each axis (``f_12_x``, ``sigma1_2_z``,
            ``alpha_y``, ...) and the velocity controller's previous R*
=========== ================================================================

Step semantics (``docs/controller-fmu.md``): the outputs have direct
feedthrough and are sample-and-hold. After the inputs of ``t_n`` are set,
a get returns the control at ``t_n`` computed from them; ``doStep(t_n, dt)``
then advances the learned state and holds that control over the step. The
communication step must be ``dt``.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any, Callable, Sequence

from fmu_models.lazy_casadi import ca

from fmu_models.export.model import FmuModel, Sampled
from fmu_models.export.variables import discrete, input_, output, parameter
from fmu_models.models.quadrotor import QUADROTOR, STATE_NAMES

from .fmu_names import FNN_SEED, fmu_identifier  # re-exported: where the controller FMU's users found them
from .step import OUTPUTS, state_ports
from .geometric import GeometricParams
from .parametric import initial_state_function, parameter_table, parametric_step_function, geometric_structure
from .position_parameters import PositionParams

_POSITION, _GEOMETRIC = PositionParams(), GeometricParams()  # the defaults: one (frozen) instance for every signature
from .variants import Variant, variant as lookup

__all__ = ["controller_model", "step_model", "STATE", "PARAMETERS", "fmu_identifier", "REFERENCE_INPUTS", "PSI_REF",
           "ACCELERATION_INPUTS", "FNN_SEED"]

_AXES = "xyz"
REFERENCE_INPUTS = (
    *((f"{a}_ref", "m", f"reference position {a} (world, z down)") for a in _AXES),
    *((f"v{a}_ref", "m/s", f"reference velocity d{a}*/dt") for a in _AXES),
)
# The commanded yaw is held for a run (the paper's missions fly at psi* = 0): a
# parameter, so that no input of the FMU is left for an importer to find unconnected.
PSI_REF = parameter("psi_ref", "rad", "commanded yaw psi*, held for the run", 0.0)
# After the plant states, start 0: unconnected they leave the paper's law as it is.
ACCELERATION_INPUTS = tuple((f"a{a}_ref", "m/s2", f"reference acceleration d2{a}*/dt2 "
                             "(fed forward with accel_feedforward)") for a in _AXES)


def _discrete_states(variant: Variant) -> tuple:
    return tuple(discrete(name, unit, text) for name, unit, text in state_ports(variant))


STATE, PARAMETERS = "state", "parameters"  # step arguments that are no inputs (see step_model)


def step_model(identifier: str, description: str, inputs: Sequence, arguments: Sequence, step: ca.Function,
               outputs: Sequence[tuple[str, str, str]], table: Sequence, states: Sequence,
               initial: Callable[[ca.SX, ca.SX], Any], n_random: int = 0) -> FmuModel:
    """A sampled-data FMU model around a controller step ``step(*args) ->
    (y, state_next, check)``: ``arguments`` says what each argument of
    ``step`` is, a tuple of names of ``inputs`` stacked into a vector, :data:`STATE`
    (the discrete ``states``) or :data:`PARAMETERS` (the parameters of
    ``table``, :mod:`fnn_controller.parametric`); ``y`` is laid out as
    ``outputs``; ``initial(p, r)`` gives the state after reset from the
    parameter vector and ``n_random`` uniform numbers drawn from
    :data:`FNN_SEED` (no seed when ``n_random`` is 0)."""
    variables = (
        *inputs,
        *(output(name, unit, text) for name, unit, text in outputs),
        *(parameter(p.name, p.unit, p.description, p.default, min=p.min, max=p.max) for p in table),
        *((FNN_SEED,) if n_random else ()),
        *states,
    )

    def vector(v, what):
        names = ([s.name for s in states] if what == STATE else [p.name for p in table] if what == PARAMETERS
                 else what)
        return ca.vertcat(*(v[name] for name in names))

    def update(t, v):
        y, state_next, _ = step(*(vector(v, what) for what in arguments))
        return (dict(zip((name for name, _, _ in outputs), ca.vertsplit(y))),
                dict(zip((s.name for s in states), ca.vertsplit(ca.vertcat(state_next)))))

    def initial_states(v, r):
        return dict(zip((s.name for s in states), ca.vertsplit(ca.vertcat(initial(vector(v, PARAMETERS), r)))))

    return FmuModel(identifier=identifier, description=description, variables=variables,
                    sampled=Sampled(update=update, initial=initial_states, n_random=n_random,
                                    seed=FNN_SEED.name if n_random else None, sample_period="dt"))


@lru_cache(maxsize=None)
def controller_model(variant: str, position: PositionParams = _POSITION,
                     geometric: GeometricParams = _GEOMETRIC) -> FmuModel:
    """The FMU model of ``variant``; ``position`` and ``geometric`` give the
    parameters' start values and the structural choices."""
    v = lookup(variant)
    step = parametric_step_function(variant, PositionParams(), geometric_structure(geometric))
    init = initial_state_function(variant, PositionParams(), geometric_structure(geometric))
    plant = [QUADROTOR.variable(name) for name in STATE_NAMES]  # the rigid body's 12
    inputs = (
        *(input_(name, unit, text) for name, unit, text in REFERENCE_INPUTS),
        *(input_(var.name, var.unit, f"plant state: {var.description}") for var in plant),
        *(input_(name, unit, text) for name, unit, text in ACCELERATION_INPUTS),
        PSI_REF,
    )
    arguments = (tuple(f"{a}_ref" for a in _AXES), tuple(f"v{a}_ref" for a in _AXES), STATE_NAMES, ("psi_ref",),
                 STATE, PARAMETERS, tuple(name for name, _, _ in ACCELERATION_INPUTS))
    return step_model(
        fmu_identifier(variant),
        f"{v.label} flight controller of the LM-FNN paper (Fig. 2): {v.description}; "
        f"geometric SE(3) velocity control (eqs. 13-18); sampled at dt, z axis down",
        inputs, arguments, step, OUTPUTS, parameter_table(variant, position, geometric), _discrete_states(v),
        init, n_random=3 * v.n_random)
