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

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

if TYPE_CHECKING:
    from .units import Unit

__all__ = ["Port", "PythonComponent", "ports"]


@dataclass(frozen=True)
class Port:
    """One scalar input or output of a component.

    ``type`` follows the FMI 3.0 names (``Float64``, ``Int32``, ``Boolean``);
    FMI 2.0 ``Real`` is read as ``Float64``. ``unit`` is ``None`` when the
    component declares none (the unit check is then skipped). An input with
    a ``start`` value may be left unconnected: it then holds that value, as
    an FMU's input holds its start value; an input without one must be
    connected. ``unit_definition`` is the meaning of ``unit`` the
    component's own description gives (an FMU's ``UnitDefinitions``, read by
    :mod:`cosim.units`), ``None`` when it gives none: the name is then read
    by pint.
    """

    name: str
    unit: str | None = None
    type: str = "Float64"
    description: str = ""
    start: float | None = None
    unit_definition: "Unit | None" = None


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
        return np.zeros(0)

    def step(self, n: int, t: float, u: np.ndarray | None) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError
