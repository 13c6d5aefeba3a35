"""Units by meaning: SI base-unit exponents, a factor and an offset.

FMI 2.0 (section 2.2.2, "Definition of Units") and FMI 3.0 (section 2.4.3,
"Unit Definitions") define a unit by the exponents of the SI base units kg,
m, s, A, K, mol, cd and rad (``<BaseUnit kg=".." m=".." ... rad="..">``) and
a ``factor`` and an ``offset``:

    value_SI = factor * value + offset

so two units are one quantity when their exponents are equal, and a value
in one converts to the other by a factor and an offset. This module holds
that form (:class:`Unit`), reads it from a modelDescription's
``UnitDefinitions`` (:func:`definitions`, fmpy's ``unitDefinitions``) and,
for a unit name no definition gives, from the name itself, parsed by pint
(:func:`parse`): ``rad/s`` and ``radian / second`` are one unit, ``km/h``
is ``m/s`` times 1000/3600, ``degC`` is ``K`` with an offset of 273.15.
:func:`conversion` gives the factor and offset between two units, or a
one-line :class:`~cosim.errors.ConnectionCheckError` naming both.

Decisions where the standards leave a choice (docs/cosim.md, "Units"):

* ``rad`` is a base unit, as in FMI: pint reads the radian as dimensionless,
  but its exponent is kept here (pint's root units keep ``radian``), so
  ``rad/s`` and ``1/s`` (or ``Hz``) are different quantities, and so are
  ``rad`` and ``1``; ``deg`` and ``rpm`` are radians by a factor.
* ``1``, ``dimensionless`` and the empty name are the dimensionless unit
  (every exponent 0, factor 1); a port that declares no unit at all is not
  checked.
* A definition in the modelDescription wins over the name; a ``<Unit>``
  without ``<BaseUnit>`` says nothing about SI, so its name is parsed.
* A display unit (``<DisplayUnit>``, a variable's ``displayUnit``) is how a
  tool shows a value, never how it crosses a connection (the value is
  always in ``unit``), so it takes no part here.
* Two ports with the same unit name and no definition are the same unit
  even if pint does not know the name (nothing says otherwise).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Mapping

from ..errors import ConnectionCheckError

__all__ = ["BASE_UNITS", "Unit", "definition", "definitions", "parse", "unit_of", "conversion", "describe",
           "DIMENSIONLESS"]

# the SI base units of FMI 2.0 section 2.2.2 / FMI 3.0 section 2.4.3, in the standards' order
BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

# pint's root units -> the FMI base unit; pint's root of mass is the gram
_PINT_ROOTS = {"gram": "kg", "meter": "m", "second": "s", "ampere": "A", "kelvin": "K", "mole": "mol",
               "candela": "cd", "radian": "rad"}
_DIMENSIONLESS_NAMES = ("", "1", "dimensionless")


@dataclass(frozen=True)
class Unit:
    """A unit as FMI defines it: ``exponents`` of :data:`BASE_UNITS` (in that
    order), with ``value_SI = factor * value + offset``; ``name`` as written."""

    name: str
    exponents: tuple[int, ...]
    factor: float = 1.0
    offset: float = 0.0

    def same_quantity(self, other: "Unit") -> bool:
        """Both measure the same quantity (equal exponents): a factor and an offset convert one to the other."""
        return self.exponents == other.exponents

    @property
    def si(self) -> str:
        """The exponents as a unit name (``rad.s-1``; ``1`` when dimensionless)."""
        parts = [b if e == 1 else f"{b}{e}" for b, e in zip(BASE_UNITS, self.exponents) if e]
        return ".".join(parts) or "1"


DIMENSIONLESS = Unit("1", (0,) * len(BASE_UNITS))


def definition(unit: Any) -> Unit | None:
    """The :class:`Unit` of one fmpy ``Unit`` (``model_description.unitDefinitions``),
    or ``None`` if it has no ``<BaseUnit>`` (then its name is all it says)."""
    base = getattr(unit, "baseUnit", None)
    if base is None:
        return None
    return Unit(unit.name, tuple(int(getattr(base, b)) for b in BASE_UNITS), float(base.factor),
                float(base.offset))


def definitions(model_description: Any) -> dict[str, Unit]:
    """The units a modelDescription defines with their SI base units, by name."""
    out = {}
    for unit in getattr(model_description, "unitDefinitions", None) or ():
        made = definition(unit)
        if made is not None:
            out[unit.name] = made
    return out


@lru_cache(maxsize=1)
def _registry():
    import pint  # imported on first use: a registry takes a fraction of a second to build

    return pint.UnitRegistry()


# Modelica's unit syntax (which FMUs exported from Modelica tools use): "m/s2", "kg.m2"
_MODELICA_EXPONENT = re.compile(r"(?<=[A-Za-z])(-?\d+)")


def _pint_quantity(name: str):
    import pint

    registry = _registry()
    for text in (name, _MODELICA_EXPONENT.sub(r"^\1", name)):
        try:
            return registry.Quantity(1.0, text)
        except (pint.errors.PintError, AttributeError, TypeError, ValueError, SyntaxError, KeyError):
            continue
    return None


# one power of an FMI base unit as a name writes it: m, s2, s-1, m^2
_BASE_POWER = re.compile(r"(kg|mol|cd|rad|m|s|A|K)(?:\^?(-?\d+))?")


def _base_units_only(name: str) -> Unit | None:
    """The :class:`Unit` of a name written with the FMI base units alone
    (``m``, ``rad/s``, ``m/s2``, ``kg.m2``, ``1/s``: powers of
    :data:`BASE_UNITS` joined by ``.`` or ``*``, at most one ``/``), read
    from the name itself: factor 1, no offset, what pint gives for it
    (test). ``None`` for any other name (``ms``, ``Hz``, ``km/h``,
    parentheses), which pint reads. Most ports are named so, and pint's
    registry costs about a second to build."""
    numerator, slash, denominator = name.partition("/")
    if "/" in denominator:
        return None
    exponents = dict.fromkeys(BASE_UNITS, 0)
    for part, sign in ((numerator, 1), (denominator, -1)) if slash else ((numerator, 1),):
        if slash and sign == 1 and part.strip() == "1":
            continue  # 1/s
        for token in re.split(r"[.*]", part):
            power = _BASE_POWER.fullmatch(token.strip())
            if power is None:
                return None
            exponents[power[1]] += sign * int(power[2] or 1)
    return Unit(name, tuple(exponents[b] for b in BASE_UNITS))


@lru_cache(maxsize=1024)
def parse(name: str) -> Unit | None:
    """The :class:`Unit` of a unit name, by pint (``None`` if pint does not
    know it, or it is no product of powers of the FMI base units).

    The name is read as pint reads it, and failing that in Modelica's
    syntax (``m/s2``, ``kg.m2``); an offset unit (``degC``, ``degF``) takes
    its factor and offset from pint's definition of it. A name of base
    units alone is read without pint (:func:`_base_units_only`).
    """
    if name.strip() in _DIMENSIONLESS_NAMES:
        return Unit(name, DIMENSIONLESS.exponents)
    plain = _base_units_only(name)
    if plain is not None:
        return plain
    quantity = _pint_quantity(name)
    if quantity is None:
        return None
    registry = _registry()
    offset = 0.0
    if not quantity._is_multiplicative:  # degC, degF: pint keeps them as one unit with an offset converter
        units = dict(quantity.units._units)
        if len(units) != 1 or next(iter(units.values())) != 1:
            return None
        converter = registry._units[next(iter(units))].converter
        scale, offset = float(converter.scale), float(converter.offset)
        reference = registry._units[next(iter(units))].reference
        root = registry.Quantity(scale, reference).to_root_units()
        offset = offset * float(root.magnitude) / scale
    else:
        root = quantity.to_root_units()
    factor = float(root.magnitude)
    exponents = dict.fromkeys(BASE_UNITS, 0)
    for root_name, power in root.units._units.items():
        base = _PINT_ROOTS.get(root_name)
        if base is None or power != int(power):  # bits, counts, half powers: no FMI unit
            return None
        exponents[base] = int(power)
        if root_name == "gram":  # to the kilogram by an exact power of 1000
            factor = factor / 1000.0 ** power if power > 0 else factor * 1000.0 ** -power
    return Unit(name, tuple(exponents[b] for b in BASE_UNITS), factor, offset)


def unit_of(name: str, defined: Mapping[str, Unit] | Unit | None = None) -> Unit | None:
    """The meaning of unit ``name``: its definition (one :class:`Unit`, or
    the modelDescription's, by name) when there is one, else :func:`parse`."""
    if isinstance(defined, Unit):
        return defined
    if defined and name in defined:
        return defined[name]
    return parse(name)


def describe(name: str, unit: Unit | None) -> str:
    """Unit ``name`` for a message, with its SI base units when they say
    more than the name (``km/h (SI m.s-1)``), or that nothing knows it."""
    if unit is None:
        return f"{name} (unknown to the modelDescription and to pint)"
    return name if unit.si == name else f"{name} (SI {unit.si})"


# pint's names of the units that count cycles (a cycle is 2 pi rad): Hz, rpm, rps, turn, cycle
_CYCLE_UNITS = ("hertz", "revolution", "turn", "cycle")


def _cycles(name: str) -> bool:
    """Whether the unit ``name`` counts cycles (pint's reading of it has a
    hertz, revolution, turn or cycle in it)."""
    if _base_units_only(name) is not None:
        return False
    quantity = _pint_quantity(name)
    return quantity is not None and any(c in u for u in quantity.units._units for c in _CYCLE_UNITS)


def radian_dropped(a: Unit, b: Unit) -> bool:
    """Whether ``a`` and ``b`` are one quantity but for the radian, which one
    of them leaves out (an FMU's ``<BaseUnit s="-1"/>`` for ``rad/s``, a
    units library's ``1/s``; docs/fmi-support.md, "Angles"): then they
    connect, by the units' own factors. A rad-less unit that counts cycles
    (``Hz``: 2 pi rad a cycle) is no such unit: a refusal says why (one
    whose name pint reads with its radian, ``rpm`` defined as ``1/min``, is
    read by its name); :class:`~cosim.errors.ConnectionCheckError`."""
    if a.exponents[:-1] != b.exponents[:-1] or (a.exponents[-1] == 0) == (b.exponents[-1] == 0):
        return False
    plain, angle = (a, b) if a.exponents[-1] == 0 else (b, a)
    if _cycles(plain.name):
        named = parse(plain.name)
        if named is None or named.exponents != angle.exponents:
            raise ConnectionCheckError(
                f"units {describe(a.name, a)} and {describe(b.name, b)} are not one quantity: {plain.name} counts "
                f"cycles, {angle.name} radians (2*pi rad a cycle)")
    return True


def _frequency_is_no_angular_rate(a: Unit, b: Unit) -> None:
    """Two rad-less rates of one quantity where one counts cycles (``Hz``)
    and the other's name reads as radians (an FMU's ``rad/s`` defined as
    ``<BaseUnit s="-1"/>``): refused as :func:`radian_dropped` refuses
    ``Hz`` against ``rad/s``. Only pure rates (s^k alone) are looked at: no
    other unit loads pint for this."""
    if a.exponents[-1] != 0 or any(e for b_, e in zip(BASE_UNITS, a.exponents) if b_ != "s"):
        return
    for plain, angle in ((a, b), (b, a)):
        named = parse(angle.name)
        if _cycles(plain.name) and named is not None and named.exponents[-1] != 0:
            radian_dropped(plain, named)  # raises, naming the cycles


def conversion(source: str | Unit, destination: str | Unit) -> tuple[float, float]:
    """``(factor, offset)`` turning a value in ``source`` into ``destination``:
    ``destination_value = factor * source_value + offset``, from both units'
    ``value_SI = factor * value + offset``; a unit given by name is read by
    :func:`parse`. A one-line :class:`~cosim.errors.ConnectionCheckError`
    naming both when they are not one quantity (or one is unknown)."""
    src = source if isinstance(source, Unit) else parse(source)
    dst = destination if isinstance(destination, Unit) else parse(destination)
    src_name = source.name if isinstance(source, Unit) else source
    dst_name = destination.name if isinstance(destination, Unit) else destination
    if src is None and dst is None and src_name == dst_name:
        return 1.0, 0.0  # one name, unknown to pint: nothing says the two differ
    if src is not None and dst is not None and src.same_quantity(dst) and src.name != dst.name:
        _frequency_is_no_angular_rate(src, dst)
    if src is not None and dst is not None and not src.same_quantity(dst) and radian_dropped(src, dst):
        src, dst = (parse(u.name) if u.exponents[-1] == 0 and _cycles(u.name) else u for u in (src, dst))
    if src is None or dst is None or not (src.same_quantity(dst) or radian_dropped(src, dst)):
        raise ConnectionCheckError(f"units {describe(src_name, src)} and {describe(dst_name, dst)} "
                                   f"are not one quantity")
    # v_dst = (f_src v + o_src - o_dst) / f_dst
    return src.factor / dst.factor, (src.offset - dst.offset) / dst.factor
