"""The fixed-step co-simulation master.

Algorithm (stated in full in ``docs/cosim.md``): communication points
``t_n = t0 + n h`` from the step counter n = 0 .. N. At each ``t_n``:

1. every FMU output is known at ``t_n`` (read after initialization, then after
   each step);
2. the Python components are evaluated in topological order of their
   connections (a sampled-data block may have direct feedthrough: a
   controller's command at ``t_n`` may depend on the plant state at ``t_n``),
   and so are the FMUs with direct feedthrough (feedthrough ordering); a
   cycle among them is refused before the first step;
3. the recorded signals at ``t_n`` are stored (and streamed in blocks), and
   the guard checks every signal (finite, inside its envelope);
4. every FMU gets all its connected inputs, taken at ``t_n``, in one call;
5. every FMU steps from ``t_n`` to ``t_{n+1}`` (Jacobi among FMUs: they only
   see each other's values at ``t_n``, held constant over the step), and its
   outputs (and internal signals in use) at ``t_{n+1}`` are read in one call.

Everything above is decided once, before the first step, as one typed plan
(:mod:`cosim.loop.plan`: the slots of the one float64 signal array, the blocks at
``t_n``, each FMU's bound inputs and reads, the held outputs and initial
transfers of the exchange ordering, what is recorded and guarded). The
master binds it and runs it in one of two loops that execute the same plan:
its Python loop, or, when the plan evaluates only FMUs, the compiled loop of
:mod:`cosim.loop.kernel`; both give the same results bit for bit.

A run can be frozen at chosen points (``snapshots``: every FMU's state and
every signal, :class:`Snapshot`) and resumed from one (``restore``);
``docs/cosim.md``, "Snapshots and resuming a run".

The loop holds no clock: ``run(..., profile=True)`` wraps each phase (the FMU
exchange, each Python component, recording, the guard) in a timer before the
loop starts (in the Python loop), and the result's ``phase_times`` says where
the time went.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..component import PythonComponent, typed_value
from .connection import Connection, check_connections, parse_connections
from ..errors import ConnectionCheckError, CosimError, DivergenceError, FmuCallError, ScenarioError, SimulationTerminated
from ..time_grid import communication_point, seed_error, whole_steps
from ..fmi.fmu import FmuComponent
from ..fmi.lifecycle import stream_seed
from .guard import Guard
from ..names import split_endpoint
from .plan import ORDERINGS, FmuBlock, PythonBlock, every_output, make_plan
from .recorder import Recorder

__all__ = ["Master", "RunResult", "Snapshot", "ORDERINGS"]


@dataclass(frozen=True, eq=False)
class Snapshot:
    """The run's FMUs frozen at a communication point ``t_n`` (``time``,
    step ``n``): every FMU has stepped to ``t_n``, and everything at ``t_n``
    is evaluated (the feedthrough FMUs' inputs set and outputs read, the
    Python components stepped), before the step to ``t_{n+1}``.

    ``states``: FMU name -> its serialized FMU state (getFMUState +
    serializeFMUState); ``parameters``: FMU name -> the values it was
    started with (base, scenario, seed, run); ``outputs``: ``component.name``
    -> value at ``t_n`` of every signal the master holds (the outputs in
    use, published internals; an Int64, UInt64, String or Binary signal as
    its Python value); ``inputs``: the same for every connected
    input. Python components are not part of a snapshot: a run resumed from
    it (``Master.run(..., t0=time, restore=snapshot.states)``) starts them
    afresh."""

    time: float
    step: int
    states: dict[str, bytes]
    parameters: dict[str, dict[str, Any]]
    outputs: dict[str, Any]
    inputs: dict[str, Any]

    def inputs_of(self, component: str) -> dict[str, float]:
        """The values at ``t_n`` of ``component``'s inputs in :attr:`inputs`, by variable name."""
        prefix = component + "."
        return {k[len(prefix):]: v for k, v in self.inputs.items() if k.startswith(prefix)}


@dataclass
class RunResult:
    """What a run produced: the recorded rows (``data[:, 0]`` is time), the
    status (``ok``, ``diverged``, ``failed``), the error message, the wall
    time, and (for a profiled run) its split into phases (s): ``fmu`` (the
    FMU exchange), ``python:<name>`` (each Python component), ``record``,
    ``guard``."""

    columns: tuple[str, ...]
    units: tuple[str | None, ...]
    data: np.ndarray
    status: str
    error: str | None
    wall_time: float
    n_steps: int
    step: float
    phase_times: dict[str, float] = field(default_factory=dict)
    csv_path: Path | None = None
    seed: int = 0
    parameters: dict[str, Any] = field(default_factory=dict)
    snapshots: list[Snapshot] = field(default_factory=list)
    types: tuple[str, ...] = ()
    objects: dict[str, np.ndarray] = field(default_factory=dict)
    python_loop: tuple[str, ...] = ()
    terminated: str | None = None
    python_calls: dict[str, str] = field(default_factory=dict)
    rows: int = 0
    stride: int = 1
    span: tuple[float, float] | None = None
    observers: tuple = ()
    """``rows``: the rows recorded (``data`` holds those kept: all of them,
    the default; none; or every ``stride``-th and the last, as
    ``Master.run(keep=...)`` asked); ``span``: the first and the last row's
    time (``None`` without rows); ``observers``: those the rows streamed to
    (``Master.run(observers=...)``); ``types``: each column's signal type (docs/cosim.md, "Signal types");
    ``objects``: the columns of Int64, UInt64, String and Binary signals, as
    object arrays of ``int``, ``str`` and ``bytes`` (their ``data`` column is
    NaN); ``python_loop``: why this run took the Python loop
    (:meth:`cosim.loop.plan.Plan.python_loop_for`: the plan's reasons, a profiled run, no compiled loop; empty when it ran compiled);
    ``python_calls``: the FMUs it drives through their Python calls
    (:attr:`cosim.loop.plan.Plan.python_calls`), with the reason;
    ``terminated``: an FMU asked to end the simulation
    (:class:`~cosim.errors.SimulationTerminated`): the run ended early, at
    its last row, status ok; the message says which FMU and when."""

    def __post_init__(self) -> None:
        if not self.rows and len(self.data):  # built with every row (libcosim's run, cosim.ssp.archive)
            self.rows, self.span = len(self.data), (float(self.data[0, 0]), float(self.data[-1, 0]))

    @property
    def time(self) -> np.ndarray:
        return self.data[:, 0]

    def __getitem__(self, name: str) -> np.ndarray:
        """A recorded column: float64 values, or the objects of an Int64,
        UInt64, String or Binary column (:attr:`objects`)."""
        if name in self.objects:
            return self.objects[name]
        try:
            return self.data[:, self.columns.index(name)]
        except ValueError:
            raise KeyError(f"signal {name!r} was not recorded; recorded: {', '.join(self.columns)}") from None


class Master:
    """A fixed-step co-simulation of FMUs and Python components.

    Parameters
    ----------
    fmus : FMU components, with their base parameter values (``{name: {...}}``
        in ``fmu_parameters``).
    components : Python components (:class:`~cosim.component.PythonComponent`).
    connections : connection strings or :class:`~cosim.loop.connection.Connection`.
    step : communication step h (s).
    record : signals (``component.variable``) to record, after ``time``;
        ``None``: every output of every component (:func:`cosim.loop.plan.every_output`).
    bounds : ``signal -> (low, high)``, the envelope (inclusive); every
        signal the master holds (the FMU outputs in use, every Python output,
        the internal signals recorded) is also checked to be finite.
    fmu_parameters : ``{fmu name: {parameter: value}}``, the base values set
        at every run's start (a run's ``parameters`` override them).
    ordering : ``"feedthrough"`` (default: the blocks with direct
        feedthrough evaluated at ``t_n``) or ``"exchange"`` (every block sees
        the others' values of the previous step, as Jacobi masters do);
        :data:`cosim.loop.plan.ORDERINGS`, docs/cosim.md.
    coupling : ``"tight"`` (default: connected Model Exchange FMUs are
        integrated as one system, their connections evaluated inside its
        right-hand side) or ``"loose"`` (each alone, its inputs held over a
        step); :mod:`cosim.fmi.me_system`, docs/cosim.md "Model Exchange".
    """

    def __init__(self, fmus: Sequence[FmuComponent], components: Sequence[PythonComponent],
                 connections: Sequence[str | Connection], step: float, record: Sequence[str] | None = (),
                 bounds: Mapping[str, tuple[float, float]] | None = None,
                 fmu_parameters: Mapping[str, Mapping[str, float]] | None = None, ordering: str = "feedthrough",
                 coupling: str = "tight"):
        if not step > 0:
            raise ValueError(f"step = {step!r} s must be positive")
        if ordering not in ORDERINGS:
            raise ValueError(f"ordering = {ordering!r}: expected one of {', '.join(ORDERINGS)}")
        self.ordering = ordering
        self.step = float(step)
        self.fmus = list(fmus)
        self.python = list(components)
        names = [c.name for c in self.fmus + self.python]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ConnectionCheckError(f"component names must be unique; repeated: {sorted(dup)}")
        self.components: dict[str, Any] = {c.name: c for c in self.fmus + self.python}
        self.fmu_parameters = {k: dict(v) for k, v in (fmu_parameters or {}).items()}
        for key in self.fmu_parameters:
            if key not in self.components or key not in {f.name for f in self.fmus}:
                raise ConnectionCheckError(f"parameters given for unknown FMU {key!r}")
        conns = [c for c in connections if isinstance(c, Connection)]
        conns += parse_connections([c for c in connections if not isinstance(c, Connection)], self.components)
        self.connections = check_connections(conns, self.components)
        self.coupling = coupling
        self.me_systems = []  # the Model Exchange FMUs, each in the system that integrates it (cosim.fmi.me_system)
        self._kernel_kept = None  # the compiled loop's structure and what it points into (_kernel_run)
        if any(f.model_exchange for f in self.fmus):
            from ..fmi.me_system import systems

            self.me_systems = systems(self.fmus, self.connections, coupling)
        self.bounds = dict(bounds or {})
        self._plan(every_output(self.fmus + self.python) if record is None else list(record))

    # ---- planning -----------------------------------------------------------

    def _plan(self, record: list[str]) -> None:
        """Plan the run (:func:`cosim.loop.plan.make_plan`) and bind it: the signal
        array, each FMU's inputs and reads (straight into its slots), the guard."""
        internal = frozenset().union(*(s.internal for s in self.me_systems))
        self.plan = plan = make_plan(self.fmus, self.python, self.connections, self.ordering, record, self.bounds,
                                     internal)
        self.slots, self.source_of = plan.slots, plan.source_of
        self.signals = np.zeros(len(plan.slots))
        for slot, value in plan.start_values:
            self.signals[slot] = value
        self.values = np.full(len(plan.object_slots), None, dtype=object)  # Int64, UInt64, String, Binary
        for slot, value in plan.object_start_values:
            self.values[slot] = value
        for fmu, b in zip(self.fmus, plan.fmus):
            fmu.bind(b.inputs, b.reads, self.signals[b.block] if b.reads else None,
                     objects=self.values, object_inputs=(b.object_inputs, b.object_sources),
                     object_reads=(b.object_reads, b.object_block))
        self.record_columns, self.record_units = plan.record, plan.record_units
        self.guard = Guard(plan.watched, plan.bounds)

    # ---- running --------------------------------------------------------------

    def _split_parameters(self, parameters: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
        split: dict[str, dict[str, Any]] = {name: {} for name in self.components}
        for key, value in parameters.items():
            comp, var = split_endpoint(key, self.components) or (key, "")
            if comp not in self.components or not var:
                raise ConnectionCheckError(
                    f"parameter {key!r}: expected 'component.name' with a component among "
                    f"{', '.join(sorted(self.components))}")
            split[comp][var] = value
        return split

    def run(self, duration: float, seed: int = 0, parameters: Mapping[str, Any] | None = None,
            csv_path: str | Path | None = None, t0: float = 0.0, block_rows: int = 100,
            raise_on_error: bool = True, progress: Callable[[int, int], None] | None = None,
            profile: bool = False, snapshots: Sequence[float] = (),
            restore: Mapping[str, bytes] | None = None, keep: int | None = None, observers: Sequence = (),
            record_every: int = 1) -> RunResult:
        """Run from ``t0`` for ``duration`` seconds (a whole number of steps).

        ``seed`` (an integer in [0, 2^53]) goes to every Python component's
        ``start`` and to every FMU's seed parameter (its stream's seed,
        :func:`cosim.fmi.lifecycle.stream_seed`). ``csv_path``: the recorded
        rows are also streamed there as they are produced, ``block_rows`` rows
        at a time, with a JSON sidecar (:mod:`cosim.loop.recorder`); a failed run
        keeps what it wrote. ``progress(done_steps, n_steps)`` is called
        as the run advances (at each written block). ``parameters`` overrides, for this run only, FMU parameters and Python
        component parameters by ``component.name``. With ``raise_on_error``
        (default) a divergence or FMU failure raises after the partial result
        is saved (the exception carries it as ``.result``); otherwise the
        result is returned with its status. A failure before the first step
        (a parameter the FMU refuses, a component that cannot start) always
        raises: there is no run to return. ``profile`` times each phase of
        the loop (``RunResult.phase_times``), at a small cost per step.

        ``snapshots``: communication points (s, in ``[t0, t0 + duration]``)
        at which every FMU's state is taken (:class:`Snapshot`, in
        ``RunResult.snapshots``, in time order); a time between two points
        is refused. ``restore``: FMU name -> a serialized FMU state (e.g. a
        snapshot's ``states``) set after that FMU is started at ``t0``: a
        run resumed from a snapshot (``t0`` its time). An FMU left out
        starts from its parameters, so a run can resume with some FMUs put
        in another state (a perturbed plant, a linearization's check).

        The rows stream (:class:`~cosim.loop.recorder.Recorder`): to ``csv_path``
        (every ``record_every``-th row), to ``observers`` (each with
        ``add(rows)``: :class:`~cosim.loop.recorder.Rows` in order, e.g. metrics
        taken as the run goes) and into the result's ``data``: every row
        (``keep=None``, bounded by ``cosim.limits.MAX_RECORD_BYTES``), none
        (``keep=0``) or at most ``keep``, evenly thinned, and the last: a
        run's memory then does not grow with its duration.
        """
        if (why := seed_error(seed)) is not None:
            raise ScenarioError(f"seed = {seed!r}: {why}")
        h = self.step
        n_steps = whole_steps(duration, h)
        if n_steps is None:
            raise ValueError(f"duration = {duration!r} s is not a positive whole number of steps of {h!r} s")
        split = self._split_parameters(parameters or {})
        snap_steps = self._snapshot_steps(snapshots, t0, n_steps)
        restore = dict(restore or {})
        unknown = sorted(set(restore) - {f.name for f in self.fmus})
        if unknown:
            raise ConnectionCheckError(f"restore: no FMU named {', '.join(map(repr, unknown))}; the FMUs are "
                                       f"{', '.join(f.name for f in self.fmus)}")
        recorder = Recorder(self.record_columns, self.record_units, n_steps + 1, csv_path, block_rows,
                            meta={"step": h, "t0": t0, "seed": seed}, types=self.plan.record_types,
                            objects=self.plan.record_objects, keep=keep, observers=observers, every=record_every)
        phase_times: dict[str, float] = {}
        started: dict[str, dict[str, Any]] = {}
        taken: list[Snapshot] = []
        status, error, terminated = "ok", None, None
        wall0 = _time.perf_counter()
        try:
            for comp in self.python:
                comp.set_parameters(split[comp.name])
                comp.start(t0, h, n_steps, seed)
            for fmu in self.fmus:  # reads the initial outputs at t0 into the signal array
                seeded = {fmu.seed_parameter: stream_seed(seed, fmu.seed_stream)} if fmu.seed_parameter else {}
                started[fmu.name] = {**fmu.base_parameters, **self.fmu_parameters.get(fmu.name, {}), **seeded,
                                     **split[fmu.name]}
                fmu.enter_initialization(t0, started[fmu.name])
            self._initialize_inputs(t0)
            for fmu in self.fmus:  # reads the outputs at t0
                fmu.exit_initialization(t0)
                if fmu.name in restore:
                    fmu.restore_state(restore[fmu.name])
                    fmu.read_outputs(t0)
        except BaseException as exc:  # nothing ran: a refused start is raised, never a run's status
            recorder.close("failed", f"could not start: {exc}")
            raise
        python_loop = self._python_loop_for(profile)
        try:
            take = self._snapshot_taker(snap_steps, t0, started, taken)
            blocks = _Blocks(recorder, progress, n_steps)
            if python_loop:
                self._loop_python(t0, n_steps, blocks, phase_times if profile else None, take)
            else:
                from . import kernel

                self._loop_compiled(kernel.load(), t0, n_steps, blocks, take, snap_steps)
        except SimulationTerminated as exc:  # the FMU's own end of the simulation: not a failure
            terminated = str(exc)
        except DivergenceError as exc:
            status, error, failure = "diverged", str(exc), exc
        except (FmuCallError, CosimError) as exc:
            status, error, failure = "failed", str(exc), exc
        except BaseException as exc:  # the partial result is saved even on Ctrl-C
            recorder.close("failed", f"{type(exc).__name__}: {exc}")
            raise
        if terminated is not None:
            recorder.meta["terminated"] = terminated
        recorder.close(status, error)
        data, stride = recorder.kept()
        result = RunResult(self.record_columns, self.record_units, data,
                           status, error, _time.perf_counter() - wall0, n_steps, h, phase_times,
                           recorder.path, seed, dict(parameters or {}), taken, self.plan.record_types,
                           recorder.object_columns(), python_loop, terminated,
                           dict(self.plan.python_calls), recorder.n_rows, stride, recorder.span,
                           tuple(observers))
        if status != "ok" and raise_on_error:
            failure.result = result
            raise failure
        return result

    def _initialize_inputs(self, t0: float, passes: int = 100) -> None:
        """Initialization Mode at ``t0``: every FMU's inputs connected to
        another FMU's outputs are set (:attr:`Plan.initialization`) and its
        initial outputs read again, pass after pass, until no output changes
        by more than 1e-12 of its size (a chain settles in one pass per link;
        an algebraic loop through feedthrough FMUs is a fixed-point
        iteration); one line naming the connections that still change after
        ``passes`` passes. Python components have no outputs before their
        first step: their connections are set at t0 by the loop."""
        transfers = self.plan.initialization
        if not transfers:
            return
        signals, objects = self.signals, self.values

        def still(before: np.ndarray) -> np.ndarray:  # the float slots still moving
            return ~((np.abs(signals - before) <= 1e-12 * np.maximum(np.abs(signals), 1.0)) | (signals == before))

        for _ in range(passes):
            before, objects_before = signals.copy(), list(objects)
            for tr in transfers:
                fmu = self.fmus[tr.index]
                fmu.set_inputs(self._transferred(tr), t0)
                fmu.read_outputs(t0)
            if not still(before).any() and list(objects) == objects_before:
                return
        moving = still(before)
        fed = {self.fmus[tr.index].name for tr in transfers}
        loop = [f"{src} -> {dst}" for dst, src in self.source_of.items()
                if split_endpoint(dst, self.components)[0] in fed and (src in self.slots and moving[self.slots[src]])]
        raise ConnectionCheckError(f"initialization at t0 = {t0!r} s: the FMUs' outputs did not settle after {passes} "
                                   f"passes through the connections (an algebraic loop at t0 through "
                                   f"{', '.join(loop) or 'the feedthrough FMUs'}): break it with a delay")

    def _snapshot_steps(self, times: Sequence[float], t0: float, n_steps: int) -> frozenset[int]:
        h, steps = self.step, set()
        for t in times:
            n = communication_point(t, t0, h, n_steps)
            if n is None:
                raise ValueError(f"snapshot at t = {t!r} s: not a communication point t0 + n h of this run "
                                 f"(t0 = {t0!r} s, h = {h!r} s, {n_steps} steps)")
            steps.add(n)
        return frozenset(steps)

    def _snapshot_taker(self, steps: frozenset[int], t0: float, started, taken: list[Snapshot]):
        """``take(n)``: the :class:`Snapshot` at ``t_n`` appended to ``taken``
        if ``n`` is one of ``steps``; ``None`` without snapshots."""
        if not steps:
            return None
        conversion_of = self.plan.conversion_of
        outputs = [name for name in self.slots if name != "time" and name not in conversion_of]
        inputs = [(dst, src, conversion_of.get(dst)) for dst, src in self.source_of.items()]

        def take(n: int) -> None:
            if n in steps:
                values = {name: float(self.signals[self.slots[name]]) for name in outputs}
                values.update((name, self.values[slot]) for name, slot in self.plan.object_slots.items())
                taken.append(Snapshot(t0 + n * self.step, n, {f.name: f.serialize_state() for f in self.fmus},
                                      {k: dict(v) for k, v in started.items()}, values,
                                      {dst: values[src] if conv is None else conv[0] * values[src] + conv[1]
                                       for dst, src, conv in inputs}))
        return take

    def _transferred(self, tr) -> dict[str, Any]:
        """The values a :class:`~cosim.loop.plan.Transfer` sets now: its sources'
        (float and object slots), its connections' unit conversions applied."""
        floats = self.signals[tr.sources]
        for i, factor, offset in tr.converted:
            floats[i] = factor * floats[i] + offset
        return {**dict(zip(tr.inputs, floats.tolist())),
                **dict(zip(tr.object_inputs, self.values[tr.object_sources]))}

    def _initial_transfer(self, transfers, t0: float) -> None:
        """Exchange ordering, at t0 only (the plan's ``transfer`` or
        ``first_transfer``): as libcosim does before its first step, every FMU
        gets the values its inputs are connected to at t0 and its outputs are
        read again, once per FMU, so a chain of direct feedthroughs is
        consistent at t0."""
        for _ in self.fmus:
            for tr in transfers:
                fmu = self.fmus[tr.index]
                fmu.set_inputs(self._transferred(tr), t0)
                fmu.read_outputs(t0)

    # ---- the loop and its phases -------------------------------------------------

    def _py_phase(self, b: PythonBlock, held: np.ndarray | None = None) -> Callable[[int, float], None]:
        """One Python component's step at ``t_n``: gather its inputs (straight
        into its :meth:`~cosim.component.PythonComponent.input_buffers`, if it
        offers them), step it, store its outputs and published internals --
        into ``held`` instead of the signal array when the outputs are
        delayed (exchange ordering)."""
        if b.typed is not None:
            return self._py_typed_phase(b)
        comp = self.python[b.index]
        in_idx, out_block, published = b.sources, b.block, b.published
        signals, take, step = self.signals, np.take, comp.step
        buffers = comp.input_buffers()
        if buffers is None:
            u = np.zeros(len(in_idx))
            targets = [(in_idx, u)]
        else:
            sizes = [buf.size for buf in buffers]
            if sum(sizes) != len(in_idx):
                raise ValueError(f"{comp.name}.input_buffers() sizes {sizes} do not add up to "
                                 f"its {len(in_idx)} inputs")
            edges = np.cumsum([0] + sizes)
            targets = [(in_idx[a:z], buf) for a, z, buf in zip(edges[:-1], edges[1:], buffers)]
            u = None
        step = _converting(step, [buf for _, buf in targets], b.converted)

        if held is not None:
            def phase(n: int, t: float) -> None:
                for idx, buf in targets:
                    take(signals, idx, out=buf)
                held[:] = step(n, t, u)
                if published is not None:
                    signals[published[1]] = comp.internal_values()[published[0]]
                if n == 0:  # its first sample is also its output over the first step, as after
                    signals[out_block] = held  # libcosim's initial transfer
        elif published is None:
            def phase(n: int, t: float) -> None:
                for idx, buf in targets:
                    take(signals, idx, out=buf)
                signals[out_block] = step(n, t, u)
        else:
            which, slots = published
            internal_values = comp.internal_values

            def phase(n: int, t: float) -> None:
                for idx, buf in targets:
                    take(signals, idx, out=buf)
                signals[out_block] = step(n, t, u)
                signals[slots] = internal_values()[which]
        return phase

    def _py_typed_phase(self, b: PythonBlock) -> Callable[[int, float], None]:
        """A Python component with ports of other types than Float64 at
        ``t_n``: ``step`` receives its inputs as a list of Python values (in
        port order, an array's elements in row-major order: float, int, bool,
        str, bytes as :func:`~cosim.component.typed_value` makes them) and
        returns its outputs in the same form; each is checked against its
        port's type (a value the type cannot hold is refused, never rounded)."""
        from ..component import element_ports

        comp = self.python[b.index]
        signals, values, step = self.signals, self.values, comp.step
        in_types = [p.type for p in element_ports(tuple(comp.inputs))]
        outputs = element_ports(tuple(comp.outputs))
        sources, targets = b.typed

        def value_of(in_objects: bool, slot: int, type_: str):
            if in_objects:
                return values[slot]
            value = float(signals[slot])
            if type_ in ("Float64", "Float32"):
                return value
            return bool(value) if type_ == "Boolean" else int(value)  # held exactly (FLOAT_HELD)

        def phase(n: int, t: float) -> None:
            u = [value_of(o, slot, ty) for (o, slot), ty in zip(sources, in_types)]
            y = step(n, t, u)
            if len(y) != len(outputs):
                raise CosimError(f"{comp.name}.step returned {len(y)} values for its {len(outputs)} outputs")
            for (in_objects, slot), port, value in zip(targets, outputs, y):
                try:
                    value = typed_value(port.type, value, f"{comp.name}.{port.name}")
                except ValueError as exc:
                    raise CosimError(f"at t = {t!r} s: {exc}") from None
                if in_objects:
                    values[slot] = value
                else:
                    signals[slot] = value
        return phase

    def _fmu_eval_phase(self, b: FmuBlock) -> Callable[[int, float], None]:
        """An FMU with direct feedthrough at ``t_n`` (feedthrough ordering): its
        inputs at ``t_n`` set, its outputs at ``t_n`` read (it steps at the exchange)."""
        fmu = self.fmus[b.index]
        signals, take, in_idx, u = self.signals, np.take, b.sources, fmu.u[:len(b.sources)]
        write, read = _converting(fmu.write_inputs, [u], b.converted), fmu.read_outputs

        def phase(n: int, t: float) -> None:
            take(signals, in_idx, out=u)
            write(t)
            read(t)
        return phase

    def _fmu_phase(self, t0: float, holds=()) -> Callable[[int, float], None]:
        """Every FMU from ``t_n`` to ``t_{n+1}``: set all its connected inputs
        (taken at ``t_n``) unless it was evaluated at ``t_n``, doStep, read its
        outputs at ``t_{n+1}``; then the held outputs of delayed Python
        components become the values at ``t_{n+1}``."""
        signals, take, h = self.signals, np.take, self.step
        writes = []
        for b in self.plan.exchanged:
            fmu = self.fmus[b.index]
            u = fmu.u[:len(b.sources)]
            writes.append((_converting(fmu.write_inputs, [u], b.converted), b.sources, u))
        do_steps = [f.do_step for f in self.fmus]
        reads = [self.fmus[b.index].read_outputs for b in self.plan.fmus if b.reads or b.object_reads]

        def phase(n: int, t: float) -> None:
            for write, in_idx, u in writes:
                take(signals, in_idx, out=u)
                write(t)
            for do_step in do_steps:
                do_step(t, h)
            t_next = t0 + (n + 1) * h  # from the step counter, never accumulated
            for read in reads:
                read(t_next)
            for held, out_block in holds:
                signals[out_block] = held
        return phase

    def _python_loop_for(self, profile: bool) -> tuple[str, ...]:
        """Why this run takes the Python loop (:meth:`cosim.loop.plan.Plan.python_loop_for`);
        the compiled loop is looked for only where the plan allows it."""
        compiled_available = True
        if self.plan.compiled and not profile:
            from . import kernel

            compiled_available = kernel.load() is not None
        return self.plan.python_loop_for(profile=profile, compiled_available=compiled_available)

    def _loop_compiled(self, run, t0: float, n_steps: int, blocks: "_Blocks", take=None,
                       marks=frozenset()) -> None:
        """The plan run by the compiled loop (:mod:`cosim.loop.kernel`): one call
        per block of recorded rows (:class:`_Blocks`, as :meth:`_loop_python`
        writes them) when a block has somewhere to go (the CSV, the
        progress), else one call per chunk of the recorder (the observers
        and the kept rows get a chunk at a time either way, so the same rows
        reach them: a study's 50 s run returns to Python twice, not 51
        times, and each return waits for the GIL); a call also ends before
        a snapshot's row (``marks``, taken by ``take``)."""
        import ctypes

        from . import kernel

        recorder = blocks.recorder
        h, signals, block, chunk = self.step, self.signals, recorder.block_rows, recorder.chunk
        span = block if recorder.path is not None or blocks.progress is not None else chunk  # rows a call flies
        args = self._kernel_run(kernel, recorder.data, t0, n_steps)
        stop = kernel.KernelStop()
        if self.plan.transfer:  # exchange ordering; no Python component, so no first_transfer
            self._initial_transfer(self.plan.transfer, t0)
        marks = sorted(marks)
        evaluate = [self._fmu_eval_phase(b) for b in self.plan.at_tn] if marks else []
        n = 0
        while n <= n_steps:
            if n in marks:  # the blocks at t_n evaluated once before the snapshot; the kernel repeats them
                for phase in evaluate:  # (the same inputs set again at t_n: the same outputs)
                    signals[0] = t0 + n * h
                    phase(n, t0 + n * h)
                take(n)
            last = min((n // span + 1) * span - 1, n_steps)  # the Python loop flushes at the same rows
            last = min([last] + [m - 1 for m in marks if m > n])  # a snapshot is taken between kernel calls
            args.data_first = n - n % chunk  # the recorder's chunk in memory (a call never crosses one)
            with kernel.off_turn():  # another thread's Python runs meanwhile (kernel.python_turn)
                code = run(ctypes.byref(args), n, last, ctypes.byref(stop))
            if code != kernel.Stop.OK:
                recorder.n_rows = int(stop.n) + int(stop.recorded)
                t = t0 + int(stop.n) * h
                if code == kernel.Stop.GUARD:
                    self.guard.raise_violation(t, signals[self.plan.watch_slots])
                if code == kernel.Stop.TERMINATE:
                    raise self.fmus[int(stop.fmu)]._terminated(t, h)
                raise self.fmus[int(stop.fmu)].kernel_failure(int(stop.call), int(stop.status), t, h)
            blocks.written(last + 1)
            n = last + 1
        blocks.finished()

    def _kernel_run(self, kernel, data: np.ndarray, t0: float, n_steps: int):
        """The run's :class:`~cosim.loop.kernel.KernelRun`, into the recorder's
        ``data``: made once (:func:`~cosim.loop.kernel.prepare`) and kept
        while the plan, the guard and every FMU's instance and buffers are
        the objects it points into (:meth:`~cosim.fmi.fmu.FmuComponent.kernel_parts`);
        the next run of this master changes its start, its length and its
        rows only (a study's run on a cached master: :mod:`cosim.study.runner`)."""
        parts = (self.plan, self.signals, self.guard, *(part for f in self.fmus for part in f.kernel_parts()))
        kept = self._kernel_kept
        if kept is not None and len(kept[0]) == len(parts) and all(a is b for a, b in zip(kept[0], parts)):
            return kernel.restarted(kept[1], data, t0, n_steps)
        low, high = self.guard.limits
        args = kernel.prepare(self.plan, self.fmus, self.signals, data, low, high, t0, self.step, n_steps)
        self._kernel_kept = (parts, args)  # the parts held too: no id of a freed one is taken for theirs
        return args

    def _loop_python(self, t0: float, n_steps: int, blocks: "_Blocks", phase_times: dict[str, float] | None,
                     snap: Callable[[int], None] | None = None) -> None:
        plan, h, signals, take = self.plan, self.step, self.signals, np.take
        recorder = blocks.recorder
        data, rec_idx = recorder.data, plan.record_slots
        guard_ok, guard_idx, guard = self.guard.ok, plan.watch_slots, self.guard
        written, chunk = blocks.written, recorder.chunk

        record_objects = recorder.record_objects if plan.record_objects else None
        values = self.values

        def record(n: int, t: float) -> None:
            take(signals, rec_idx, out=data[n % chunk])  # the recorder's chunk in memory
            if record_objects is not None:  # Int64, UInt64, String, Binary columns
                record_objects(n, values)
            written(n + 1)

        if plan.derived:  # converted inputs recorded or bounded: their values before the row is recorded
            record = _deriving(record, signals, plan.derived)

        def check(n: int, t: float) -> None:
            values = signals[guard_idx]
            if not guard_ok(values):
                guard.raise_violation(t, values)

        # exchange ordering: a Python component with inputs is sampled at t_n and
        # its outputs held from t_{n+1}, like an FMU whose outputs follow its inputs
        phases, holds = [], []
        for b in plan.at_tn:
            if isinstance(b, FmuBlock):
                phases.append((f"fmu:{b.name}", self._fmu_eval_phase(b)))
                continue
            held = np.zeros(b.block.stop - b.block.start) if b.held else None
            if held is not None:
                holds.append((held, b.block))
            phases.append((f"python:{b.name}", self._py_phase(b, held)))
        exchange = self._fmu_phase(t0, holds)
        if phase_times is not None:  # timed from outside: the loop below is the same either way
            phases = [(name, _timed(phase, phase_times, name)) for name, phase in phases]
            record, check = _timed(record, phase_times, "record"), _timed(check, phase_times, "guard")
            exchange = _timed(exchange, phase_times, "fmu")
        steps = [phase for _, phase in phases]
        for n in range(n_steps + 1):
            t = t0 + n * h  # time from the step counter, never accumulated
            signals[0] = t
            if n == 0 and plan.first_transfer and steps:
                self._initial_transfer(plan.first_transfer, t0)
            for phase in steps:
                phase(n, t)
            if n == 0 and plan.transfer:
                self._initial_transfer(plan.transfer, t0)
            if snap is not None:
                snap(n)
            record(n, t)
            check(n, t)
            if n < n_steps:
                exchange(n, t)
        blocks.finished()

    def close(self) -> None:
        self._kernel_kept = None
        for f in self.fmus:
            f.close()

    def __enter__(self) -> "Master":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _Blocks:
    """How both loops hand rows to the recorder: ``written(rows)`` after each
    row (or kernel call) counts them and, every ``block_rows`` rows, commits
    the block to the CSV and reports progress; ``finished()`` reports the end."""

    __slots__ = ("recorder", "progress", "n_steps", "block")

    def __init__(self, recorder: Recorder, progress: Callable[[int, int], None] | None, n_steps: int):
        self.recorder, self.progress, self.n_steps = recorder, progress, n_steps
        self.block = recorder.block_rows

    def written(self, rows: int) -> None:
        self.recorder.n_rows = rows
        if rows % self.block == 0:
            self.recorder.commit(rows)
            if self.progress is not None:
                self.progress(rows - 1, self.n_steps)

    def finished(self) -> None:
        if self.progress is not None:
            self.progress(self.n_steps, self.n_steps)


def _converting(call: Callable, buffers: Sequence[np.ndarray], converted) -> Callable:
    """``call`` preceded by the unit conversions ``converted`` (``(i, factor,
    offset)``: input ``i`` becomes ``factor * input + offset``) of the inputs
    just gathered into ``buffers`` (in port order); ``call`` itself when
    there are none, so an input without a conversion is never touched (not
    even ``x * 1 + 0``, which would turn -0.0 into +0.0)."""
    fixes, first = [], 0
    for buf in buffers:
        mine = [(i - first, f, o) for i, f, o in converted if first <= i < first + buf.size]
        if mine:
            index, factor, offset = (np.array(column) for column in zip(*mine))
            fixes.append((buf, index.astype(np.intp), factor, offset))
        first += buf.size
    if not fixes:
        return call

    def converting(*args):
        for buf, index, factor, offset in fixes:
            buf[index] = factor * buf[index] + offset
        return call(*args)
    return converting


def _deriving(record: Callable[[int, float], None], signals: np.ndarray, derived) -> Callable[[int, float], None]:
    """``record`` preceded by the plan's ``derived`` slots (a converted input
    recorded or bounded: ``slot = factor * source + offset``)."""
    slot, source, factor, offset = (np.array(column) for column in zip(*derived))
    slot, source = slot.astype(np.intp), source.astype(np.intp)

    def deriving(n: int, t: float) -> None:
        signals[slot] = factor * signals[source] + offset
        record(n, t)
    return deriving


def _timed(phase: Callable[[int, float], None], totals: dict[str, float], name: str) -> Callable[[int, float], None]:
    """``phase`` with its wall time added to ``totals[name]`` on every call."""
    clock = _time.perf_counter
    totals.setdefault(name, 0.0)

    def timed(n: int, t: float) -> None:
        c = clock()
        try:
            phase(n, t)
        finally:
            totals[name] += clock() - c
    return timed
