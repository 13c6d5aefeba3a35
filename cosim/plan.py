"""The plan of a run: everything the master decides before the first step.

:func:`make_plan` turns the components' ports and the checked connections
into one typed :class:`Plan` (stated in ``docs/cosim.md``, "The plan"); the
master's two loops, the Python one and the compiled kernel
(:mod:`cosim.kernel`), execute that same plan and decide nothing of their own:

* the **signal slots**: every value the loop holds lives in one float64 array;
  slot 0 is the time, then each FMU's block (the outputs in use, then the
  internal signals recorded or bounded: contiguous, so one get call writes
  them in place), each Python component's outputs (one slice assignment), the
  internal signals it publishes, and its unconnected inputs that hold a start
  value;
* **the blocks evaluated at t_n**, in topological order of their connections
  (:class:`PythonBlock`; in the feedthrough ordering also the FMUs with
  direct feedthrough, :class:`FmuBlock` with ``direct``): a cycle among them
  is an algebraic loop, refused here;
* **every FMU's binding** (:class:`FmuBlock`): the inputs set in one call and
  the slots of their sources, the outputs and internals read in one call and
  their slots;
* **the held outputs** of the exchange ordering (``PythonBlock.held``): a
  Python component with inputs is sampled at t_n and its outputs become the
  values of t_{n+1}, as an FMU's do;
* **the initial transfers** of the exchange ordering (:class:`Transfer`);
* **what is recorded** (columns, units, slots) **and what is guarded** (every
  slot but the time, with the envelope of the bounded ones).

Nothing here runs a component: the plan reads ports (``inputs``, ``outputs``,
``internals``) and, of an FMU, its ModelStructure (``feedthrough``).
"""
from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping, Sequence, Union

import numpy as np

from .component import Port
from .connection import Connection
from .errors import ConnectionCheckError

__all__ = ["Plan", "FmuBlock", "PythonBlock", "Transfer", "make_plan", "signal_port", "ORDERINGS"]

ORDERINGS = ("feedthrough", "exchange")


@dataclass(frozen=True, eq=False)
class FmuBlock:
    """One FMU as the loops drive it.

    ``index`` is its place among the master's FMUs (the order they step in);
    ``inputs`` (names) are set in one call from the slots ``sources``;
    ``reads`` (its outputs in use, then its internal signals recorded or
    bounded) are read in one call into the slots ``block``; ``direct``: it
    is evaluated at t_n (feedthrough ordering: a used output depends directly
    on a connected input), else its inputs are set at the exchange.
    """

    index: int
    name: str
    inputs: tuple[str, ...]
    sources: np.ndarray
    reads: tuple[str, ...]
    block: slice
    direct: bool


@dataclass(frozen=True, eq=False)
class PythonBlock:
    """One Python component's step at t_n: its inputs gathered from the slots
    ``sources`` (in port order), its outputs stored in ``block``, the internal
    signals it publishes (``published``: their indices in
    ``internal_values()`` and their slots, or ``None``); ``held``: exchange
    ordering, its outputs are held and become the values of t_{n+1}."""

    index: int
    name: str
    sources: np.ndarray
    block: slice
    published: tuple[np.ndarray, np.ndarray] | None
    held: bool


@dataclass(frozen=True, eq=False)
class Transfer:
    """At t0 (exchange ordering): FMU ``index`` gets ``inputs`` from the
    slots ``sources``, then its outputs are read again."""

    index: int
    inputs: tuple[str, ...]
    sources: np.ndarray


Block = Union[FmuBlock, PythonBlock]


@dataclass(frozen=True, eq=False)
class Plan:
    """What a run executes (module docstring).

    ``transfer`` is the exchange ordering's initial transfer (every
    connection into an FMU), made once per FMU so a chain of direct
    feedthroughs is consistent at t0; ``first_transfer`` the part of it
    whose sources are FMUs, made before the Python components' first step
    (their outputs do not exist yet). Both are empty in the feedthrough
    ordering. ``initialization``: every connection from an FMU into an FMU,
    per destination FMU, made in Initialization Mode (FMI 2.0 §3.2.3 / FMI
    3.0 §2.3.4: connected inputs set before the initial unknowns are
    computed) until the FMUs' outputs settle. ``python_loop``: why the compiled loop cannot run the plan,
    one reason per component (a Python component, an FMU whose
    :meth:`~cosim.fmu_component.FmuComponent.python_loop_reason` names
    one); empty when it can (:attr:`compiled`).
    """

    ordering: str
    slots: Mapping[str, int]
    start_values: tuple[tuple[int, float], ...]
    source_of: Mapping[str, str]
    fmus: tuple[FmuBlock, ...]
    at_tn: tuple[Block, ...]
    transfer: tuple[Transfer, ...]
    first_transfer: tuple[Transfer, ...]
    record: tuple[str, ...]
    record_units: tuple[str | None, ...]
    record_slots: np.ndarray
    watched: tuple[str, ...]
    watch_slots: np.ndarray
    bounds: Mapping[str, tuple[float, float]]

    python_loop: tuple[str, ...] = ()
    initialization: tuple[Transfer, ...] = ()

    @property
    def fmus_only(self) -> bool:
        """Every block at t_n is an FMU (no Python component)."""
        return all(isinstance(b, FmuBlock) for b in self.at_tn)

    @property
    def compiled(self) -> bool:
        """The compiled kernel can run the plan: nothing in
        :attr:`python_loop`, the reasons (one per component, naming it) the
        plan takes the Python loop instead."""
        return not self.python_loop

    @property
    def exchanged(self) -> tuple[FmuBlock, ...]:
        """The FMUs whose inputs are set at the exchange (not at t_n)."""
        return tuple(b for b in self.fmus if b.inputs and not b.direct)


def _internals(comp) -> tuple[Port, ...]:
    return tuple(getattr(comp, "internals", ()))


def signal_port(components: Mapping[str, Any], signal: str) -> Port:
    """The port a signal (``component.variable``: an output, an internal
    signal, or an input, recorded as the value its source gives it) names;
    a one-line :class:`ConnectionCheckError` otherwise."""
    comp_name, _, var = signal.partition(".")
    comp = components.get(comp_name)
    if comp is None:
        raise ConnectionCheckError(
            f"signal {signal!r}: unknown component {comp_name!r}; components are: "
            f"{', '.join(sorted(components))}")
    if not var:
        raise ConnectionCheckError(f"signal {signal!r}: expected 'component.variable'")
    internals = _internals(comp)
    for port in comp.outputs + internals + comp.inputs:
        if port.name == var:
            return port
    known = ", ".join(p.name for p in comp.outputs + comp.inputs + internals)
    kinds = "output, input or internal signal" if internals else "output or input"
    raise ConnectionCheckError(f"signal {signal!r}: {comp_name} has no {kinds} {var!r}; it has: {known}")


def _direct_fmus(fmus: Sequence, connections: Sequence[Connection], used: set[str], ordering: str) -> set[str]:
    """FMUs to evaluate at t_n (feedthrough ordering): those with a used
    output that depends directly on a connected input (ModelStructure)."""
    if ordering != "feedthrough":
        return set()
    direct = set()
    for fmu in fmus:
        connected = {c.destination.variable for c in connections if c.destination.component == fmu.name}
        if any(fmu.feedthrough.get(p.name, frozenset()) & connected
               for p in fmu.outputs if f"{fmu.name}.{p.name}" in used):
            direct.add(fmu.name)
    return direct


def _order(blocks: Sequence[str], components: Mapping[str, Any], connections: Sequence[Connection],
           direct: set[str], ordering: str) -> list[str]:
    """The blocks evaluated at t_n, in topological order of their
    connections. Only a connection whose source depends on its block's inputs
    at t_n orders two blocks, so a plant's states feeding a controller that
    feeds the plant is no loop. In the exchange ordering nothing is ordered:
    every block reads the values of the previous exchange."""
    deps: dict[str, set[str]] = {name: set() for name in blocks}
    for c in connections:
        src, dst = c.source.component, c.destination.component
        if src not in deps or dst not in deps or ordering != "feedthrough":
            continue
        if src not in direct or components[src].feedthrough.get(c.source.variable):
            deps[dst].add(src)
    order: list[str] = []
    state: dict[str, int] = {}

    def visit(name: str, path: list[str]) -> None:
        if state.get(name) == 2:
            return
        if state.get(name) == 1:
            cycle = path[path.index(name):] + [name]
            raise ConnectionCheckError(
                f"algebraic loop: {' -> '.join(cycle)}; each block needs the one before it at the same "
                f"instant: break it with a delay, or use the 'exchange' ordering")
        state[name] = 1
        for d in sorted(deps[name]):
            visit(d, path + [name])
        state[name] = 2
        order.append(name)

    for name in blocks:  # declared order breaks ties
        visit(name, [])
    return order


def _indices(values) -> np.ndarray:
    """Signal slots (or other indices) as a read-only array: a plan is decided once."""
    array = np.array(list(values), dtype=np.intp)
    array.flags.writeable = False
    return array


def make_plan(fmus: Sequence, python: Sequence, connections: Sequence[Connection], ordering: str,
              record: Sequence[str], bounds: Mapping[str, tuple[float, float]]) -> Plan:
    """The :class:`Plan` of a run of ``fmus`` and ``python`` components joined
    by ``connections`` (already checked) in the ``ordering`` (one of
    :data:`ORDERINGS`, checked by the master), recording ``record`` and guarding
    ``bounds`` (signal -> (low, high)); one-line
    :class:`~cosim.errors.ConnectionCheckError` for what cannot run."""
    components = {c.name: c for c in list(fmus) + list(python)}
    record = list(record)
    source_of = {str(c.destination): str(c.source) for c in connections}
    for s in record + list(bounds):
        signal_port(components, s)
        comp, _, var = source_of.get(s, s).partition(".")
        if var not in {p.name for p in components[comp].outputs + _internals(components[comp])}:
            raise ConnectionCheckError(f"signal {s!r} is an input that nothing feeds; record its source")
    used = {str(c.source) for c in connections}
    used |= {source_of.get(s, s) for s in record + list(bounds)}

    slots: dict[str, int] = {"time": 0}
    reads: dict[str, tuple[str, ...]] = {}
    blocks: dict[str, slice] = {}
    for comp in fmus:  # used outputs, then used internals: one get call
        names = tuple(p.name for p in comp.outputs + _internals(comp) if f"{comp.name}.{p.name}" in used)
        first = len(slots)
        slots.update((f"{comp.name}.{n}", first + i) for i, n in enumerate(names))
        reads[comp.name], blocks[comp.name] = names, slice(first, len(slots))
    for comp in python:  # every output: one slice assignment
        first = len(slots)
        slots.update((f"{comp.name}.{p.name}", first + i) for i, p in enumerate(comp.outputs))
        blocks[comp.name] = slice(first, len(slots))
    published: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for comp in python:
        picked = [(i, f"{comp.name}.{p.name}") for i, p in enumerate(comp.internals)
                  if f"{comp.name}.{p.name}" in used]
        for _, name in picked:
            slots[name] = len(slots)
        if picked:
            published[comp.name] = (_indices(i for i, _ in picked), _indices(slots[n] for _, n in picked))
    # Unconnected Python inputs that declare a start value: one slot each,
    # written once before the run and by nothing after, so they hold it.
    start_values = []
    for comp in python:
        for p in comp.inputs:
            name = f"{comp.name}.{p.name}"
            if name not in source_of and p.start is not None:
                slots[name] = len(slots)
                start_values.append((slots[name], float(p.start)))

    direct = _direct_fmus(fmus, connections, used, ordering)
    fmu_blocks = []
    for i, fmu in enumerate(fmus):
        ins = [c for c in connections if c.destination.component == fmu.name]
        fmu_blocks.append(FmuBlock(i, fmu.name, tuple(c.destination.variable for c in ins),
                                   _indices(slots[str(c.source)] for c in ins), reads[fmu.name], blocks[fmu.name],
                                   fmu.name in direct))
    at_tn = _order([c.name for c in python] + [f.name for f in fmus if f.name in direct], components, connections,
                   direct, ordering)
    by_name: dict[str, Block] = {b.name: b for b in fmu_blocks}
    index = {c.name: j for j, c in enumerate(python)}
    for comp in (components[n] for n in at_tn if n in index):
        names = [f"{comp.name}.{p.name}" for p in comp.inputs]
        missing = [p.name for p, name in zip(comp.inputs, names) if name not in source_of and name not in slots]
        if missing:
            raise ConnectionCheckError(f"inputs of {comp.name} not connected: {', '.join(missing)}")
        by_name[comp.name] = PythonBlock(index[comp.name], comp.name,
                                         _indices(slots[source_of.get(n, n)] for n in names), blocks[comp.name],
                                         published.get(comp.name), ordering == "exchange" and bool(comp.inputs))

    fmu_names = {f.name for f in fmus}

    def transfers(keep) -> tuple[Transfer, ...]:
        out = []
        for b in fmu_blocks:
            ins = [c for c in connections if c.destination.component == b.name and keep(c)]
            out.append(Transfer(b.index, tuple(c.destination.variable for c in ins),
                                _indices(slots[str(c.source)] for c in ins)))
        return tuple(out)

    transfer = first_transfer = ()
    if ordering == "exchange":
        transfer = transfers(lambda c: True)
        first_transfer = transfers(lambda c: c.source.component in fmu_names)
    initialization = tuple(t for t in transfers(lambda c: c.source.component in fmu_names) if t.inputs)

    # what the compiled loop cannot do (it makes set, get and doStep calls of Float64 values only)
    python_loop = tuple(f"Python component {c.name}" for c in python if c.name in at_tn)
    python_loop += tuple(f"{f.name}: {why}" for f in fmus if (why := f.python_loop_reason()) is not None)
    columns = ("time",) + tuple(record)
    watched = tuple(s for s in slots if s != "time")
    return Plan(
        ordering=ordering, slots=MappingProxyType(slots), start_values=tuple(start_values),
        source_of=MappingProxyType(source_of),
        fmus=tuple(fmu_blocks), at_tn=tuple(by_name[n] for n in at_tn), transfer=transfer,
        first_transfer=first_transfer, record=columns,
        record_units=("s",) + tuple(signal_port(components, s).unit for s in record),
        record_slots=_indices(slots[source_of.get(s, s)] for s in columns), watched=watched,
        watch_slots=_indices(slots[s] for s in watched), python_loop=python_loop,
        initialization=initialization,
        bounds=MappingProxyType({source_of.get(s, s): (float(b[0]), float(b[1])) for s, b in bounds.items()}))
