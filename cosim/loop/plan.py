"""The plan of a run: everything the master decides before the first step.

:func:`make_plan` turns the components' ports and the checked connections
into one typed :class:`Plan` (stated in ``docs/cosim.md``, "The plan"); the
master's two loops, the Python one and the compiled kernel
(:mod:`cosim.loop.kernel`), execute that same plan and decide nothing of their own:

* the **signal slots**: every value the loop holds lives in one float64 array;
  slot 0 is the time, then each FMU's block (the outputs in use, then the
  internal signals recorded or bounded: contiguous, so one get call writes
  them in place), each Python component's outputs (one slice assignment), the
  internal signals it publishes, and its unconnected inputs that hold a start
  value. A signal is a scalar: an FMI 3.0 array is its elements
  (``y[1]``, ..., :func:`cosim.component.element_ports`). Every type a double
  holds exactly (:data:`cosim.component.FLOAT_HELD`: Float32, the integers up
  to 32 bits, Boolean as 0/1, Enumeration) lives there too; Int64, UInt64,
  String and Binary live in the **object slots** (``object_slots``, an array
  of Python ``int``/``str``/``bytes``), laid out the same way (docs/cosim.md,
  "Signal types");
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
  slot but the time, with the envelope of the bounded ones);
* **the unit conversions** of the connections that carry one
  (:class:`~cosim.loop.connection.Connection` ``conversion``): per block, the
  inputs converted after they are gathered (``converted``: index, factor,
  offset; no other input is touched, so a run without conversions is the
  same bit for bit), and a slot of its own for a converted input that is
  recorded or bounded (``derived``), so it is recorded in its own unit.

Nothing here runs a component: the plan reads ports (``inputs``, ``outputs``,
``internals``) and, of an FMU, its ModelStructure (``feedthrough``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping, Sequence, Union

import numpy as np

from ..component import FLOAT_HELD, Port, element_ports
from ..names import base_variable, resolve, split_endpoint
from .connection import Connection
from ..errors import ConnectionCheckError

__all__ = ["Plan", "FmuBlock", "PythonBlock", "Transfer", "make_plan", "signal_port", "ORDERINGS", "PROFILED",
           "NO_COMPILED_LOOP"]

ORDERINGS = ("feedthrough", "exchange")
# the reasons a run takes the Python loop that are the run's, not the plan's (Plan.python_loop_for)
PROFILED = "a profiled run: its phases are timed in the Python loop"
NO_COMPILED_LOOP = "no C compiler (or COSIM_PYTHON_LOOP set): the compiled loop is not available"


@dataclass(frozen=True, eq=False)
class FmuBlock:
    """One FMU as the loops drive it.

    ``index`` is its place among the master's FMUs (the order they step in);
    ``inputs`` (names) are set in one call from the slots ``sources``;
    ``reads`` (its outputs in use, then its internal signals recorded or
    bounded) are read in one call into the slots ``block``; ``direct``: it
    is evaluated at t_n (feedthrough ordering: a used output depends directly
    on a connected input), else its inputs are set at the exchange.
    ``object_inputs``/``object_sources`` and ``object_reads``/``object_block``
    are the same for its signals held in the object slots (set and read by
    the component with its other inputs and outputs); ``converted``:
    ``(i, factor, offset)``, float-held input ``i`` receives ``factor *
    source + offset`` (a unit conversion of its connection).
    """

    index: int
    name: str
    inputs: tuple[str, ...]
    sources: np.ndarray
    reads: tuple[str, ...]
    block: slice
    direct: bool
    object_inputs: tuple[str, ...] = ()
    object_sources: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    object_reads: tuple[str, ...] = ()
    object_block: slice = field(default_factory=lambda: slice(0, 0))
    converted: tuple[tuple[int, float, float], ...] = ()


@dataclass(frozen=True, eq=False)
class PythonBlock:
    """One Python component's step at t_n: its inputs gathered from the slots
    ``sources`` (in port order), its outputs stored in ``block``, the internal
    signals it publishes (``published``: their indices in
    ``internal_values()`` and their slots, or ``None``); ``held``: exchange
    ordering, its outputs are held and become the values of t_{n+1}.
    ``typed``: a component with a port of another type than Float64, its
    inputs (in port order) and outputs as ``(in_objects, slot)`` pairs (the
    slot in the object slots when ``in_objects``), ``None`` for the others;
    ``converted`` as :class:`FmuBlock`'s, by index in ``sources``."""

    index: int
    name: str
    sources: np.ndarray
    block: slice
    published: tuple[np.ndarray, np.ndarray] | None
    held: bool
    typed: tuple[tuple[tuple[bool, int], ...], tuple[tuple[bool, int], ...]] | None = None
    converted: tuple[tuple[int, float, float], ...] = ()


@dataclass(frozen=True, eq=False)
class Transfer:
    """At t0 (exchange ordering): FMU ``index`` gets ``inputs`` from the
    slots ``sources`` (``converted`` as :class:`FmuBlock`'s), then its
    outputs are read again."""

    index: int
    inputs: tuple[str, ...]
    sources: np.ndarray
    object_inputs: tuple[str, ...] = ()
    object_sources: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    converted: tuple[tuple[int, float, float], ...] = ()


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
    computed) until the FMUs' outputs settle. ``python_loop``: why the
    compiled loop cannot run the plan (a Python component, recorded signals
    held as objects); empty when it can (:attr:`compiled`).
    ``python_calls``: FMU name -> why the compiled loop drives it through its Python
    calls (set, get and step: :meth:`~cosim.fmi.fmu.FmuComponent.kernel_entry`),
    each with its reason (:meth:`~cosim.fmi.fmu.FmuComponent.python_loop_reason`:
    a clock, signals of other types than Float64 scalars; a Model Exchange FMU is called
    through its system's C calls, :mod:`cosim.fmi.me_system`);
    the others it calls in C. ``conversion_of``:
    destination -> ``(factor, offset)`` of every converted connection;
    ``derived``: ``(slot, source slot, factor, offset)``, the converted
    inputs recorded or bounded, computed before each row is recorded.
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
    python_calls: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    initialization: tuple[Transfer, ...] = ()
    object_slots: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))
    object_start_values: tuple[tuple[int, Any], ...] = ()
    record_types: tuple[str, ...] = ()
    record_objects: tuple[tuple[int, int], ...] = ()
    """``record_types``: the type of each column; ``record_objects``: the
    columns held in the object slots, as ``(column, object slot)`` (their
    ``record_slots`` entry is 0, the time, overwritten by the recorder)."""
    conversion_of: Mapping[str, tuple[float, float]] = field(default_factory=lambda: MappingProxyType({}))
    derived: tuple[tuple[int, int, float, float], ...] = ()

    @property
    def compiled(self) -> bool:
        """The compiled kernel can run the plan: nothing in
        :attr:`python_loop`, the reasons the plan takes the Python loop
        instead (an FMU in :attr:`python_calls` does not stop it)."""
        return not self.python_loop

    def python_loop_for(self, *, profile: bool = False, compiled_available: bool = True) -> tuple[str, ...]:
        """Why a run of this plan takes the Python loop, the one decision of
        which loop runs (empty: the compiled loop): the plan's own reasons
        (:attr:`python_loop`), then a profiled run's (its phases are timed in
        Python) and a missing compiled loop's (no C compiler)."""
        reasons = self.python_loop + ((PROFILED,) if profile else ())
        return reasons if reasons or compiled_available else (NO_COMPILED_LOOP,)

    @property
    def exchanged(self) -> tuple[FmuBlock, ...]:
        """The FMUs whose inputs are set at the exchange (not at t_n)."""
        return tuple(b for b in self.fmus if (b.inputs or b.object_inputs) and not b.direct)


def _internals(comp) -> tuple[Port, ...]:
    return tuple(getattr(comp, "internals", ()))


def signal_port(components: Mapping[str, Any], signal: str) -> Port:
    """The port a signal (``component.variable``: an output, an internal
    signal, or an input, recorded as the value its source gives it; a whole
    array or an element ``variable[i]``) names; a one-line
    :class:`ConnectionCheckError` otherwise."""
    comp_name, var = split_endpoint(signal, components) or (signal.partition(".")[0], "")
    comp = components.get(comp_name)
    if comp is None:
        raise ConnectionCheckError(
            f"signal {signal!r}: unknown component {comp_name!r}; components are: "
            f"{', '.join(sorted(components))}")
    if not var:
        raise ConnectionCheckError(f"signal {signal!r}: expected 'component.variable'")
    internals = _internals(comp)
    ports_ = {p.name: p for p in comp.inputs + internals + comp.outputs}  # an output wins a name it shares
    shapes = {p.name: ports_[p.name].shape for p in comp.outputs + comp.inputs + internals}  # as listed
    kinds = "output, input or internal signal" if internals else "output or input"
    base, index = resolve(var, shapes, f"signal {signal!r}", comp_name, kinds)
    if index is None:
        return ports_[base]
    name = f"{base}[{','.join(map(str, index))}]"
    return next(e for e in element_ports((ports_[base],)) if e.name == name)


def scalar_signals(components: Mapping[str, Any], signals) -> list[str]:
    """``signals`` with every whole array named as its elements (``y`` ->
    ``y[1]``, ``y[2]``, ...), each checked (:func:`signal_port`)."""
    out = []
    for s in signals:
        port = signal_port(components, s)
        if port.shape:
            comp = split_endpoint(s, components)[0]
            out.extend(f"{comp}.{e.name}" for e in element_ports((port,)))
        else:
            out.append(s)
    return out


def every_output(components: Sequence) -> list[str]:
    """What a scenario without ``record.signals`` records: every output of
    every component (FMUs and Python components alike; not inputs nor
    internal signals), in the components' order, each in its ports' order
    (docs/cosim.md, "Recording")."""
    return [f"{c.name}.{p.name}" for c in components for p in c.outputs]


def _elements(comp, group: str) -> tuple[Port, ...]:
    return element_ports(tuple(getattr(comp, group, ())))


def _direct_fmus(fmus: Sequence, connections: Sequence[Connection], used: set[str], ordering: str) -> set[str]:
    """FMUs to evaluate at t_n (feedthrough ordering): those with a used
    output that depends directly on a connected input (ModelStructure)."""
    if ordering != "feedthrough":
        return set()
    direct = set()
    for fmu in fmus:
        connected = {c.destination.variable for c in connections if c.destination.component == fmu.name}
        connected = {base_variable(v, fmu.variables) for v in connected}  # an array's element: the array's
        if any(fmu.feedthrough.get(base_variable(p.name, fmu.variables), frozenset()) & connected
               for p in _elements(fmu, "outputs") if f"{fmu.name}.{p.name}" in used):
            direct.add(fmu.name)
    return direct


def _order(blocks: Sequence[str], components: Mapping[str, Any], connections: Sequence[Connection],
           direct: set[str], ordering: str) -> list[str]:
    """The blocks evaluated at t_n, in topological order of their
    connections. Only a connection whose source depends on its block's inputs
    at t_n orders two blocks, so a plant's states feeding a controller that
    feeds the plant is no loop; nor does one into an FMU input that none of
    its outputs depends on (ModelStructure): that input goes into the FMU's
    next state only, and is read as its source stands when the FMU is
    evaluated (an estimator storing the command its controller sends). In
    the exchange ordering nothing is ordered: every block reads the values of
    the previous exchange."""
    deps: dict[str, set[str]] = {name: set() for name in blocks}
    for c in connections:
        src, dst = c.source.component, c.destination.component
        if src not in deps or dst not in deps or ordering != "feedthrough":
            continue
        feeds = getattr(components[dst], "feedthrough", None)  # FMUs only: a Python block reads every input
        if feeds is not None and not any(base_variable(c.destination.variable, components[dst].variables) in d
                                         for d in feeds.values()):
            continue
        if src not in direct or components[src].feedthrough.get(base_variable(c.source.variable,
                                                                              components[src].variables)):
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
              record: Sequence[str], bounds: Mapping[str, tuple[float, float]],
              internal: frozenset[str] = frozenset()) -> Plan:
    """The :class:`Plan` of a run of ``fmus`` and ``python`` components joined
    by ``connections`` (already checked: arrays as their elements) in the
    ``ordering`` (one of :data:`ORDERINGS`, checked by the master), recording
    ``record`` and guarding ``bounds`` (signal -> (low, high); a whole array
    stands for its elements); one-line
    :class:`~cosim.errors.ConnectionCheckError` for what cannot run.
    ``internal``: the inputs (``fmu.input``) a Model Exchange system sets
    itself, inside its right-hand side (:mod:`cosim.fmi.me_system`): no FMU block
    sets them, though they order the blocks and are set at initialization."""
    components = {c.name: c for c in list(fmus) + list(python)}
    record = scalar_signals(components, record)
    bounds = {e: b for s, b in bounds.items() for e in scalar_signals(components, [s])}
    types = {f"{c.name}.{p.name}": p.type for c in components.values()
             for p in _elements(c, "outputs") + _elements(c, "inputs") + element_ports(_internals(c))}
    source_of = {str(c.destination): str(c.source) for c in connections}
    for s in record + list(bounds):
        signal_port(components, s)
        comp, var = split_endpoint(source_of.get(s, s), components)
        sources = _elements(components[comp], "outputs") + element_ports(_internals(components[comp]))
        if var not in {p.name for p in sources}:
            raise ConnectionCheckError(f"signal {s!r} is an input that nothing feeds; record its source")
    for s in bounds:
        if types[s] not in FLOAT_HELD:
            raise ConnectionCheckError(f"envelope of {s!r}: a {types[s]} signal; an envelope bounds numbers held "
                                       f"as doubles (Float32/64, Int8..UInt32, Boolean, Enumeration)")
    used = {str(c.source) for c in connections}
    used |= {source_of.get(s, s) for s in record + list(bounds)}

    slots: dict[str, int] = {"time": 0}
    objects: dict[str, int] = {}  # the object slots: Int64, UInt64, String, Binary
    reads: dict[str, tuple[str, ...]] = {}
    object_reads: dict[str, tuple[str, ...]] = {}
    blocks: dict[str, slice] = {}
    object_blocks: dict[str, slice] = {}

    def place(comp_name: str, names: Sequence[str]) -> None:
        """``names`` of ``comp_name`` in contiguous slots: the float-held ones
        in one block, the others in one block of the object slots."""
        floats = tuple(n for n in names if types[f"{comp_name}.{n}"] in FLOAT_HELD)
        others = tuple(n for n in names if types[f"{comp_name}.{n}"] not in FLOAT_HELD)
        first, first_object = len(slots), len(objects)
        slots.update((f"{comp_name}.{n}", first + i) for i, n in enumerate(floats))
        objects.update((f"{comp_name}.{n}", first_object + i) for i, n in enumerate(others))
        reads[comp_name], object_reads[comp_name] = floats, others
        blocks[comp_name], object_blocks[comp_name] = slice(first, len(slots)), slice(first_object, len(objects))

    for comp in fmus:  # used outputs, then used internals: one get call per type
        place(comp.name, [p.name for p in _elements(comp, "outputs") + element_ports(_internals(comp))
                          if f"{comp.name}.{p.name}" in used])
    for comp in python:  # every output: one slice assignment (per kind of slot)
        place(comp.name, [p.name for p in _elements(comp, "outputs")])
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
    start_values, object_start_values = [], []
    for comp in python:
        for p in _elements(comp, "inputs"):
            name = f"{comp.name}.{p.name}"
            if name not in source_of and p.start is not None:
                if p.type in FLOAT_HELD:
                    slots[name] = len(slots)
                    start_values.append((slots[name], float(p.start)))
                else:
                    objects[name] = len(objects)
                    object_start_values.append((objects[name], p.start))

    def split(ins: Sequence[Connection]) -> tuple[tuple[str, ...], np.ndarray, tuple[str, ...], np.ndarray]:
        """Connections into one FMU: the float-held inputs and their source
        slots, the object-held ones and their object slots."""
        floats = [c for c in ins if types[str(c.destination)] in FLOAT_HELD]
        others = [c for c in ins if types[str(c.destination)] not in FLOAT_HELD]
        return (tuple(c.destination.variable for c in floats), _indices(slots[str(c.source)] for c in floats),
                tuple(c.destination.variable for c in others), _indices(objects[str(c.source)] for c in others))

    # A converted input recorded or bounded: a slot of its own, its source's value converted
    conversion_of = {str(c.destination): c.conversion for c in connections if c.conversion is not None}
    derived = []
    for s in dict.fromkeys(record + list(bounds)):
        if s in conversion_of:
            slots[s] = len(slots)
            derived.append((slots[s], slots[source_of[s]], *conversion_of[s]))

    def resolved(s: str) -> str:
        return s if s in conversion_of and s in slots else source_of.get(s, s)

    def converted(names: Sequence[str]) -> tuple[tuple[int, float, float], ...]:
        return tuple((k, *conversion_of[n]) for k, n in enumerate(names) if n in conversion_of)

    direct = _direct_fmus(fmus, connections, used, ordering)
    fmu_blocks = []
    for i, fmu in enumerate(fmus):
        inputs, sources, obj_inputs, obj_sources = split(
            [c for c in connections if c.destination.component == fmu.name and str(c.destination) not in internal])
        fmu_blocks.append(FmuBlock(i, fmu.name, inputs, sources, reads[fmu.name], blocks[fmu.name],
                                   fmu.name in direct, obj_inputs, obj_sources, object_reads[fmu.name],
                                   object_blocks[fmu.name], converted([f"{fmu.name}.{n}" for n in inputs])))
    at_tn = _order([c.name for c in python] + [f.name for f in fmus if f.name in direct], components, connections,
                   direct, ordering)
    by_name: dict[str, Block] = {b.name: b for b in fmu_blocks}
    index = {c.name: j for j, c in enumerate(python)}

    def where(name: str) -> tuple[bool, int]:
        return (False, slots[name]) if name in slots else (True, objects[name])

    for comp in (components[n] for n in at_tn if n in index):
        elements = _elements(comp, "inputs")
        names = [f"{comp.name}.{p.name}" for p in elements]
        missing = [p.name for p, name in zip(elements, names)
                   if name not in source_of and name not in slots and name not in objects]
        if missing:
            raise ConnectionCheckError(f"inputs of {comp.name} not connected: {', '.join(missing)}")
        held = ordering == "exchange" and bool(comp.inputs)
        typed = None
        if any(p.type != "Float64" for p in elements + _elements(comp, "outputs")):
            if held:
                raise ConnectionCheckError(f"{comp.name}: a Python component with inputs and a port of another "
                                           f"type than Float64 runs in the feedthrough ordering only")
            typed = (tuple(where(source_of.get(n, n)) for n in names),
                     tuple(where(f"{comp.name}.{p.name}") for p in _elements(comp, "outputs")))
        by_name[comp.name] = PythonBlock(index[comp.name], comp.name,
                                         _indices(slots[source_of.get(n, n)] for n in names
                                                  if source_of.get(n, n) in slots), blocks[comp.name],
                                         published.get(comp.name), held, typed,
                                         converted([n for n in names if source_of.get(n, n) in slots]))

    fmu_names = {f.name for f in fmus}

    def transfers(keep) -> tuple[Transfer, ...]:
        out = []
        for b in fmu_blocks:
            inputs, sources, obj_inputs, obj_sources = split(
                [c for c in connections if c.destination.component == b.name and keep(c)])
            out.append(Transfer(b.index, inputs, sources, obj_inputs, obj_sources,
                                converted([f"{b.name}.{n}" for n in inputs])))
        return tuple(out)

    transfer = first_transfer = ()
    if ordering == "exchange":
        transfer = transfers(lambda c: True)
        first_transfer = transfers(lambda c: c.source.component in fmu_names)
    initialization = tuple(t for t in transfers(lambda c: c.source.component in fmu_names)
                           if t.inputs or t.object_inputs)

    columns = ("time",) + tuple(record)
    watched = tuple(s for s in slots if s != "time")
    sourced = [resolved(s) for s in columns]  # a converted input recorded: its own slot
    # what the compiled loop cannot do: Python components' steps, objects' rows; an FMU whose calls it cannot
    # make itself (it calls set, get and doStep of Float64 scalars) it makes through the FMU's Python calls
    python_loop = tuple(f"Python component {c.name}" for c in python if c.name in at_tn)
    held = [s for s in sourced if s in objects]
    if held:
        python_loop += (f"recorded signals held as objects ({', '.join(held)}): each row written by Python",)
    python_calls = {f.name: why for f, b in zip(fmus, fmu_blocks)
                    if (why := f.python_loop_reason(b.inputs + b.object_inputs + b.reads + b.object_reads))}
    return Plan(
        ordering=ordering, slots=MappingProxyType(slots), start_values=tuple(start_values),
        source_of=MappingProxyType(source_of),
        fmus=tuple(fmu_blocks), at_tn=tuple(by_name[n] for n in at_tn), transfer=transfer,
        first_transfer=first_transfer, record=columns,
        record_units=("s",) + tuple(signal_port(components, s).unit for s in record),
        record_slots=_indices(slots.get(s, 0) for s in sourced), watched=watched,
        watch_slots=_indices(slots[s] for s in watched), python_loop=python_loop,
        python_calls=MappingProxyType(python_calls), initialization=initialization,
        bounds=MappingProxyType({resolved(s): (float(b[0]), float(b[1])) for s, b in bounds.items()}),
        object_slots=MappingProxyType(objects), object_start_values=tuple(object_start_values),
        record_types=("Float64",) + tuple(types[source_of.get(s, s)] for s in columns[1:]),
        record_objects=tuple((k, objects[s]) for k, s in enumerate(sourced) if s in objects),
        conversion_of=MappingProxyType(conversion_of), derived=tuple(derived))
