"""The one table of model variables.

Every FMU model is described by a list of :class:`Variable` entries (name,
causality, unit, start, bounds, description). The modelDescription.xml files,
the C value-reference table and the Python constants are all generated from
that list; no value reference is ever typed by hand.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Variable", "UNITS", "SEED_MAX", "state", "discrete", "input_", "output", "parameter", "seed_parameter"]

# A seed is an FMU parameter, a double: every whole number up to 2^53 is exact
# in it, so a seed in [0, SEED_MAX] reaches the model's generator as it was set.
SEED_MAX = 2.0 ** 53


# SI base-unit exponents of every unit a model may use (FMI <UnitDefinitions>).
UNITS: dict[str, dict[str, int]] = {
    "1": {},
    "s": {"s": 1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "1/s": {"s": -1},
    "1/s2": {"s": -2},
    "1/m": {"m": -1},
    "kg": {"kg": 1},
    "kg.m2": {"kg": 1, "m": 2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    # Rotor coefficients multiply Omega^2 with Omega in rad/s.
    "N.s2": {"kg": 1, "m": 1},
    "N.m.s2": {"kg": 1, "m": 2},
    "N.s/m": {"kg": 1, "s": -1},
    "N.s2/m2": {"kg": 1, "m": -1},
    "N.s2/m": {"kg": 1},  # rotor drag and inflow: N per (rad/s) per (m/s), the radian left out as above
    "T": {"kg": 1, "s": -2, "A": -1},   # tesla: the magnetometer's field
}


@dataclass(frozen=True)
class Variable:
    """One scalar Float64 variable of an FMU model.

    ``causality`` is one of ``state`` (a continuous state, exposed as an
    output), ``discrete`` (the state of a sampled-data model, exposed as a
    local variable), ``input``, ``output`` (an algebraic output) or
    ``parameter``.
    ``min``/``max`` are enforced by the FMU on every set and written into
    the modelDescription. Both are inclusive, as FMI's are: a quantity that
    must be positive gets a stated positive floor, never an implied open
    bound the modelDescription could not express. ``integer``: a count kept
    as a Float64 (a number of steps), refused by the FMU and by
    :meth:`check` unless whole.
    """

    name: str
    causality: str
    unit: str
    description: str
    start: float | None = None
    min: float = -math.inf
    max: float = math.inf
    integer: bool = False
    #: a unit outside :data:`UNITS` (a signal table's column): its SI
    #: definition as ``<BaseUnit>`` attributes (exponents, ``factor``,
    #: ``offset``); empty when nothing defines it (then its name is all the
    #: modelDescription says)
    base_unit: tuple[tuple[str, float], ...] | None = None

    def __post_init__(self) -> None:
        if self.causality not in ("state", "discrete", "input", "output", "parameter"):
            raise ValueError(f"variable {self.name!r}: unknown causality {self.causality!r}")
        if self.unit not in UNITS and self.base_unit is None:
            raise ValueError(f"variable {self.name!r}: unit {self.unit!r} is not in UNITS")
        if self.causality in ("input", "parameter") and self.start is None:
            raise ValueError(f"variable {self.name!r}: an {self.causality} needs a start value")
        if not self.min <= self.max:
            raise ValueError(f"variable {self.name!r}: min = {self.min!r} is above max = {self.max!r}")
        if self.start is not None:
            self.check(self.start)  # a default the FMU would refuse is a bug in the table

    def check(self, value: float) -> None:
        """Raise ``ValueError`` naming the variable if ``value`` is not admissible.

        The same test as the FMU's (``check_value`` in ``fmu_models/export/c/fmu_core.c``):
        finite, within ``[min, max]`` and, for an ``integer`` variable, whole.
        """
        if not math.isfinite(value):
            raise ValueError(f"{self.name} = {value!r} is not a finite number")
        unit = "" if self.unit == "1" else f" {self.unit}"
        if not self.min <= value <= self.max:
            raise ValueError(
                f"{self.name} = {value!r}{unit} is outside its range "
                f"[{self.min!r}, {self.max!r}]"
            )
        if self.integer and value != math.floor(value):
            raise ValueError(f"{self.name} = {value!r} is not a whole number")


def state(name, unit, description):
    return Variable(name, "state", unit, description)


def input_(name, unit, description, start=0.0, **bounds):
    return Variable(name, "input", unit, description, start, **bounds)


def output(name, unit, description):
    return Variable(name, "output", unit, description)


def parameter(name, unit, description, start, **bounds):
    return Variable(name, "parameter", unit, description, start, **bounds)


def discrete(name, unit, description):
    return Variable(name, "discrete", unit, description)


def seed_parameter(name, description, start=0.0):
    """A model's seed: a whole-number parameter in [0, :data:`SEED_MAX`]."""
    return parameter(name, "1", description, start, min=0.0, max=SEED_MAX, integer=True)
