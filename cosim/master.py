"""The fixed-step co-simulation master.

Algorithm (stated in full in ``docs/cosim.md``): communication points
``t_n = t0 + n h`` from the step counter n = 0 .. N. At each ``t_n``:

1. every FMU output is known at ``t_n`` (read after initialization, then after
   each step);
2. the Python components are evaluated in topological order of their mutual
   connections (a sampled-data block may have direct feedthrough: the
   a controller's command at ``t_n`` may depend on the plant state at ``t_n``);
   a cycle among them is refused before the first step;
3. the recorded signals at ``t_n`` are stored (and streamed in blocks), and
   the guard checks every signal (finite, inside its envelope);
4. every FMU gets all its connected inputs, taken at ``t_n``, in one call;
5. every FMU steps from ``t_n`` to ``t_{n+1}`` (Jacobi among FMUs: they only
   see each other's values at ``t_n``, held constant over the step), and its
   outputs at ``t_{n+1}`` are read in one call.

All signals live in one float64 array; each connection is an index into it,
precomputed before the run, so a step allocates nothing but small temporaries.

The loop holds no clock: ``run(..., profile=True)`` wraps each phase (the FMU
exchange, each Python component, recording, the guard) in a timer before the
loop starts, and the result's ``phase_times`` says where the time went.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .component import Port, PythonComponent
from .connection import Connection, check_connections, parse_connections
from .errors import ConnectionCheckError, CosimError, DivergenceError, FmuCallError
from .fmu_component import FmuComponent, stream_seed
from .guard import Guard
from .recorder import Recorder

__all__ = ["Master", "RunResult", "ORDERINGS"]

ORDERINGS = ("feedthrough", "exchange")


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

    @property
    def time(self) -> np.ndarray:
        return self.data[:, 0]

    def __getitem__(self, name: str) -> np.ndarray:
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
    connections : connection strings or :class:`~cosim.connection.Connection`.
    step : communication step h (s).
    record : signals (``component.variable``) to record, after ``time``.
    bounds : ``signal -> (low, high)``, the envelope (inclusive); every
        signal the master holds (the FMU outputs in use, every Python output,
        the internal signals recorded) is also checked to be finite.
    """

    def __init__(self, fmus: Sequence[FmuComponent], components: Sequence[PythonComponent],
                 connections: Sequence[str | Connection], step: float, record: Sequence[str] = (),
                 bounds: Mapping[str, tuple[float, float]] | None = None,
                 fmu_parameters: Mapping[str, Mapping[str, float]] | None = None, ordering: str = "feedthrough"):
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
        conns += parse_connections([c for c in connections if not isinstance(c, Connection)])
        self.connections = check_connections(conns, self.components)
        self.bounds = dict(bounds or {})
        self._plan(list(record))

    # ---- planning -----------------------------------------------------------

    def _signal_port(self, signal: str) -> Port:
        comp_name, _, var = signal.partition(".")
        comp = self.components.get(comp_name)
        if comp is None:
            raise ConnectionCheckError(
                f"signal {signal!r}: unknown component {comp_name!r}; components are: "
                f"{', '.join(sorted(self.components))}")
        if not var:
            raise ConnectionCheckError(f"signal {signal!r}: expected 'component.variable'")
        internals = getattr(comp, "internals", ())
        for port in comp.outputs + internals:
            if port.name == var:
                return port
        for port in comp.inputs:  # an input is recorded as the value its source gives it
            if port.name == var:
                return port
        known = ", ".join(p.name for p in comp.outputs + comp.inputs + internals)
        kinds = "output, input or internal signal" if internals else "output or input"
        raise ConnectionCheckError(f"signal {signal!r}: {comp_name} has no {kinds} {var!r}; it has: {known}")

    def _direct_fmus(self, used: set[str]) -> set[str]:
        """FMUs to evaluate at ``t_n`` (feedthrough ordering): those with a used
        output that depends directly on a connected input (ModelStructure)."""
        if self.ordering != "feedthrough":
            return set()
        direct = set()
        for fmu in self.fmus:
            connected = {c.destination.variable for c in self.connections if c.destination.component == fmu.name}
            if any(fmu.feedthrough.get(p.name, frozenset()) & connected
                   for p in fmu.outputs if f"{fmu.name}.{p.name}" in used):
                direct.add(fmu.name)
        return direct

    def _order(self, direct: set[str]) -> list:
        """The blocks evaluated at ``t_n``, in topological order of their
        connections: the Python components (and, in the feedthrough ordering,
        the FMUs with direct feedthrough). Only a connection whose source
        depends on its block's inputs at ``t_n`` orders two blocks, so a
        plant's states feeding a controller that feeds the plant is no loop.
        In the exchange ordering nothing is ordered: every block reads the
        values of the previous exchange."""
        blocks = [c.name for c in self.python] + [f.name for f in self.fmus if f.name in direct]
        deps: dict[str, set[str]] = {name: set() for name in blocks}
        for c in self.connections:
            src, dst = c.source.component, c.destination.component
            if src not in deps or dst not in deps or self.ordering != "feedthrough":
                continue
            fmu = self.components[src] if src in direct else None
            if fmu is None or fmu.feedthrough.get(c.source.variable):
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
        return [self.components[n] for n in order]

    def _plan(self, record: list[str]) -> None:
        source_of = {str(c.destination): str(c.source) for c in self.connections}
        self.source_of = source_of
        for s in record + list(self.bounds):
            self._signal_port(s)
            src = source_of.get(s, s)
            comp, _, var = src.partition(".")
            readable = self.components[comp].outputs + getattr(self.components[comp], "internals", ())
            if var not in {p.name for p in readable}:
                raise ConnectionCheckError(f"signal {s!r} is an input that nothing feeds; record its source")
        used = {str(c.source) for c in self.connections}
        used |= {source_of.get(s, s) for s in record + list(self.bounds)}
        # Slot layout: time, then each FMU's used outputs (contiguous, so the
        # FMU writes them straight into the signal array), then each Python
        # component's outputs (contiguous, one slice assignment per step),
        # then the internal signals that are recorded or bounded.
        slots: dict[str, int] = {"time": 0}
        blocks: dict[str, slice] = {}
        for comp in self.fmus + self.python:
            first = len(slots)
            for p in comp.outputs:
                name = f"{comp.name}.{p.name}"
                if name in used or comp in self.python:
                    slots[name] = len(slots)
            blocks[comp.name] = slice(first, len(slots))
        published: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for comp in self.python:
            picked = [(i, f"{comp.name}.{p.name}") for i, p in enumerate(comp.internals)
                      if f"{comp.name}.{p.name}" in used]
            for _, name in picked:
                slots[name] = len(slots)
            if picked:
                published[comp.name] = (np.array([i for i, _ in picked], dtype=np.intp),
                                        np.array([slots[name] for _, name in picked], dtype=np.intp))
        # Unconnected Python inputs that declare a start value: one slot each,
        # written once here and by nothing after, so they hold that value.
        held_inputs: dict[str, float] = {}
        for comp in self.python:
            for p in comp.inputs:
                name = f"{comp.name}.{p.name}"
                if name not in source_of and p.start is not None:
                    held_inputs[name] = float(p.start)
                    slots[name] = len(slots)
        self.slots = slots
        self.signals = np.zeros(len(slots))
        for name, value in held_inputs.items():
            self.signals[slots[name]] = value

        direct = self._direct_fmus(used)
        self._direct = direct
        fmu_in: dict[str, np.ndarray] = {}
        self._fmu_in_idx = fmu_in
        self._fmu_in: list[tuple[FmuComponent, np.ndarray]] = []  # written at the exchange
        self._fmu_out: list[FmuComponent] = []
        for fmu in self.fmus:
            ins = [c for c in self.connections if c.destination.component == fmu.name]
            block = blocks[fmu.name]
            outs = [s.partition(".")[2] for s, i in slots.items() if block.start <= i < block.stop]
            fmu.bind([c.destination.variable for c in ins], outs, self.signals[block] if outs else None)
            fmu_in[fmu.name] = np.array([slots[str(c.source)] for c in ins], dtype=np.intp)
            if ins and fmu.name not in direct:
                self._fmu_in.append((fmu, fmu_in[fmu.name]))
            if outs:
                self._fmu_out.append(fmu)

        # the blocks evaluated at t_n: ("python", comp, in_idx, out_block, published) or ("fmu", fmu, in_idx)
        self._blocks: list[tuple] = []
        for comp in self._order(direct):
            if comp.name in direct:
                self._blocks.append(("fmu", comp, fmu_in[comp.name]))
                continue
            missing = [p.name for p in comp.inputs
                       if f"{comp.name}.{p.name}" not in source_of and f"{comp.name}.{p.name}" not in held_inputs]
            if missing:
                raise ConnectionCheckError(f"inputs of {comp.name} not connected: {', '.join(missing)}")
            in_idx = np.array([slots[source_of.get(name, name)] for name in (f"{comp.name}.{p.name}"
                                                                              for p in comp.inputs)], dtype=np.intp)
            self._blocks.append(("python", comp, in_idx, blocks[comp.name], published.get(comp.name)))

        self.record_columns = ("time",) + tuple(record)
        self.record_units = ("s",) + tuple(self._signal_port(s).unit for s in record)
        self._rec_idx = np.array([slots[source_of.get(s, s)] for s in self.record_columns], dtype=np.intp)
        watch_bounds = {source_of.get(s, s): (float(b[0]), float(b[1])) for s, b in self.bounds.items()}
        watched = [s for s in slots if s != "time"]
        self.guard = Guard(watched, watch_bounds)
        self._guard_idx = np.array([slots[s] for s in watched], dtype=np.intp)

    # ---- running --------------------------------------------------------------

    def _split_parameters(self, parameters: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
        split: dict[str, dict[str, Any]] = {name: {} for name in self.components}
        for key, value in parameters.items():
            comp, _, var = key.partition(".")
            if comp not in self.components or not var:
                raise ConnectionCheckError(
                    f"parameter {key!r}: expected 'component.name' with a component among "
                    f"{', '.join(sorted(self.components))}")
            split[comp][var] = value
        return split

    def run(self, duration: float, seed: int = 0, parameters: Mapping[str, Any] | None = None,
            csv_path: str | Path | None = None, t0: float = 0.0, block_rows: int = 100,
            raise_on_error: bool = True, progress: Callable[[int, int], None] | None = None,
            profile: bool = False) -> RunResult:
        """Run from ``t0`` for ``duration`` seconds (a whole number of steps).

        ``parameters`` overrides, for this run only, FMU parameters and Python
        component parameters by ``component.name``. With ``raise_on_error``
        (default) a divergence or FMU failure raises after the partial result
        is saved (the exception carries it as ``.result``); otherwise the
        result is returned with its status. A failure before the first step
        (a parameter the FMU refuses, a component that cannot start) always
        raises: there is no run to return. ``profile`` times each phase of
        the loop (``RunResult.phase_times``), at a small cost per step.
        """
        h = self.step
        n_steps = int(round(duration / h))
        if n_steps < 1 or abs(n_steps * h - duration) > 1e-9 * max(1.0, abs(duration)):
            raise ValueError(f"duration = {duration!r} s is not a positive whole number of steps of {h!r} s")
        split = self._split_parameters(parameters or {})
        recorder = Recorder(self.record_columns, self.record_units, n_steps + 1, csv_path, block_rows,
                            meta={"step": h, "t0": t0, "seed": seed})
        phase_times: dict[str, float] = {}
        status, error = "ok", None
        wall0 = _time.perf_counter()
        try:
            for comp in self.python:
                comp.set_parameters(split[comp.name])
                comp.start(t0, h, n_steps, seed)
            for fmu in self.fmus:  # reads the outputs at t0 into the signal array
                seeded = {fmu.seed_parameter: stream_seed(seed, fmu.seed_stream)} if fmu.seed_parameter else {}
                fmu.start(t0, {**fmu.base_parameters, **self.fmu_parameters.get(fmu.name, {}), **seeded,
                               **split[fmu.name]})
        except BaseException as exc:  # nothing ran: a refused start is raised, never a run's status
            recorder.close("failed", f"could not start: {exc}")
            raise
        try:
            self._loop(t0, n_steps, recorder, progress, phase_times if profile else None)
        except DivergenceError as exc:
            status, error, failure = "diverged", str(exc), exc
        except (FmuCallError, CosimError) as exc:
            status, error, failure = "failed", str(exc), exc
        except BaseException as exc:  # the partial result is saved even on Ctrl-C
            recorder.close("failed", f"{type(exc).__name__}: {exc}")
            raise
        recorder.close(status, error)
        result = RunResult(self.record_columns, self.record_units, recorder.data[:recorder.n_rows].copy(),
                           status, error, _time.perf_counter() - wall0, n_steps, h, phase_times,
                           recorder.path, seed, dict(parameters or {}))
        if status != "ok" and raise_on_error:
            failure.result = result
            raise failure
        return result

    def _initial_transfer(self, t0: float, fmu_sources_only: bool = False) -> None:
        """Exchange ordering, at t0 only: as libcosim does before its first
        step, every FMU gets the values its inputs are connected to at t0 (the
        FMUs' outputs after initialization, the Python components' first
        outputs) and its outputs are read again, once per FMU, so a chain of
        direct feedthroughs is consistent at t0. ``fmu_sources_only``: only
        the connections from FMUs, the transfer that runs before the Python
        components' first step (their outputs do not exist yet), so that
        they read FMU outputs consistent at t0 too (an FMU with feedthrough
        between the plant and a Python controller, such as a sensor)."""
        fmu_names = {f.name for f in self.fmus}
        feeds = {f.name: [c for c in self.connections if c.destination.component == f.name
                          and (not fmu_sources_only or c.source.component in fmu_names)] for f in self.fmus}
        for _ in self.fmus:
            for fmu in self.fmus:
                fmu.set_inputs({c.destination.variable: self.signals[self.slots[str(c.source)]]
                                for c in feeds[fmu.name]}, t0)
                fmu.read_outputs(t0)

    # ---- the loop and its phases -------------------------------------------------

    def _py_phase(self, comp: PythonComponent, in_idx: np.ndarray, out_block: slice,
                  published: tuple[np.ndarray, np.ndarray] | None,
                  held: np.ndarray | None = None) -> Callable[[int, float], None]:
        """One Python component's step at ``t_n``: gather its inputs (straight
        into its :meth:`~cosim.component.PythonComponent.input_buffers`, if it
        offers them), step it, store its outputs and published internals --
        into ``held`` instead of the signal array when the outputs are
        delayed (exchange ordering)."""
        signals, take, step = self.signals, np.take, comp.step
        buffers = comp.input_buffers()
        if buffers is None:
            u = np.zeros(len(in_idx))
            targets = [(in_idx, u)]
        else:
            sizes = [b.size for b in buffers]
            if sum(sizes) != len(in_idx):
                raise ValueError(f"{comp.name}.input_buffers() sizes {sizes} do not add up to "
                                 f"its {len(in_idx)} inputs")
            edges = np.cumsum([0] + sizes)
            targets = [(in_idx[a:b], buf) for a, b, buf in zip(edges[:-1], edges[1:], buffers)]
            u = None

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

    def _fmu_eval_phase(self, fmu: FmuComponent, in_idx: np.ndarray) -> Callable[[int, float], None]:
        """An FMU with direct feedthrough at ``t_n`` (feedthrough ordering): its
        inputs at ``t_n`` set, its outputs at ``t_n`` read (it steps at the exchange)."""
        signals, take, u = self.signals, np.take, fmu.u[:len(in_idx)]
        write, read = fmu.write_inputs, fmu.read_outputs

        def phase(n: int, t: float) -> None:
            take(signals, in_idx, out=u)
            write(t)
            read(t)
        return phase

    def _fmu_phase(self, t0: float, holds=()) -> Callable[[int, float], None]:
        """Every FMU from ``t_n`` to ``t_{n+1}``: set all its connected inputs
        (taken at ``t_n``), doStep, read its outputs at ``t_{n+1}``; then the
        held outputs of delayed Python components become the values at ``t_{n+1}``."""
        signals, take, h = self.signals, np.take, self.step
        writes = [(f.write_inputs, in_idx, f.u[:len(in_idx)]) for f, in_idx in self._fmu_in]
        do_steps = [f.do_step for f in self.fmus]
        reads = [f.read_outputs for f in self._fmu_out]

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

    def _loop(self, t0: float, n_steps: int, recorder: Recorder, progress: Callable[[int, int], None] | None,
              phase_times: dict[str, float] | None) -> None:
        if phase_times is None and all(kind == "fmu" for kind, *_ in self._blocks):
            from . import kernel

            run = kernel.load()
            if run is not None:
                return self._loop_compiled(run, t0, n_steps, recorder, progress)
        self._loop_python(t0, n_steps, recorder, progress, phase_times)

    def _loop_compiled(self, run, t0: float, n_steps: int, recorder: Recorder,
                       progress: Callable[[int, int], None] | None) -> None:
        """The loop of :meth:`_loop_python`, for FMUs only, compiled
        (:mod:`cosim.kernel`): one call per block of recorded rows."""
        import ctypes

        from . import kernel

        h, signals, block = self.step, self.signals, recorder.block_rows
        entries = (kernel.KernelFmu * len(self.fmus))(
            *(f.kernel_entry(f.name in self._direct, self._fmu_in_idx[f.name]) for f in self.fmus))
        order = np.array([self.fmus.index(comp) for _, comp, _ in self._blocks], dtype=np.int64)
        rec_idx = np.ascontiguousarray(self._rec_idx, dtype=np.int64)
        guard_idx = np.ascontiguousarray(self._guard_idx, dtype=np.int64)
        low, high = self.guard.limits
        stop = kernel.KernelStop()
        if self.ordering == "exchange":
            self._initial_transfer(t0)
        i64, dbl, ptr = ctypes.c_int64, ctypes.c_double, ctypes.c_void_p
        fixed = (ptr(ctypes.addressof(entries)), i64(len(self.fmus)), ptr(order.ctypes.data), i64(len(order)),
                 ptr(signals.ctypes.data), dbl(t0), dbl(h))
        tail = (i64(n_steps), ptr(recorder.data.ctypes.data), i64(len(rec_idx)), ptr(rec_idx.ctypes.data),
                i64(len(guard_idx)), ptr(guard_idx.ctypes.data), ptr(low.ctypes.data), ptr(high.ctypes.data),
                ctypes.byref(stop))
        n = 0
        while n <= n_steps:
            last = min((n // block + 1) * block - 1, n_steps)  # the Python loop flushes at the same rows
            code = run(*fixed, i64(n), i64(last), *tail)
            if code != kernel.KERNEL_OK:
                recorder.n_rows = int(stop.n) + int(stop.recorded)
                t = t0 + int(stop.n) * h
                if code == kernel.KERNEL_GUARD:
                    self.guard.raise_violation(t, signals[self._guard_idx])
                raise self.fmus[int(stop.fmu)].kernel_failure(int(stop.call), int(stop.status), t, h)
            recorder.n_rows = last + 1
            if (last + 1) % block == 0:
                recorder.commit(last + 1)
                if progress is not None:
                    progress(last, n_steps)
            n = last + 1
        if progress is not None:
            progress(n_steps, n_steps)

    def _loop_python(self, t0: float, n_steps: int, recorder: Recorder,
                     progress: Callable[[int, int], None] | None, phase_times: dict[str, float] | None) -> None:
        h, signals, take = self.step, self.signals, np.take
        data, rec_idx = recorder.data, self._rec_idx
        guard_ok, guard_idx, guard = self.guard.ok, self._guard_idx, self.guard
        block = recorder.block_rows

        def record(n: int, t: float) -> None:
            take(signals, rec_idx, out=data[n])
            recorder.n_rows = n + 1
            if (n + 1) % block == 0:
                recorder.commit(n + 1)
                if progress is not None:
                    progress(n, n_steps)

        def check(n: int, t: float) -> None:
            values = signals[guard_idx]
            if not guard_ok(values):
                guard.raise_violation(t, values)

        # exchange ordering: a Python component with inputs is sampled at t_n and
        # its outputs held from t_{n+1}, like an FMU whose outputs follow its inputs
        python, holds = [], []
        for kind, comp, *rest in self._blocks:
            if kind == "fmu":
                python.append((f"fmu:{comp.name}", self._fmu_eval_phase(comp, *rest)))
                continue
            in_idx, out_block, published = rest
            held = np.zeros(out_block.stop - out_block.start) if self.ordering == "exchange" and len(in_idx) else None
            if held is not None:
                holds.append((held, out_block))
            python.append((f"python:{comp.name}", self._py_phase(comp, in_idx, out_block, published, held)))
        exchange = self._fmu_phase(t0, holds)
        if phase_times is not None:  # timed from outside: the loop below is the same either way
            python = [(name, _timed(phase, phase_times, name)) for name, phase in python]
            record, check = _timed(record, phase_times, "record"), _timed(check, phase_times, "guard")
            exchange = _timed(exchange, phase_times, "fmu")
        steps = [phase for _, phase in python]
        for n in range(n_steps + 1):
            t = t0 + n * h  # time from the step counter, never accumulated
            signals[0] = t
            if n == 0 and self.ordering == "exchange" and steps:
                self._initial_transfer(t0, fmu_sources_only=True)
            for phase in steps:
                phase(n, t)
            if n == 0 and self.ordering == "exchange":
                self._initial_transfer(t0)
            record(n, t)
            check(n, t)
            if n < n_steps:
                exchange(n, t)
        if progress is not None:
            progress(n_steps, n_steps)

    def close(self) -> None:
        for f in self.fmus:
            f.close()

    def __enter__(self) -> "Master":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


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
