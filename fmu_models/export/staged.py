"""A sampled model's step as a chain of functions: laws it uses again and again
compiled once and called, the rest cut into straight-line pieces between the calls.

An extended Kalman filter's step inlined is one straight-line function of
30 000-40 000 lines of C (the same scalar correction a dozen times, the same
prediction twice), which gcc compiles in 8-14 CPU-s at ``-O1``. A law called as
a CasADi function from inside an SX function (a call node) is generated once,
but the step around it stays one function in which every value live across a
call is spilled, and gcc's register allocation over it costs more than the
code it saves (measured: half the lines, the same compile time, twice the run
time). So, while a model's step is built (:func:`recording`), :func:`call`
records each call and stands for its results with placeholders;
:func:`function` then makes the step an MX function that runs, in order, one
SX function computing the next call's arguments from the step's inputs and the
results so far (its own straight-line piece of the step), the call, ..., and a
last piece computing the outputs. The generated C is each law once plus the
pieces, none with a call inside, and the pieces pass their values through the
work vector (so their null checks are left out: :mod:`fmu_models.export.spelling`).
Every operation is the one the inlined step performs, on the same operands:
the numbers are the same, bit for bit (docs/estimation.md, "The generated C").
"""
from __future__ import annotations

from contextlib import contextmanager

from ..lazy_casadi import ca

__all__ = ["call", "function", "inlining", "inlined", "recording", "value"]

_RECORDING: list | None = None  # the calls recorded while a step is built, else None
_INLINED = False  # True while a step is built whole, its laws inlined (:func:`inlined`)


@contextmanager
def inlined():
    """Build a step whole, every law inlined where it is used: the expression
    graph the step had before it was cut into pieces, for what reads its
    structure (the modelDescription's dependencies: a law called on dense
    arguments would make every entry it touches depend on every input)."""
    global _INLINED
    outer, _INLINED = _INLINED, True
    try:
        yield
    finally:
        _INLINED = outer


def inlining() -> bool:
    """True while a step is built whole (:func:`inlined`): a law is to be written inline, not called."""
    return _INLINED


@contextmanager
def recording():
    """Record the :func:`call` made while a step is built; yields their list."""
    global _RECORDING
    outer, _RECORDING = _RECORDING, []
    try:
        yield _RECORDING
    finally:
        _RECORDING = outer


def call(f, args) -> list:
    """``f(*args)``: while recording, placeholders (symbols) for its results,
    which :func:`function` binds to the call; otherwise the call itself."""
    if _RECORDING is None:
        return list(f(*args))
    results = [ca.SX.sym(f"{f.name()}_{len(_RECORDING)}_{k}", *f.size_out(k)) for k in range(f.n_out())]
    _RECORDING.append((f, [ca.SX(a) for a in args], results))
    return list(results)


def value(values) -> list:
    """``values`` computed once: while recording, placeholders bound to them
    (a cut between two of the step's pieces: the pieces after it read them
    instead of computing them again); otherwise the values themselves."""
    if _RECORDING is None:
        return list(values)
    values = [ca.densify(ca.SX(v)) for v in values]
    results = [ca.SX.sym(f"value_{len(_RECORDING)}_{k}", *v.shape) for k, v in enumerate(values)]
    _RECORDING.append((None, values, results))
    return list(results)


def function(name: str, inputs: list, outputs: list, input_names: list[str], output_names: list[str],
             calls: list) -> "ca.Function":
    """The MX function ``inputs -> outputs`` (SX symbols and expressions) with
    the recorded ``calls`` made in order: before each, one SX function
    computes its arguments (or a cut's values, :func:`value`) from the inputs
    and the results of the calls before it; after the last, one computes the
    outputs."""
    mx = [ca.MX.sym(n, s.sparsity()) for n, s in zip(input_names, inputs)]
    known_sx, known_mx = list(inputs), list(mx)
    for k, (f, args, results) in enumerate(calls):
        # an argument that is an input or an earlier result as it stands is passed on, not copied by the piece
        given = [next((j for j, s in enumerate(known_sx) if s.shape == a.shape and ca.is_equal(s, a)), None)
                 for a in args]
        computed = [a for a, j in zip(args, given) if j is None]
        values = iter(ca.Function(f"{name}_{k}", known_sx, computed).call(known_mx) if computed else [])
        values = [next(values) if j is None else known_mx[j] for j in given]
        known_sx += results
        known_mx += values if f is None else f.call(values)
    last = ca.Function(f"{name}_out", known_sx, outputs)
    return ca.Function(name, mx, last.call(known_mx), input_names, output_names)
