"""The flight controller of ``fnn_controller`` as a component of the master.

A scenario's ``[controller]`` runs as the controller FMU of its variant
(``form = "fmu"``, the default: :mod:`fnn_controller.controller_fmu`, the
parametric step compiled, built on demand), so a mission of FMUs only runs
in the master's compiled loop (:mod:`cosim.loop.kernel`). Its learned state
starts from the run's seed, or from a saved one (``learned``,
:mod:`quadrotor_paper.learned`).

``form = "python"`` runs the same parametric step in process instead, one
adapter with no layer between it and CasADi: the step function
(:func:`fnn_controller.parametric.parametric_step`) behind a
:class:`~fnn_controller.FastFunction`; the master gathers the 21 inputs
straight into the function's input arrays (``input_buffers``) and takes the
17 outputs from its output vector. Its purpose: a variant being written
runs at once, with no C code generated and compiled per change, and a step
that goes non-finite is reported naming the input or law that did
(``fnn_controller.step.raise_non_finite``) rather than the state that
became non-finite. Both forms fly bit for bit alike
(``tests/paper/test_controller_component.py``).

Ports (NED world frame, SI units):

========= ========================================================== =====
inputs    x_ref y_ref z_ref (p*), vx_ref vy_ref vz_ref (dp*/dt)       m, m/s
          x y z u v w phi theta psi p q r (plant state)               SI
          ax_ref ay_ref az_ref (d²p*/dt², start 0: may stay          m/s2
          unconnected; read with position.accel_feedforward > 0)
outputs   Omega_1..Omega_4 (rotor speeds, to the plant)               rad/s
          v_ref_x/y/z (v* = tau_c - tau_n, eq. 26)                    m/s
          tau_c_x/y/z (PD part, eq. 19), tau_n_x/y/z (FNN part, eq. 24) m/s
          T tau_phi tau_theta tau_psi (eq. 18, before saturation)     N, N.m
internals the learned parameters of each axis, e.g. ``f_12_x``,
          ``sigma1_2_z``, ``alpha_y`` (the variant's axis state ports),
          at t_n the ones the control at t_n was computed with (the FMU
          form: its local variables, which also hold the previous R*)
========= ========================================================== =====

The controller's nominal vehicle (mass, inertia, rotor coefficients, the
rotor limit) is the plant's: ``plant`` names the FMU instance it is taken
from (default ``Quadrotor``; its scenario parameters over the FMU's start
values), and ``nominal = { m = 1.2 }`` is a deliberate, named mismatch.

The run's seed draws f_ij(0) (§5.1) at every start.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import fields
from typing import Annotated, Any, Mapping

import numpy as np

from cosim.component import Port, PythonComponent
from cosim.errors import DivergenceError, ScenarioError
from cosim.scenario.parameters import Given
from fnn_controller.variants import DEFAULT_VARIANT

__all__ = ["ControllerComponent", "ControllerSettings", "controller_settings", "controller_variant",
           "CONTROLLER_INPUTS", "CONTROLLER_OUTPUTS", "DEFAULT_PLANT", "internal_ports"]

DEFAULT_PLANT = "Quadrotor"
FORMS = ("python", "fmu")
# the defaults of a [controller] table's keys (its declaration, controller_table, and a validated table's values
# read without it, Given)
_DEFAULTS = {"variant": DEFAULT_VARIANT, "psi_ref": 0.0, "position": None, "geometric": None, "plant": DEFAULT_PLANT,
             "nominal": None, "form": "fmu", "fmi_version": 2, "interface": "CoSimulation", "learned": None}
_AXES = "xyz"


def _ports() -> tuple[tuple[Port, ...], tuple[Port, ...]]:
    from fmu_models.models.quadrotor import QUADROTOR, STATE_NAMES
    from fnn_controller.step import OUTPUTS
    from fnn_controller.controller_fmu import ACCELERATION_INPUTS

    inputs = (
        *(Port(f"{a}_ref", "m", description=f"reference position {a}") for a in _AXES),
        *(Port(f"v{a}_ref", "m/s", description=f"reference velocity d{a}*/dt") for a in _AXES),
        *(Port(v.name, v.unit, description=f"plant state: {v.description}")
          for v in (QUADROTOR.variable(name) for name in STATE_NAMES)),
        *(Port(name, unit, description=text, start=0.0) for name, unit, text in ACCELERATION_INPUTS),
    )
    return inputs, tuple(Port(name, unit, description=text) for name, unit, text in OUTPUTS)


CONTROLLER_INPUTS, CONTROLLER_OUTPUTS = _ports()


def internal_ports(variant_name: str) -> tuple[Port, ...]:
    """The learned state the component publishes for ``variant_name``: each
    axis state port of the variant, per axis (``f_12_x``)."""
    from fnn_controller.step import state_ports
    from fnn_controller.variants import variant

    v = variant(variant_name)
    n = 3 * v.axis_state_size
    return tuple(Port(name, unit, description=text) for name, unit, text in state_ports(v)[:n])


def _nominal_vehicle(name: str, plant: str, nominal: Mapping[str, Any], context) -> dict[str, float]:
    """The vehicle the controller assumes: the plant FMU's parameters, then
    the deliberate mismatch ``nominal``."""
    from fnn_controller import VehicleParams

    keys = [f.name for f in fields(VehicleParams)]
    vehicle: dict[str, float] = {}
    fmu = context.fmus.get(plant) if context is not None and plant else None
    if context is not None and plant and fmu is None:
        raise ScenarioError(f"{name}.plant = {plant!r}: no such FMU in [fmus]; FMUs: {', '.join(context.fmus)}")
    if fmu is not None:
        given = context.scenario.fmus[plant]["parameters"]
        for key in keys:
            var = fmu.variables.get(key)
            if key in given:
                vehicle[key] = float(given[key])
            elif var is not None and var.start is not None:
                vehicle[key] = float(var.start)
    vehicle.update(nominal)
    return vehicle


def _parameters(cls, value: Any, where: str, base: Any = None) -> Any:
    """A parameter dataclass from its table's values (a mapping, or a
    validated table), over ``base`` (default: the dataclass's defaults)."""
    if isinstance(value, cls):
        return value
    if value is None:  # no table: the base as it is
        return cls() if base is None else base
    if hasattr(value, "applied"):  # a validated table (ParameterTable, Given)
        return value.applied(cls() if base is None else base)
    from cosim.scenario.schema import dataclass_table, validate

    return validate(dataclass_table(cls), dict(value), where).applied(base)


def _unknown_variant(name: Any) -> str | None:
    """Why ``name`` is no registered variant, or ``None``: the one check of a
    controller's variant (the scenario's table, the component's constructor)."""
    from fnn_controller.variants import variant_names

    return None if name in variant_names() else f"expected one of {', '.join(variant_names())}"


def _known_variant(name: str) -> str:
    from cosim.scenario.schema import refuse

    if (why := _unknown_variant(name)) is not None:
        raise refuse(why, value=name)
    return name


def _no_vehicle(value: Any) -> Any:
    from cosim.scenario.schema import refuse

    if isinstance(value, Mapping) and "vehicle" in value:
        raise refuse("the nominal vehicle is the plant's (the controller's plant); set a deliberate mismatch in "
                     "its nominal table", key="vehicle")
    return value


@functools.lru_cache(maxsize=None)
def controller_table() -> type[Table]:
    """The declaration of a ``[controller]`` table (``docs/controller.md``):
    the variant, the yaw command, the position and geometric controllers'
    parameters (their dataclasses' fields, units and ranges), the plant the
    nominal vehicle is read from and the deliberate mismatch, the form, the
    FMI version, a learned state to resume from."""
    from pydantic import AfterValidator, BeforeValidator, Field, WithJsonSchema, model_validator

    from cosim.scenario.schema import Number, Table, dataclass_table, one_of, refuse
    from fnn_controller import GeometricParams, PositionParams, VehicleParams
    from fnn_controller.position_parameters import check_one_step
    from fnn_controller.variants import variant_names

    d = _DEFAULTS

    class ControllerTable(Table):
        variant: Annotated[str, Field(strict=True), AfterValidator(_known_variant),
                           WithJsonSchema({"type": "string", "enum": list(variant_names())})] = Field(
            d["variant"], description="the controller variant: its laws and learned state")
        psi_ref: Number = Field(d["psi_ref"], description="commanded yaw psi* [rad]")
        position: dataclass_table(PositionParams) = Field(d["position"], description="position controller (section 3.1)")
        geometric: Annotated[dataclass_table(GeometricParams), BeforeValidator(_no_vehicle)] = Field(
            d["geometric"], description="geometric velocity controller (eqs. 13-18); its vehicle is the plant's")
        plant: Annotated[str, Field(strict=True)] = Field(
            d["plant"], description="the FMU whose parameters are the nominal vehicle ('' for none)")
        nominal: dataclass_table(VehicleParams) = Field(
            d["nominal"], description="a deliberate mismatch: vehicle parameters that differ from the plant's")
        form: one_of(FORMS) = Field(d["form"], description="'fmu': the controller FMU (the compiled loop); 'python': "
                                                           "the same step in process")
        fmi_version: one_of((2, 3), "expected 2 or 3", int) = Field(d["fmi_version"],
                                                                    description="FMI version of the FMU form")
        interface: one_of(("CoSimulation", "ModelExchange")) = Field(
            d["interface"], description="how the master drives the FMU form; 'ModelExchange' needs fmi_version = 3 "
                                        "(the clocked controller: its ticks are time events)")
        learned: Annotated[str, Field(strict=True)] = Field(d["learned"],
                                                            description="a learned-state file to resume from")

        @model_validator(mode="after")
        def _one_step(self):
            position_dt = self.position.dt if self.position is not None and self.position.dt is not None \
                else PositionParams().dt
            geometric_dt = self.geometric.dt if self.geometric is not None and self.geometric.dt is not None \
                else None
            if geometric_dt is not None:
                try:
                    check_one_step(position_dt, geometric_dt)
                except ValueError as e:
                    raise refuse(str(e).split(": ", 1)[1], key="geometric.dt", value=geometric_dt) from None
            return self

        @model_validator(mode="after")
        def _flown_gains(self):
            from fnn_controller.position_parameters import FLOWN_KD_MIN

            kd = self.position.kd if self.position is not None else None
            if kd is not None and kd < FLOWN_KD_MIN:  # negative damping, silently flown before (issue 28)
                raise refuse(f"must be in [{FLOWN_KD_MIN:g}, inf): a flight's derivative gain (the stability "
                             f"analysis maps kd < 0; below -1 the vehicle runs away)", key="position.kd", value=kd)
            return self

    return ControllerTable


def _check_period(name: str, dt: float, step: float) -> None:
    """The controller computes once per ``position.dt``: a master takes no
    other communication step (the rule of every sampled-data part, :func:`cosim.time_grid.runs_at`)."""
    from cosim.time_grid import runs_at

    if not runs_at(step, dt):
        raise ScenarioError(f"{name}.position.dt = {dt!r}: the controller's period must equal the communication "
                            f"step simulation.step = {step!r} s")


class ControllerComponent(PythonComponent):
    """PD + FNN position control and geometric velocity control (paper Fig. 2).

    Parameters
    ----------
    variant : a registered variant (``"pd"``, ``"pd+smc"``, ``"pd+lm"``, ...),
        which fixes the laws and the learned state (as the FMU's model does):
        a scenario override ``controller.variant`` changes it, no run-level
        parameter.
    position, geometric : mappings of :class:`fnn_controller.PositionParams`
        and :class:`fnn_controller.GeometricParams` fields (nested tables for
        ``init``, ``bounds``); unset fields keep the defaults.
    psi_ref : commanded yaw (rad).
    vehicle : :class:`fnn_controller.VehicleParams` fields, the nominal model
        (see :meth:`from_parameters` for how a scenario ties it to the plant).
    """

    inputs = CONTROLLER_INPUTS
    outputs = CONTROLLER_OUTPUTS

    def __init__(self, variant: str = DEFAULT_VARIANT, position: Any = None, geometric: Any = None,
                 psi_ref: float = 0.0, name: str = "controller", vehicle: Mapping[str, Any] | None = None):
        super().__init__(name)
        import fnn_controller as fc

        self._fc = fc
        self.position = _parameters(fc.PositionParams, position, f"{name}.position")
        base = dataclasses.replace(fc.GeometricParams(), dt=self.position.dt)  # one step for both loops
        if vehicle:  # the nominal vehicle first: the geometric table cannot set it (controller_table)
            base = dataclasses.replace(base, vehicle=dataclasses.replace(base.vehicle, **vehicle))
        self.geometric = _parameters(fc.GeometricParams, geometric, f"{name}.geometric", base)
        self.psi_ref = float(psi_ref)
        self.variant = self._check_variant(variant)
        self.internals = internal_ports(self.variant)
        self._fast = None
        self.learned: np.ndarray | None = None  # a saved state to start from instead of the seed's

    @classmethod
    def from_parameters(cls, name: str, parameters: Mapping[str, Any], context=None,
                        validated: bool = False) -> "ControllerComponent":
        """The component of a scenario's ``[controller]`` (or ``[components.NAME]
        kind = "fnn_controller"``) table; errors name ``name.key``.

        ``plant`` (default ``"Quadrotor"``, ``""`` for none) is the FMU whose
        parameters are the nominal vehicle; ``nominal`` overrides some of them
        on purpose (model mismatch). The vehicle is not set through
        ``geometric.vehicle``: one way to say it. ``validated``: ``parameters``
        are a validated table's values (a scenario's, which validated them
        with the whole document): read as they are (:class:`cosim.scenario.parameters.Given`).
        """
        if validated:
            table = Given(parameters, _DEFAULTS)
        else:
            from cosim.scenario.schema import validate

            table = validate(controller_table(), parameters, name)
        nominal = {}
        if table.nominal is not None:
            from fnn_controller import VehicleParams

            nominal = dataclasses.asdict(table.nominal.applied(VehicleParams()))
            nominal = {k: v for k, v in nominal.items() if k in table.nominal.model_fields_set}
        plant = table.plant
        if context is not None and plant not in context.fmus and "plant" not in table.model_fields_set:
            plant = ""  # no FMU of the default name: the controller keeps its own defaults
        vehicle = _nominal_vehicle(name, plant, nominal, context)
        try:
            component = cls(table.variant, table.position, table.geometric, table.psi_ref, name=name,
                            vehicle=vehicle)
        except ValueError as exc:  # a parameter dataclass refused a combination of values
            raise ScenarioError(f"{name}: {exc}") from None
        form, version = table.form, table.fmi_version
        if context is not None:  # refused before any run, not at its start
            _check_period(name, component.position.dt, context.scenario.step)
        if "learned" in parameters:  # resume learning from a saved state
            from .learned import load_learned

            component.learned = load_learned(table.learned, component.variant)
        return component.as_fmu(version, table.interface) if form == "fmu" and context is not None else component

    def fmu_entry(self, fmi_version: int = 2) -> dict[str, Any]:
        """This controller as an ``[fmus]`` entry: the FMU of its variant
        (:func:`fnn_controller.controller_fmu.fmu_identifier`), its
        parameters set to this component's, ``psi_ref`` (a parameter, held for
        the run), its seed parameter (if its variant
        draws f_ij(0)) bound to the run's seed."""
        from fnn_controller.fmu_names import fmu_identifier, seed_parameter_name
        from fnn_controller.parametric import parameter_table

        values = {p.name: p.default for p in parameter_table(self.variant, self.position, self.geometric)}
        seed = seed_parameter_name(self.variant)
        return {"model": fmu_identifier(self.variant), "fmi_version": fmi_version,
                "parameters": {**values, "psi_ref": self.psi_ref}, **({"seed_parameter": seed} if seed else {})}

    def as_fmu(self, fmi_version: int = 2, interface: str = "CoSimulation"):
        """This controller as its FMU (:meth:`fmu_entry`; the same parametric
        step compiled, :func:`fnn_controller.controller_fmu.controller_model`),
        starting from :attr:`learned` if set."""
        from .models import controller_fmu_model
        from .learned import LearnedControllerFmu

        entry = self.fmu_entry(fmi_version)
        return LearnedControllerFmu(self.name, controller_fmu_model(self.variant).build(fmi_version),
                                    parameters=entry["parameters"], seed_parameter=entry.get("seed_parameter"),
                                    variant=self.variant, state=self.learned, interface=interface)

    def _check_variant(self, variant: Any) -> str:
        if (why := _unknown_variant(variant)) is not None:
            raise ScenarioError(f"{self.name}.variant = {variant!r}: {why}")
        return variant

    def function(self):
        """The :class:`~fnn_controller.FastFunction` of the variant's parametric
        step (built once; the same function the controller FMU is generated
        from), its parameter input filled from this component's parameters."""
        if self._fast is None:
            from fnn_controller.parametric import parametric_step

            function, p = parametric_step(self.variant, self.position, self.geometric)
            fast = self._fc.FastFunction(function, state=("state", "state_next"))
            fast.inputs["p"][:] = p
            self._fast = fast
        return self._fast

    def set_parameters(self, values: Mapping[str, Any]) -> None:
        unknown = set(values) - {"psi_ref"}
        if unknown:
            raise KeyError(f"{self.name}: the run-level parameter is 'psi_ref', not {sorted(unknown)} "
                           f"(the variant is the scenario's: override controller.variant)")
        self._psi = float(values.get("psi_ref", self.psi_ref))

    def start(self, t0: float, h: float, n_steps: int, seed: int) -> None:
        _check_period(self.name, self.position.dt, h)  # a component made without a scenario: checked here
        if not hasattr(self, "_psi"):
            self._psi = self.psi_ref
        fast = self.function()
        if self.learned is not None:
            fast.state[:] = self.learned  # resume learning
        else:
            fast.state[:] = self._fc.initial_state(self._fc.variant(self.variant), seed, self.position)
        fast.inputs["psi_ref"][0] = self._psi
        self._n_internal = len(self.internals)
        self._last = n_steps
        self._pending = False

    def input_buffers(self) -> list[np.ndarray]:
        """The step function's own input arrays (p*, dp*/dt, plant state, d²p*/dt²), in port order."""
        ins = self._fast.inputs
        return [ins["p_ref"], ins["p_ref_dot"], ins["x"], ins["p_ref_ddot"]]

    def step(self, n: int, t: float, u: np.ndarray | None) -> np.ndarray:
        fast = self._fast
        if self._pending:  # the update of the step before takes effect now, so that between
            fast.commit()  # steps the state is the one the last control was computed with
        if u is not None:  # called without input_buffers(): copy the inputs in
            ins = fast.inputs
            ins["p_ref"][:], ins["p_ref_dot"][:], ins["x"][:] = u[0:3], u[3:6], u[6:18]
            ins["p_ref_ddot"][:] = u[18:21]
        fast.evaluate()
        pending = fast.pending
        if not math.isfinite(pending["check"][0]):
            try:
                self._fc.step.raise_non_finite(fast.inputs)
            except (ValueError, FloatingPointError) as exc:
                raise DivergenceError(t, f"{self.name} ({exc})", float("nan"), None) from None
        self._pending = n < self._last  # at the last point no step follows: nothing learned
        return pending["y"]

    @property
    def state(self) -> np.ndarray:
        """A copy of the whole controller state after the run (the last point
        learns nothing: the state the last control was computed with)."""
        return self._fast.state.copy()

    def internal_values(self) -> np.ndarray:
        """The learned state of the three axes (the position part of the
        state) the control at t_n was computed with, as the FMU form's
        local variables read at t_n."""
        return self._fast.state[:self._n_internal]


@dataclasses.dataclass(frozen=True)
class ControllerSettings:
    """What a scenario's controller flies, validated: its instance name, the
    FMU it flies (``plant``, whose parameters are its nominal vehicle; ``""``
    for none), its variant and its position controller's parameters
    (:class:`fnn_controller.PositionParams`)."""

    instance: str
    plant: str
    variant: str
    position: Any


def _controller_instance(scenario, instance: str | None) -> str | None:
    """``instance`` if it is one of ``scenario``'s controllers, else (``None``
    given) its one ``fnn_controller`` component; ``None`` without one."""
    found = [name for name, spec in scenario.components.items() if spec.get("kind") == "fnn_controller"]
    if instance is None:
        if len(found) > 1:
            raise ScenarioError(f"the scenario has {len(found)} controllers ({', '.join(found)}): name one")
        instance = found[0] if found else None
    return instance if instance in found else None


def controller_variant(scenario, instance: str | None = None) -> str | None:
    """The variant ``scenario``'s controller flies (``None`` without one): its
    table's ``variant`` (checked when the scenario was parsed), else the
    table's default. Read on every study row, so without validating the
    table again (:func:`controller_settings` does, for the rest)."""
    instance = _controller_instance(scenario, instance)
    if instance is None:
        return None
    return scenario.components[instance]["parameters"].get("variant", DEFAULT_VARIANT)


def controller_settings(scenario, instance: str | None = None) -> ControllerSettings | None:
    """The settings of ``scenario``'s controller ``instance`` (default: its one
    ``fnn_controller`` component), ``None`` without one: the one way the
    application reads a controller's settings (the scenario's table
    validated as a run builds it, its defaults included)."""
    instance = _controller_instance(scenario, instance)
    if instance is None:
        return None
    parameters = scenario.components[instance]["parameters"]
    component = ControllerComponent.from_parameters(instance, parameters)  # the table validated once, here
    # the plant given, else the default one when the scenario has it (as from_parameters ties the vehicle)
    plant = parameters.get("plant", DEFAULT_PLANT if DEFAULT_PLANT in scenario.fmus else "")
    return ControllerSettings(instance, plant, component.variant, component.position)
