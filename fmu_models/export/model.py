"""A model as the FMU sees it: a variable table plus CasADi equations.

:class:`FmuModel` turns the equations, written once in CasADi symbolics, into
the five functions every FMU of this project is made of (the generic C layer
in ``fmu_models/export/c`` calls nothing else):

=============  ==========================  =====================================
name           signature                   what
=============  ==========================  =====================================
``init``       p -> x0                     initial state from the parameters
``ode``        (t, x, u, p) -> xdot        right-hand side (Model Exchange)
``out``        (t, x, u, p) -> y           algebraic outputs
``step``       (t, x, u, p, h) -> x(t+h)   one classical RK4 step, u held
``jac``        (t, x, u, p) -> J           d[xdot; y]/d[x; u], dense (AD)
=============  ==========================  =====================================

A sampled-data model (a controller: a :class:`Sampled` part, no continuous
states) is made of two others instead:

=============  ==========================  =====================================
``dinit``      (p, r) -> z0                discrete state at initialization from
                                           the parameters and ``n_random``
                                           uniform numbers in [0, 1)
``dstep``      (t, u, p, z) -> (y, z+)     outputs and next discrete state
               (t, u, p, z, rs) -> (y, z+) the same, with ``n_random_step > 0``
                                           fresh uniform numbers ``rs`` in [0, 1)
                                           for the sample being computed
=============  ==========================  =====================================

The uniform numbers come from one stream, numpy's ``default_rng(seed)``: the
first ``n_random`` go to ``dinit``, then ``n_random_step`` per communication
step to ``dstep`` (step 0 first). The generic C core keeps the generator inside
the FMU state, so restoring a state continues the same stream.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable, Mapping

from ..lazy_casadi import ca
from . import staged
from .variables import SEED_MAX, Variable, parameter

__all__ = ["FmuModel", "INTERNAL_STEP"]

# Every model gets this solver parameter; the generic C layer reads it.
# Floor 1 us: RK4's truncation error is below round-off long before that on
# these models, and with the core's cap of 1e7 RK4 steps per doStep a
# communication step of up to 10 s still runs at the floor.
INTERNAL_STEP = parameter(
    "internal_step", "s",
    "fixed step of the FMU's internal RK4 integrator; each communication step "
    "is split into ceil(h / internal_step) equal RK4 steps",
    1e-3, min=1e-6,
)

# strings: reading ca.SX here would load CasADi (fmu_models.lazy_casadi)
Equations = Callable[["ca.SX", Mapping[str, "ca.SX"]], tuple[Mapping[str, "ca.SX"], Mapping[str, "ca.SX"]]]


@dataclass(frozen=True)
class Sampled:
    """The discrete-time part of a sampled-data model, stepped once per
    communication step of exactly ``sample_period`` (a parameter's name).

    ``update(t, v)`` receives the time and every input, parameter and
    discrete state by name and returns ``(outputs, next discrete state)``,
    both by name. ``initial(v, r)`` receives the parameters by name and a
    vector of ``n_random`` uniform numbers, which the FMU draws from numpy's
    ``default_rng(seed)`` with ``seed`` a parameter's name, and returns the
    discrete state by name. A model that draws nothing (``n_random =
    n_random_step = 0``) may have no seed (``seed=None``).

    With ``n_random_step > 0`` the update is ``update(t, v, rs)``: ``rs`` is a
    vector of ``n_random_step`` uniform numbers in [0, 1), the next ones of
    the same stream, fresh at every communication step and the same for every
    evaluation of one step's sample (a get before doStep and the doStep).
    """

    update: Callable[..., tuple[Mapping[str, ca.SX], Mapping[str, ca.SX]]]
    initial: Callable[[Mapping[str, ca.SX], ca.SX], Mapping[str, ca.SX]]
    n_random: int
    seed: str | None
    sample_period: str
    n_random_step: int = 0


@dataclass(frozen=True)
class FmuModel:
    """An FMU model: identifier, variable table and equations.

    ``equations(t, v)`` receives the time and a mapping from every state, input
    and parameter name to its CasADi symbol; it returns two mappings, state
    name -> time derivative and output name -> value. ``initial_state(v)``
    receives the parameter symbols and returns state name -> initial value.
    """

    identifier: str
    description: str
    variables: tuple[Variable, ...]
    equations: Equations | None = field(default=None, repr=False)
    initial_state: Callable[[Mapping[str, ca.SX]], Mapping[str, ca.SX]] | None = field(default=None, repr=False)
    sampled: Sampled | None = field(default=None, repr=False)
    #: a table model: no states, no inputs, its outputs the columns of a table
    #: the FMU reads from its resources (``c/signal_table.h``); ``equations``
    #: give them as zeros, replaced by the table's values
    table: bool = False

    def __post_init__(self) -> None:
        names = [v.name for v in self.all_variables]
        duplicated = {n for n in names if names.count(n) > 1}
        if duplicated:
            raise ValueError(f"model {self.identifier}: duplicated variable names {sorted(duplicated)}")
        if (self.sampled is None) == (self.equations is None):
            raise ValueError(f"model {self.identifier}: give equations (continuous) or a sampled part, not both")
        if self.table and (self.states or self.inputs or self.sampled is not None):
            raise ValueError(f"model {self.identifier}: a table model has outputs and parameters only")
        if self.sampled is not None:
            if self.states:
                raise ValueError(f"model {self.identifier}: a sampled-data model has no continuous states")
            draws = self.sampled.n_random > 0 or self.sampled.n_random_step > 0
            if self.sampled.seed is None and draws:
                raise ValueError(f"model {self.identifier}: it draws random numbers, so it needs a seed parameter")
            roles = [("seed", self.sampled.seed)] if self.sampled.seed is not None else []
            roles.append(("sample_period", self.sampled.sample_period))
            for role, name in roles:
                if name not in {v.name for v in self.parameters}:
                    raise ValueError(f"model {self.identifier}: its {role} {name!r} is not a parameter")
            if self.sampled.n_random < 0 or self.sampled.n_random_step < 0:
                raise ValueError(f"model {self.identifier}: negative count of random numbers")
            seed = next((v for v in self.parameters if v.name == self.sampled.seed), None)
            if seed is not None and not (seed.integer and seed.min >= 0 and seed.max <= SEED_MAX):
                # the FMU seeds numpy's generator with it as set: its table must make it a whole
                # number a double holds exactly
                raise ValueError(f"model {self.identifier}: its seed {seed.name!r} must be an integer "
                                 "parameter within [0, 2^53]")

    # The table's views, each made once per model (the model is frozen): the builder reads them for every
    # variable of every table it writes, which made them quadratic in the variables (the EKFs: ~0.5 s of a
    # first build's CPU).
    @cached_property
    def all_variables(self) -> tuple[Variable, ...]:
        """The table, plus the integrator's ``internal_step`` for a continuous model."""
        own = any(v.name == INTERNAL_STEP.name for v in self.variables)  # a start of its own (with_defaults)
        return self.variables + ((INTERNAL_STEP,) if self.sampled is None and not own else ())

    @cached_property
    def _by_causality(self) -> dict[str, tuple[Variable, ...]]:
        groups: dict[str, list[Variable]] = {}
        for v in self.all_variables:
            groups.setdefault(v.causality, []).append(v)
        return {causality: tuple(group) for causality, group in groups.items()}

    @cached_property
    def _by_name(self) -> dict[str, Variable]:
        return {v.name: v for v in self.all_variables}

    def _of(self, causality: str) -> tuple[Variable, ...]:
        return self._by_causality.get(causality, ())

    @property
    def states(self) -> tuple[Variable, ...]:
        return self._of("state")

    @property
    def discrete_states(self) -> tuple[Variable, ...]:
        return self._of("discrete")

    @property
    def inputs(self) -> tuple[Variable, ...]:
        return self._of("input")

    @property
    def outputs(self) -> tuple[Variable, ...]:
        return self._of("output")

    @property
    def parameters(self) -> tuple[Variable, ...]:
        return self._of("parameter")

    def variable(self, name: str) -> Variable:
        if name in self._by_name:
            return self._by_name[name]
        known = ", ".join(v.name for v in self.all_variables)
        raise KeyError(f"model {self.identifier} has no variable {name!r}; it has: {known}")

    def with_defaults(self, values: Mapping[str, float]) -> "FmuModel":
        """This model with the start values of some parameters and inputs
        replaced by ``values`` (each checked against its variable's range).

        The one number becomes both the modelDescription's ``start`` and the
        default compiled into the binary (both are generated from the table),
        so the FMU runs with ``values`` without being told them, as FMI
        requires of a start value. Its GUID (and so the token of its saved
        states and its build-cache key) is a digest of the table: it cannot be
        taken for the stock FMU's. Unchanged values give an equal table, and
        the same FMU.
        """
        table = {v.name: v for v in self.all_variables}
        for name, value in values.items():
            var = table.get(name)
            if var is None or var.causality not in ("parameter", "input"):
                raise KeyError(f"model {self.identifier} has no parameter or input {name!r}")
            var.check(float(value))
        replaced = tuple(dataclasses.replace(v, start=float(values[v.name])) if v.name in values else v
                         for v in self.variables)
        own = any(v.name == INTERNAL_STEP.name for v in self.variables)
        if INTERNAL_STEP.name in values and self.sampled is None and not own:
            # internal_step is appended to every continuous model's table: kept as a variable of its own
            replaced += (dataclasses.replace(INTERNAL_STEP, start=float(values[INTERNAL_STEP.name])),)
        return dataclasses.replace(self, variables=replaced)

    def parameter_values(self, **overrides: float) -> list[float]:
        """Parameter vector in table order: start values, with ``overrides``
        checked against each variable's bounds."""
        for name, value in overrides.items():
            var = self.variable(name)
            if var.causality != "parameter":
                raise KeyError(f"{name!r} is a {var.causality} of {self.identifier}, not a parameter")
            var.check(value)
        return [overrides.get(v.name, v.start) for v in self.parameters]

    def input_values(self, **overrides: float) -> list[float]:
        return [overrides.get(v.name, v.start) for v in self.inputs]

    @cached_property
    def symbols(self) -> dict[str, ca.SX]:
        """Vector symbols t, x, u, p, h of the generated functions."""
        return {
            "t": ca.SX.sym("t"),
            "x": ca.SX.sym("x", len(self.states)),
            "u": ca.SX.sym("u", len(self.inputs)),
            "p": ca.SX.sym("p", len(self.parameters)),
            "h": ca.SX.sym("h"),
            "z": ca.SX.sym("z", len(self.discrete_states)),
            "r": ca.SX.sym("r", self.sampled.n_random if self.sampled else 0),
            "rs": ca.SX.sym("rs", self.sampled.n_random_step if self.sampled else 0),
        }

    @cached_property
    def functions(self) -> dict[str, ca.Function]:
        """The five CasADi functions of the module docstring, keyed by name."""
        s = self.symbols
        t, x, u, p, h = s["t"], s["x"], s["u"], s["p"], s["h"]
        named: dict[str, ca.SX] = {}
        for vec, group in ((x, self.states), (u, self.inputs), (p, self.parameters), (s["z"], self.discrete_states)):
            named.update({v.name: vec[i] for i, v in enumerate(group)})
        if self.sampled is not None:
            return self._sampled_functions(named)

        derivatives, outputs = self.equations(t, named)
        missing = {v.name for v in self.states} - set(derivatives)
        missing |= {v.name for v in self.outputs} - set(outputs)
        if missing:
            raise ValueError(f"model {self.identifier}: equations do not define {sorted(missing)}")
        xdot = ca.vertcat(*[derivatives[v.name] for v in self.states]) if self.states else ca.SX(0, 1)
        y = ca.vertcat(*[outputs[v.name] for v in self.outputs]) if self.outputs else ca.SX(0, 1)
        x0_named = self.initial_state(named)
        x0 = ca.vertcat(*[x0_named[v.name] for v in self.states]) if self.states else ca.SX(0, 1)

        ode = ca.Function("model_ode", [t, x, u, p], [xdot], ["t", "x", "u", "p"], ["xdot"])
        k1 = ode(t, x, u, p)
        k2 = ode(t + h / 2, x + h / 2 * k1, u, p)
        k3 = ode(t + h / 2, x + h / 2 * k2, u, p)
        k4 = ode(t + h, x + h * k3, u, p)
        x_next = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        unknowns = ca.vertcat(xdot, y)
        knowns = ca.vertcat(x, u)
        return {
            "init": ca.Function("model_init", [p], [x0], ["p"], ["x0"]),
            "ode": ode,
            "out": ca.Function("model_out", [t, x, u, p], [y], ["t", "x", "u", "p"], ["y"]),
            "step": ca.Function("model_step", [t, x, u, p, h], [x_next], ["t", "x", "u", "p", "h"], ["x_next"]),
            "jac": ca.Function(
                "model_jac", [t, x, u, p], [ca.densify(ca.jacobian(unknowns, knowns))],
                ["t", "x", "u", "p"], ["J"],
            ),
        }

    @cached_property
    def inlined_step(self) -> ca.Function:
        """``dstep`` of a sampled-data model as one SX function, every law the
        step calls inlined (:func:`fmu_models.export.staged.inlined`): the same
        values, and the exact structure its modelDescription's dependencies
        are read from."""
        s = self.symbols
        if self.sampled is None or self.functions["dstep"].class_name() == "SXFunction":
            return self.functions["dstep"]
        named = {v.name: vec[i] for vec, group in ((s["u"], self.inputs), (s["p"], self.parameters),
                                                   (s["z"], self.discrete_states)) for i, v in enumerate(group)}
        with staged.inlined():
            return self._sampled_functions(named)["dstep"]

    def _sampled_functions(self, named: dict[str, ca.SX]) -> dict[str, ca.Function]:
        """``dinit`` and ``dstep`` of a sampled-data model."""
        s = self.symbols
        t, u, p, z, r, rs = s["t"], s["u"], s["p"], s["z"], s["r"], s["rs"]
        stochastic = self.sampled.n_random_step > 0
        with staged.recording() as calls:  # the laws the step calls as functions (fmu_models.export.staged)
            outputs, z_next = self.sampled.update(t, named, rs) if stochastic else self.sampled.update(t, named)
        params = {v.name: named[v.name] for v in self.parameters}
        z0 = self.sampled.initial(params, r)
        missing = ({v.name for v in self.outputs} - set(outputs)) | ({v.name for v in self.discrete_states} - set(z_next))
        missing |= {v.name for v in self.discrete_states} - set(z0)
        if missing:
            raise ValueError(f"model {self.identifier}: the sampled part does not define {sorted(missing)}")
        # dense: a structurally zero entry (e.g. an off-diagonal of a diagonal matrix) would otherwise be left
        # out of the generated code's output, which the C layer reads as one value per variable
        y = ca.densify(ca.vertcat(*[outputs[v.name] for v in self.outputs]))
        z_plus = ca.densify(ca.vertcat(*[z_next[v.name] for v in self.discrete_states]))
        z_init = ca.densify(ca.vertcat(*[z0[v.name] for v in self.discrete_states]))
        # rs only where the model asks for it: the others' generated code stays as it was
        inputs, names = ([t, u, p, z, rs], ["t", "u", "p", "z", "rs"]) if stochastic else ([t, u, p, z], ["t", "u", "p", "z"])
        return {
            "dinit": ca.Function("model_dinit", [p, r], [z_init], ["p", "r"], ["z0"]),
            "dstep": (staged.function("model_dstep", inputs, [y, z_plus], names, ["y", "z_next"], calls) if calls else
                      ca.Function("model_dstep", inputs, [y, z_plus], names, ["y", "z_next"])),
        }
