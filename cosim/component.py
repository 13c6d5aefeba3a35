"""The contract of a Python component of the co-simulation.

A component has named, typed, unit-carrying input and output ports. The
master calls, once per run, ``set_parameters`` (optional run-level
overrides), then ``start(t0, h, n_steps, seed)``, then at every
communication point ``t_n = t0 + n h`` (n = 0 .. n_steps) ``step(n, t_n, u)``
with the current input values ``u`` (a float64 array in the order of
``inputs``); ``step`` returns the outputs at ``t_n`` (a float64 array in the
order of ``outputs``; it may be the same preallocated array every call).

Python components are sampled-data blocks with direct feedthrough: their
outputs at ``t_n`` may depend on their inputs at ``t_n`` (a controller's
do). The master evaluates them in an order that respects their
connections (see ``docs/cosim.md``).

Two optional parts of the contract:

* ``input_buffers()`` -- arrays, in port order, the component reads its
  inputs from; the master then gathers the inputs straight into them (no
  copy in ``step``, which then receives ``u = None``);
* ``internals`` and ``internal_values()`` -- internal signals (learned
  parameters, filter states) the component publishes: they can be recorded
  and bounded like outputs, by ``component.name``, but not connected. The
  master reads them after each step only when some are recorded or bounded.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

if TYPE_CHECKING:
    from .fmi.units import Unit

__all__ = ["Port", "PythonComponent", "ports", "TYPES", "FLOAT_HELD", "element_ports", "element_of", "typed_value"]


def _numpy_floating(value: Any) -> bool:
    """Whether ``value`` is a numpy floating-point scalar (numpy is not imported for it: a value of numpy's
    means numpy is loaded already; registering components, at fnn-cosim's start, loads no numpy)."""
    np = sys.modules.get("numpy")
    return np is not None and isinstance(value, np.floating)

# The signal types (docs/cosim.md, "Signal types"): FMI 3.0's names (FMI 3.0
# section 2.4.7.4); FMI 2.0's Real, Integer, Boolean, String and Enumeration
# are read as Float64, Int32 (an fmi2Integer is a 32-bit int), Boolean,
# String, Enumeration. A Clock is no signal.
TYPES = ("Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
         "Boolean", "String", "Binary", "Enumeration")
# Held in the master's float64 signal array: every value of these types is a
# double exactly (Float32 widens exactly; the integers have at most 32 bits;
# an Enumeration's values are its declared items, refused beyond 2^53 when
# read). Int64 and UInt64 (beyond 2^53 a double rounds), String and Binary are
# held as Python objects (int, str, bytes) in the master's object array.
FLOAT_HELD = frozenset(TYPES) - {"Int64", "UInt64", "String", "Binary"}
_INT_RANGE = {"Int8": (-2 ** 7, 2 ** 7 - 1), "UInt8": (0, 2 ** 8 - 1), "Int16": (-2 ** 15, 2 ** 15 - 1),
              "UInt16": (0, 2 ** 16 - 1), "Int32": (-2 ** 31, 2 ** 31 - 1), "UInt32": (0, 2 ** 32 - 1),
              "Int64": (-2 ** 63, 2 ** 63 - 1), "UInt64": (0, 2 ** 64 - 1), "Enumeration": (-2 ** 53, 2 ** 53)}


@dataclass(frozen=True)
class Port:
    """One input or output of a component: a scalar, or an array of ``shape``.

    ``type`` is one of :data:`TYPES` (the FMI 3.0 names: ``Float64``,
    ``Int32``, ``Boolean``, ...); FMI 2.0 ``Real`` is read as ``Float64``,
    ``Integer`` as ``Int32``. ``shape`` is ``()`` for a scalar, else the
    sizes of an FMI 3.0 array variable (row-major, FMI 3.0 section 2.4.6.2):
    its elements are signals named ``name[i]`` (``name[i,j]``), 1-based as
    FMI and Modelica count (:func:`element_ports`). ``unit`` is ``None`` when the
    component declares none (the unit check is then skipped). An input with
    a ``start`` value may be left unconnected: it then holds that value, as
    an FMU's input holds its start value; an input without one must be
    connected. ``unit_definition`` is the meaning of ``unit`` the
    component's own description gives (an FMU's ``UnitDefinitions``, read by
    :mod:`cosim.fmi.units`), ``None`` when it gives none: the name is then read
    by pint.
    """

    name: str
    unit: str | None = None
    type: str = "Float64"
    description: str = ""
    start: float | tuple | None = None  # an array's: one value per element, row-major
    shape: tuple[int, ...] = ()
    unit_definition: "Unit | None" = None  # the unit's definition in the FMU's modelDescription

    @property
    def size(self) -> int:
        """Number of scalar signals (1 for a scalar)."""
        n = 1
        for k in self.shape:
            n *= k
        return n


def _index_names(shape: tuple[int, ...]) -> list[str]:
    names = [""]
    for k in shape:
        names = [f"{head},{i}" if head else str(i) for head in names for i in range(1, k + 1)]
    return names


def element_ports(ports_: tuple[Port, ...]) -> tuple[Port, ...]:
    """The scalar signals of ``ports_``: a scalar port itself, an array port's
    elements in row-major order, named ``name[i]`` or ``name[i,j]`` (1-based)."""
    out = []
    for p in ports_:
        if not p.shape:
            out.append(p)
            continue
        starts = p.start if isinstance(p.start, (tuple, list)) else None
        for k, index in enumerate(_index_names(p.shape)):
            start = starts[k] if starts is not None and k < len(starts) else None
            out.append(Port(f"{p.name}[{index}]", p.unit, p.type, p.description, start,
                            unit_definition=p.unit_definition))
    return tuple(out)


def element_of(name: str) -> tuple[str, tuple[int, ...] | None]:
    """``"y[2]"`` -> ``("y", (2,))``, ``"A[1,2]"`` -> ``("A", (1, 2))``; a name
    without an index -> ``(name, None)`` (:func:`cosim.names.array_element`;
    whether ``y[2]`` is a variable of its own is :func:`cosim.names.resolve`'s
    to say)."""
    from .names import array_element

    return array_element(name) or (name, None)


def typed_value(type_: str, value, what: str):
    """``value`` as a value of the signal type ``type_`` (a float for the
    Float types, an int for the integers and Enumeration, a bool, a str,
    bytes), or ``ValueError`` naming ``what``: an integer out of its type's
    range, a fraction where an integer is due, are refused, never rounded."""
    if type_ in ("Float64", "Float32"):
        try:
            if isinstance(value, bytes):
                raise ValueError
            return float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{what} = {value!r}: expected a number ({type_})") from None
    if type_ == "Boolean":
        if isinstance(value, str):
            text = value.strip().lower()
            if text in ("true", "1"):
                return True
            if text in ("false", "0"):
                return False
            raise ValueError(f"{what} = {value!r}: expected true/false or 1/0 (Boolean)")
        if value in (0, 1):  # 0, 1, 0.0, 1.0, False, True
            return bool(value)
        raise ValueError(f"{what} = {value!r}: expected true/false or 1/0 (Boolean)")
    if type_ == "String":
        if not isinstance(value, str):
            raise ValueError(f"{what} = {value!r}: expected a string (String)")
        return value
    if type_ == "Binary":
        if isinstance(value, str):
            try:
                return bytes.fromhex(value)
            except ValueError:
                raise ValueError(f"{what} = {value!r}: expected hexadecimal digits (Binary)") from None
        if not isinstance(value, (bytes, bytearray)):
            raise ValueError(f"{what} = {value!r}: expected bytes or hexadecimal digits (Binary)")
        return bytes(value)
    low, high = _INT_RANGE[type_]
    if isinstance(value, str):
        try:
            number = int(value.strip())
        except ValueError:
            raise ValueError(f"{what} = {value!r}: expected a whole number ({type_})") from None
    elif isinstance(value, float) or _numpy_floating(value):
        if not float(value).is_integer():
            raise ValueError(f"{what} = {value!r}: expected a whole number ({type_})")
        number = int(value)
    else:
        number = int(value)
    if not low <= number <= high:
        raise ValueError(f"{what} = {value!r}: outside the range [{low}, {high}] of {type_}")
    return number


def ports(*spec: tuple[str, str | None] | str) -> tuple[Port, ...]:
    """Shorthand: ``ports(("x", "m"), ("u", "m/s"))`` -> Float64 ports."""
    out = []
    for item in spec:
        name, unit = (item, None) if isinstance(item, str) else item
        out.append(Port(name, unit))
    return tuple(out)


class PythonComponent:
    """Base class of the Python components (controllers, references, sensors, ...).

    Subclasses set ``inputs`` and ``outputs`` (tuples of :class:`Port`) and
    implement :meth:`step`; they may override :meth:`start`,
    :meth:`set_parameters`, :meth:`input_buffers`, and publish
    ``internals`` with :meth:`internal_values`.
    """

    inputs: tuple[Port, ...] = ()
    outputs: tuple[Port, ...] = ()
    internals: tuple[Port, ...] = ()

    def __init__(self, name: str):
        self.name = name

    def set_parameters(self, values: Mapping[str, Any]) -> None:
        """Apply run-level parameter overrides; refuse unknown names."""
        if values:
            raise KeyError(f"component {self.name!r} takes no parameters, got {sorted(values)}")

    def start(self, t0: float, h: float, n_steps: int, seed: int) -> None:
        """Prepare a run of ``n_steps`` steps of ``h`` seconds from ``t0``."""

    def input_buffers(self) -> list[np.ndarray] | None:
        """Arrays (float64, in port order, sizes adding up to ``len(inputs)``)
        the master writes the inputs into before each step, or ``None`` (the
        default): then ``step`` receives them as ``u``. Asked once per run,
        after :meth:`start`."""
        return None

    def internal_values(self) -> np.ndarray:
        """The current values of ``internals``, in their order (after the
        step just taken)."""
        import numpy as np

        return np.zeros(0)

    def step(self, n: int, t: float, u: np.ndarray | None) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError
