"""Segments and their exact sensitivities from the model's own CasADi definition.

When the FMU is one of ours (a registered model whose ``definition`` the
registry gives, and whose built FMU is this very file: the same GUID), the
law the FMU runs is at hand, written once in CasADi: its ``init`` (parameters
-> initial state), its ``step`` (one classical RK4 step, inputs held) and
its ``out`` (the outputs). The calibrator then makes no FMU call:

* **a row** is the FMU's communication step as its C core takes it
  (``fmu_models/export/c/fmu_core.c``, ``core_do_step``): ``n = ceil(dt /
  internal_step - 1e-9)`` equal RK4 steps of ``h = dt / n`` at the times ``t
  + k h`` (a step counter), the inputs of the row held; the outputs at the
  row from its state and inputs;
* **a segment** is ``init`` at the segment's parameters (each state's
  ``<state>_0`` set to the segment's start) and the row ``mapaccum``-ed
  over its rows; its **sensitivities** to the fitted names and the
  estimated initial states are CasADi's forward mode through the same
  graph, all directions at once: the derivatives of the discrete
  trajectory itself (no Magnus step, no differences: exact to round-off);
* the segment functions are generated as C and compiled once per
  machine (:func:`cosim.native.compiled_library`: the cache keyed by the
  source, so by the model and the RK4 steps a row; a Jacobian's chunk takes
  :data:`DIRECTIONS` directions a call, the last padded, so not by their count): the
  simulation and both Jacobians the solver asks for (``n`` RK4 steps a
  row, and the coarse one step) in one library, where the ``step`` and its
  forward derivative they share are compiled once; the segments run side
  by side in ``workers`` threads.
  Without a C compiler, CasADi's virtual machine runs the same functions.

The FMU's binary is generated from the same ``step`` and ``out``, so a
trajectory here is the FMU's to round-off (bit for bit where the C compiler
emits the same operations): both ways give the same estimates
(tests/engine/test_engine_calibration.py). The generic way
(:mod:`cosim.calibration.model`, :mod:`cosim.calibration.sensitivity`)
stays for every other FMU.
"""
from __future__ import annotations

import time

import numpy as np

from ..errors import FmuCallError
from .model import LogModel, Trajectory
from .problem import _float

# -O1, as the FMUs' generated C (docs/fmi-export.md): -O2 took about twice the compiler's time (the two
# largest segment libraries 6.8 and 6.2 CPU-s against 3.3 and 4.6) for the same fit time, and gave the same
# estimates and standard errors bit for bit (no -ffast-math: the optimizer may not change a double's value;
# measured on the plant's fits of tests/paper/test_calibrate_plant.py).
CFLAGS = ("-O1",)

__all__ = ["SymbolicModel", "symbolic_model", "definition_of", "CHUNK"]

# rows a compiled call integrates: the compiled code depends on the model and the RK4 steps a row only
# (not on the log, nor on the directions: DIRECTIONS), and a segment is chained from whole chunks (the last
# padded)
CHUNK = 50

# directions of a Jacobian a compiled call takes (SymbolicModel.directions), the last call padded with zero
# directions: the sensitivities' library is the same for every count of directions, compiled once per machine
# and model (one for four fitted names and another for six was about 1.5 CPU-s of compiler more), and the
# trajectory, which each call carries again, is carried a call per eight directions (docs/calibration.md)
DIRECTIONS = 8


def definition_of(cs) -> object | None:
    """The CasADi definition of the FMU ``cs`` (a
    :class:`~cosim.fmi.fmu.FmuComponent`) when it is one of ours: the
    registered model of its identifier, built as this FMI version, has its
    GUID (a digest of the generated model: any other FMU, or ours with other
    built-in values, differs); else ``None``."""
    from fmpy import read_model_description

    from ..scenario import registry

    md = cs.model_description
    interface = md.coSimulation or md.modelExchange
    entry = registry.fmu_models().get(getattr(interface, "modelIdentifier", None) or md.modelName)
    if entry is None or entry.definition is None:
        return None
    try:
        built = entry.build(cs.fmi_version)
    except Exception:  # noqa: BLE001 - a model that does not build here: the generic way calibrates it
        return None
    if read_model_description(str(built), validate=False).guid != md.guid:
        return None
    return entry.definition()


def symbolic_model(model: LogModel, definition, workers: int = 1) -> "SymbolicModel | str":
    """The :class:`SymbolicModel` of ``model``'s problem with ``definition``,
    or why it does not apply (a string)."""
    p = model.problem
    if "step" not in definition.functions:
        return "the model is not continuous"
    states = [v.name for v in definition.states]
    if states != list(model.states):
        return "its states differ from the FMU's"
    inputs = [v.name for v in definition.inputs]
    parameters = [v.name for v in definition.parameters]
    if any(u not in inputs for u in model.drive):
        return "an input is not the model's"
    if any(model.setters[s] not in parameters for s in model.states):
        return "a state is not started by a parameter"
    outputs = [v.name for v in definition.outputs]
    if any(o not in states and o not in outputs for o in p.outputs):
        return "a compared output is not the model's"
    if "internal_step" in p.fit[:model.n_params]:
        return "internal_step is fitted"
    symbolic = SymbolicModel(model, definition, workers)
    try:
        symbolic._arguments(np.asarray(p.guess, dtype=float), [_whole(model)], model.initial_guess()[None])
    except ValueError as exc:
        return str(exc)
    return symbolic


def _whole(model: LogModel):
    from .segments import Segment

    return Segment(0, 0, model.times.size)


class SymbolicModel:
    """A problem's segments from the CasADi definition (module docstring):
    :meth:`simulate` and :meth:`sensitivities` of every segment at once."""

    def __init__(self, model: LogModel, definition, workers: int = 1):
        self.model, self.definition = model, definition
        self.workers = max(int(workers), 1)
        p = model.problem
        cs = model.cs
        self.x_names = [v.name for v in definition.states]
        self.u_names = [v.name for v in definition.inputs]
        self.p_names = [v.name for v in definition.parameters]
        self.y_names = [v.name for v in definition.outputs]
        self.u_base = np.array([_float(cs.variables[n].start, 0.0) if n in cs.variables else 0.0
                                for n in self.u_names])
        self.p_base = np.array([_float(cs.variables[n].start, 0.0) if n in cs.variables else float(v.start)
                                for n, v in zip(self.p_names, definition.parameters)])
        self.u_log = np.array([self.u_names.index(n) for n in p.inputs], dtype=int)
        self.u_fit = np.array([self.u_names.index(n) for n in p.fit_inputs], dtype=int)
        self.p_fit = np.array([self.p_names.index(n) for n in p.fit[:model.n_params]], dtype=int)
        self.p_setter = np.array([self.p_names.index(model.setters[s]) for s in model.states], dtype=int)
        # a compared output: a state (row of the trajectory) or one of the model's outputs
        self.out_from = [("x", self.x_names.index(o)) if o in self.x_names else ("y", self.y_names.index(o))
                         for o in p.outputs]
        self._functions: dict = {}
        self.compile_seconds = 0.0  # spent generating and compiling C in this process (0 when cached)
        # directions a compiled Jacobian call takes (None: all of them, a library per count): DIRECTIONS, so
        # that one library serves every count (the fitted names and the estimated states; docs/calibration.md)
        self.directions: int | None = DIRECTIONS
        self.source = "compiled"  # or "CasADi's virtual machine" without a C compiler

    # ---- the segments' arguments --------------------------------------------------------------

    def _substeps(self, parameters: np.ndarray, dt: np.ndarray) -> int:
        step = float(parameters[self.p_names.index("internal_step")]) if "internal_step" in self.p_names else \
            float(np.max(dt))
        counts = np.maximum(np.ceil(dt / step - 1e-9), 1)
        if counts.min() != counts.max():
            raise ValueError("rows a different number of RK4 steps apart")
        return int(counts[0])

    def _arguments(self, theta: np.ndarray, segments, x0: np.ndarray):
        """``(n, [(p, T, U, DT) of each segment])``: the RK4 steps a row, and
        each segment's parameters and its rows' times, inputs and steps,
        padded to whole chunks (held at the segment's last row), as CasADi
        takes them (column-major: each array is the transpose of the matrix)."""
        m, p = self.model, self.model.problem
        t = m.times
        base = self.p_base.copy()
        for name, value in m.parameters(theta).items():
            if name in self.p_names:
                base[self.p_names.index(name)] = value
        dt_all = np.diff(t)
        n = self._substeps(base, dt_all)
        out = []
        for s, start in zip(segments, np.asarray(x0, dtype=float)):
            params = base.copy()
            params[self.p_setter] = start
            padded = -(-(s.last - s.first) // CHUNK) * CHUNK
            rows = np.minimum(np.arange(s.first, s.first + padded), s.last - 1)
            U = np.tile(self.u_base, (padded, 1))
            U[:, self.u_fit] = theta[m.n_params:]
            if self.u_log.size:
                U[:, self.u_log] = p.input_values[rows]
            out.append((params, np.ascontiguousarray(t[rows]), U,
                        np.ascontiguousarray(dt_all[np.minimum(rows, t.size - 2)])))
        return n, out

    # ---- the functions ----------------------------------------------------------------------------

    def _function(self, kind: str, n: int, nd: int):
        """``kind``: ``"start"`` (a segment's initial state from its
        parameters, and its sensitivities: CasADi's virtual machine, it is
        small), ``"simulate"`` of :data:`CHUNK` rows of ``n`` RK4 steps,
        ``"sensitivities"`` of :data:`CHUNK` rows of ``n`` RK4 steps and
        ``"coarse"`` of one (compiled)."""
        key = (kind, n, nd)
        if key not in self._functions:
            if kind == "start":
                self._functions[key] = self._start(nd)
                return self._functions[key]
            # the simulation and both Jacobians the solver asks for in one library: they call the same model
            # step (and its forward derivative), the bulk of the C, which is then generated and compiled once
            # (a library each compiled it twice: the plant's four fitted names 4.4 CPU-s against 2.5, its six
            # 6.5 against 3.8; the simulation's own library about 0.4 s more; the coarse one's own code is
            # small, so a fit without coarse iterations pays little for it); the coarse one is the exact one
            # where a row is one RK4 step already
            wanted = {}
            if ("simulate", n, 0) not in self._functions:
                wanted[("simulate", n, 0)] = self._simulate(n)
            jd = nd if kind != "simulate" else (self.directions or 1)
            if ("sensitivities", n, jd) not in self._functions:
                kinds = {"sensitivities": n, "coarse": 1} if n > 1 else {"sensitivities": 1, "coarse": 1}
                made = {}
                for name, steps in kinds.items():
                    made.setdefault(steps, self._sensitivities(steps, jd, name))
                    wanted[(name, n, jd)] = made[steps]
            fns = list({id(fn): fn for fn in wanted.values()}.values())
            compiled = dict(zip(map(id, fns), self._compile(fns)))
            for k, fn in wanted.items():
                self._functions[k] = compiled[id(fn)]
        return self._functions[key]

    def _start(self, nd: int):
        import casadi as ca

        f = self.definition.functions
        p0, P0d = ca.MX.sym("p0", len(self.p_names)), ca.MX.sym("P0d", len(self.p_names), nd)
        x0 = f["init"](p0)
        return _Interpreted(ca.Function("start", [p0, P0d], [
            x0, f["init"].forward(nd)(p0, x0, P0d) if nd else ca.MX(len(self.x_names), 0)]))

    def _one_direction(self, name: str):
        """The model's ``step`` or ``out`` whose forward derivative takes one
        direction a call (CasADi's ``max_num_dir``): a Jacobian's ``nd``
        directions are ``nd`` calls of one derivative function, where
        ``forward(nd)`` generated one function of all of them, about ``nd``
        times the C (the plant's RK4 step: 2400 lines for one direction, 9000
        for six), compiled again for every count of directions a fit has (the
        fitted names and estimated states). Each direction is the same
        operations either way, so the Jacobians are the same bit for bit; the
        step's own values are computed again in each call instead of once,
        which makes an exact Jacobian about 1.6x the time (docs/calibration.md:
        the decision and the figures). The function's own code is unchanged
        (made again from its expression graph)."""
        import casadi as ca

        key = ("one direction", name)
        if key not in self._functions:
            fn = self.definition.functions[name]
            if fn.is_a("SXFunction"):
                ins = fn.sx_in()
                fn = ca.Function(fn.name(), ins, fn.call(ins), fn.name_in(), fn.name_out(), {"max_num_dir": 1})
            self._functions[key] = fn
        return self._functions[key]

    def _row(self, n: int):
        """One row: ``n`` RK4 steps from its state and the outputs at its start (``core_do_step``); one
        function of each ``n``, which the simulation and the Jacobians of a library share."""
        if ("row", n) not in self._functions:
            self._functions[("row", n)] = self._make_row(n)
        return self._functions[("row", n)]

    def _make_row(self, n: int):
        import casadi as ca

        f = {name: self._one_direction(name) for name in ("step", "out")}
        x, t, dt = ca.MX.sym("x", len(self.x_names)), ca.MX.sym("t"), ca.MX.sym("dt")
        u, p = ca.MX.sym("u", len(self.u_names)), ca.MX.sym("p", len(self.p_names))
        h = dt / n
        xk = x
        for k in range(n):  # core_do_step: n equal RK4 steps, the time from a step counter
            xk = f["step"](t + k * h, xk, u, p, h)
        return ca.Function("row", [x, t, u, p, dt], [xk, f["out"](t, x, u, p)])

    def _simulate(self, n: int):
        import casadi as ca

        x, p0 = ca.MX.sym("x", len(self.x_names)), ca.MX.sym("p0", len(self.p_names))
        T, U, DT = ca.MX.sym("T", 1, CHUNK), ca.MX.sym("U", len(self.u_names), CHUNK), ca.MX.sym("DT", 1, CHUNK)
        X, Y = self._row(n).mapaccum("rows", CHUNK)(x, T, U, ca.repmat(p0, 1, CHUNK), DT)
        return ca.Function("calibration_simulate", [x, p0, T, U, DT], [X, Y])

    def _sensitivities(self, n: int, nd: int, name: str):
        import casadi as ca

        nx, nu, npar = len(self.x_names), len(self.u_names), len(self.p_names)
        x, t, dt = ca.MX.sym("x", nx), ca.MX.sym("t"), ca.MX.sym("dt")
        u, p, p0 = ca.MX.sym("u", nu), ca.MX.sym("p", npar), ca.MX.sym("p0", npar)
        T, U, DT = ca.MX.sym("T", 1, CHUNK), ca.MX.sym("U", nu, CHUNK), ca.MX.sym("DT", 1, CHUNK)
        S, Pd, Ud = ca.MX.sym("S", nx, nd), ca.MX.sym("Pd", npar, nd), ca.MX.sym("Ud", nu, nd)
        row = self._row(n)
        xn, y = row(x, t, u, p, dt)
        dxn, dy = row.forward(nd)(x, t, u, p, dt, xn, y, S, ca.MX(1, nd), Ud, Pd, ca.MX(1, nd))
        rows = ca.Function(f"row_{name}", [x, S, t, u, p, dt, Pd, Ud], [xn, dxn, y, dy])
        X, dX, Y, dY = rows.mapaccum("rows", CHUNK, [0, 1], [0, 1])(
            x, S, T, U, ca.repmat(p0, 1, CHUNK), DT, ca.repmat(Pd, 1, CHUNK), ca.repmat(Ud, 1, CHUNK))
        return ca.Function(f"calibration_{name}", [x, S, p0, Pd, Ud, T, U, DT], [X, dX, Y, dY])

    def _compile(self, fns: list) -> list:
        """``fns`` generated as C into one library, compiled once per machine
        (:func:`cosim.native.compiled_library`), each a callable; without a C
        compiler, run by CasADi's virtual machine."""
        import casadi as ca

        from ..native import compiled_library

        cg = ca.CodeGenerator(f"{fns[0].name()}.c")
        for fn in fns:
            cg.add(fn)
        started = time.perf_counter()
        try:
            library = compiled_library(cg.dump().encode(), f"calibration_{self.definition.identifier}", CFLAGS)
        except RuntimeError:
            library = None
        self.compile_seconds += time.perf_counter() - started
        if library is None:
            self.source = "CasADi's virtual machine"
            return [_Interpreted(fn) for fn in fns]
        return [_Compiled(library, fn) for fn in fns]

    def _run(self, fn, arguments: list) -> list:
        """``fn`` on each segment's arguments, ``workers`` segments at a time
        (threads: a compiled call releases the interpreter's lock)."""
        if self.workers > 1 and len(arguments) > 1:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(self.workers) as pool:
                return list(pool.map(fn, arguments))
        return [fn(a) for a in arguments]

    # ---- what the solver asks --------------------------------------------------------------------

    def _failed(self, s) -> FmuCallError:
        return FmuCallError(self.model.cs.name, self.model.cs.path,
                            f"a state is not finite in the segment from t = {self.model.times[s.first]:g} s")

    def _trajectory(self, s, x_rows: np.ndarray, y_rows: np.ndarray) -> Trajectory:
        n_rows = s.last - s.first
        steps = n_rows if s.last < self.model.times.size else n_rows - 1
        states = x_rows[:steps + 1]
        outputs = np.column_stack([x_rows[:n_rows, j] if where == "x" else y_rows[:n_rows, j]
                                   for where, j in self.out_from])
        return Trajectory(states, outputs)

    def simulate(self, theta: np.ndarray, segments, x0: np.ndarray) -> list:
        """Each segment's :class:`~cosim.calibration.model.Trajectory` (or the
        :class:`~cosim.errors.FmuCallError` of a state that is not finite)."""
        n, args = self._arguments(theta, segments, x0)
        start, chunk = self._function("start", n, 0), self._function("simulate", n, 0)

        def one(a):
            params, T, U, DT = a
            x = start((params, np.zeros((0, params.size))))[0].ravel()
            xs, ys = [x[None]], []
            with np.errstate(all="ignore"):
                for c in range(0, T.size, CHUNK):
                    X, Y = chunk((xs[-1][-1], params, T[c:c + CHUNK], U[c:c + CHUNK], DT[c:c + CHUNK]))
                    xs.append(X)
                    ys.append(Y)
            return np.concatenate(xs), np.concatenate(ys)

        out = []
        for s, (X, Y) in zip(segments, self._run(one, args)):
            tr = self._trajectory(s, X, Y)
            out.append(tr if np.isfinite(tr.states).all() and np.isfinite(tr.outputs).all() else self._failed(s))
        return out

    def sensitivities(self, theta: np.ndarray, segments, x0: np.ndarray, estimated: np.ndarray,
                      coarse: bool = False) -> list:
        """Each segment's ``(dY, dX_end)`` as
        :func:`~cosim.calibration.sensitivity.segment_sensitivities` gives
        them (unknowns: the fitted names, then the estimated initial states),
        here the trajectory's exact derivatives; ``coarse``: those of one RK4
        step a row instead of the FMU's ``n`` (the solver's first iterations:
        a Jacobian within ``O(dt^4)`` at ``1/n`` of the cost)."""
        m = self.model
        nt, est = len(m.problem.fit), np.flatnonzero(estimated)
        nd = nt + est.size
        n, args = self._arguments(theta, segments, x0)
        Pd = np.zeros((len(self.p_names), nd))
        Ud = np.zeros((len(self.u_names), nd))
        Pd[self.p_fit, np.arange(self.p_fit.size)] = 1.0
        Ud[self.u_fit, m.n_params + np.arange(self.u_fit.size)] = 1.0
        Pd[self.p_setter[est], nt + np.arange(est.size)] = 1.0
        # the compiled chunk takes DIRECTIONS of them a call (one library whatever the fitted names: below), the
        # last call's padded with zero directions
        g = nd if self.directions is None else self.directions
        padded = -(-nd // g) * g
        Pd, Ud = (np.vstack([a.T, np.zeros((padded - nd, a.shape[0]))]) for a in (Pd, Ud))  # column-major
        groups = [slice(i, i + g) for i in range(0, padded, g)]
        kind = "coarse" if coarse else "sensitivities"
        start = self._function("start", n, nd)
        chunk = self._function(kind, n, g)

        def one(a):
            params, T, U, DT = a
            x, S = start((params, Pd[:nd]))  # S: nd x nx (column-major nx x nd)
            S = np.vstack([S, np.zeros((padded - nd, S.shape[1]))])
            xs = [x.ravel()] * len(groups)  # each group's own (the same) trajectory
            Ss, dys = [S[None]], []
            with np.errstate(all="ignore"):
                for c in range(0, T.size, CHUNK):
                    dX, dY = np.empty((CHUNK, padded, S.shape[1])), []
                    for k, sl in enumerate(groups):
                        X, dXg, _, dYg = chunk((xs[k], Ss[-1][-1][sl], params, Pd[sl], Ud[sl], T[c:c + CHUNK],
                                                U[c:c + CHUNK], DT[c:c + CHUNK]))
                        dX[:, sl] = dXg.reshape(CHUNK, g, -1)
                        dY.append(dYg.reshape(CHUNK, g, -1))
                        xs[k] = X[-1]
                    Ss.append(dX)
                    dys.append(np.concatenate(dY, axis=1))
            # rows x states x unknowns; rows x unknowns x outputs
            return np.concatenate(Ss)[:, :nd].transpose(0, 2, 1), np.concatenate(dys)[:, :nd]

        out = []
        for s, (S, dYr) in zip(segments, self._run(one, args)):
            n_rows = s.last - s.first
            dy = np.stack([S[:n_rows, j] if where == "x" else dYr[:n_rows, :, j] for where, j in self.out_from],
                          axis=1)
            steps = n_rows if s.last < m.times.size else n_rows - 1
            out.append((dy, S[n_rows] if steps == n_rows else None))
        return out


class _Compiled:
    """A generated CasADi function in its compiled library, called through
    ctypes on numpy arrays in place (no copies; the interpreter's lock is
    released during the call): arrays column-major, as CasADi's dense
    matrices (each array is the transpose of its matrix)."""

    def __init__(self, library, fn):
        import ctypes

        self.ctypes = ctypes
        self.lib = ctypes.CDLL(str(library))
        name = fn.name()
        self.call = getattr(self.lib, name)
        sizes = [ctypes.c_longlong() for _ in range(4)]
        getattr(self.lib, f"{name}_work")(*map(ctypes.byref, sizes))
        self.n_arg, self.n_res, self.n_iw, self.n_w = (v.value for v in sizes)
        self.out_shapes = [(fn.size2_out(i), fn.size1_out(i)) for i in range(fn.n_out())]
        for suffix in ("incref",):
            if hasattr(self.lib, f"{name}_{suffix}"):
                getattr(self.lib, f"{name}_{suffix}")()

    def __call__(self, arguments) -> list:
        ctypes = self.ctypes
        P = ctypes.c_void_p
        ins = [np.ascontiguousarray(a, dtype=float) for a in arguments]
        outs = [np.empty(shape) for shape in self.out_shapes]
        arg = (P * max(self.n_arg, len(ins)))(*[a.ctypes.data for a in ins])
        res = (P * max(self.n_res, len(outs)))(*[o.ctypes.data for o in outs])
        iw = np.zeros(max(self.n_iw, 1), dtype=np.int64)
        w = np.zeros(max(self.n_w, 1))
        status = self.call(arg, res, P(iw.ctypes.data), P(w.ctypes.data), 0)
        if status:
            raise RuntimeError(f"the compiled calibration function returned {status}")
        return outs


class _Interpreted:
    """The same function run by CasADi's virtual machine (no C compiler): same arrays in and out."""

    def __init__(self, fn):
        import threading

        self.fn = fn
        self.lock = threading.Lock()  # one call at a time: the segments' threads share it

    def __call__(self, arguments) -> list:
        ins = [np.asarray(a, dtype=float).T for a in arguments]
        with self.lock:
            outs = self.fn(*ins)
        return [np.asarray(o).T.copy() for o in outs]
