"""CasADi's generated C spelled so that gcc compiles it in less time: the same
operations on the same operands, so every function computes the same doubles,
bit for bit (docs/fmi-export.md, "The generated C spelled for the compiler").

Most of gcc's time over a model's straight-line C went into branches it had
to build a control-flow graph for, one per element, not into the arithmetic:

- CasADi writes ``if_else`` (a gate's decision, a clipped command, a noise
  sample taken or not) as ``(c?x:0)``, one conditional per element: the four
  EKFs about 1500-2000 each, a sensor ~600-1000. :func:`branch_free` spells
  it as :data:`IF_ELSE_ZERO`'s ``if_else_zero(c, x)``, a mask on ``x``'s bits:
  ``x`` whole when ``c`` is not zero (NaN included, as C's ``c ? :`` has
  it), ``+0.0`` otherwise, the two results of the conditional.
- CasADi reads each input element as ``arg[i] ? arg[i][k] : 0`` and writes
  each output behind ``if (res[i] != 0)``: a null pointer means "zeros" or
  "not wanted". :func:`without_null_checks` leaves these out where no null
  pointer comes: in a function an MX step calls, every pointer is a slice of
  the work vector (unless the step's C passes a null one, which is checked);
  in an entry point, the FMU's C layer (``fmu_core.c``) passes an array of
  the instance's for every argument and result of every function it calls
  (``ModelFunction`` in ``fmu_core.h``).
"""
from __future__ import annotations

import re

__all__ = ["IF_ELSE_ZERO", "branch_free", "spelled", "without_null_checks"]

#: ``c ? x : 0`` without a branch: ``c != 0`` is what C's conditional tests (true for NaN, false for -0.0),
#: and the mask keeps x's 64 bits or none, +0.0 (the 0 the conditional converts to double)
IF_ELSE_ZERO = b"""
/* (c?x:0), the same double without a branch (fmu_models/export/spelling.py) */
static inline casadi_real if_else_zero(casadi_real c, casadi_real x) {
  union { casadi_real value; unsigned long long bits; } v = {x};
  v.bits &= -(unsigned long long)(c != 0);
  return v.value;
}
"""

_ENTRY = re.compile(rb"return (casadi_f\d+)\(arg, res, iw, w, mem\);")
_BODY = re.compile(rb"^static int (casadi_f\d+)\(const casadi_real\*\* arg.*?^}$", re.M | re.S)
_READ = re.compile(rb"=arg\[(\d+)\]\? arg\[\1\]\[(\d+)\] : 0;")
_WRITE = re.compile(rb"^(\s*)if \(res\[(\d+)\]!=0\) (res\[\2\]\[\d+\]=)", re.M)
_NULL_PASSED = re.compile(rb"(arg|res)1\[\d+\]=0;")
_SELECT = re.compile(rb"\(([A-Za-z_]\w*)\?([A-Za-z_]\w*):0\)")
_FIRST_FUNCTION = re.compile(rb"^(/\*[^\n]*\*/\n)?static int casadi_f\d+\(", re.M)  # with its comment line


def without_null_checks(c: bytes, entries: bool = False) -> bytes:
    """``c`` with the element-wise null checks of CasADi's SX functions left
    out: of the functions an MX step calls, and with ``entries`` of the entry
    points the FMU's C layer calls too (see the module docstring). When the
    step's MX code passes a null pointer to any function it calls (CasADi
    writes ``arg1[k]=0;`` or ``res1[k]=0;`` for an argument or result it
    leaves out), ``c`` as it was."""
    if _NULL_PASSED.search(c):
        return c
    kept = set() if entries else set(_ENTRY.findall(c))

    def plain(body: re.Match) -> bytes:
        if body.group(1) in kept:
            return body.group(0)
        # the replacements built by functions, not templates: Python 3.11 expands a template match by match
        # in Python (the spelling of two EKFs, a sensor and the quadrotor: 0.21 -> 0.14 CPU-s with branch_free's)
        return _WRITE.sub(_written, _READ.sub(_read, body.group(0)))

    return _BODY.sub(plain, c)


def _read(match: re.Match) -> bytes:
    """``=arg[i]? arg[i][k] : 0;`` read as ``=arg[i][k];``."""
    return b"=arg[" + match[1] + b"][" + match[2] + b"];"


def _written(match: re.Match) -> bytes:
    """``if (res[i]!=0) res[i][k]=`` written as ``res[i][k]=``, its indent kept."""
    return match[1] + match[3]


def branch_free(c: bytes) -> bytes:
    """``c`` with every ``(c?x:0)`` of two variables spelled ``if_else_zero(c,x)``
    (:data:`IF_ELSE_ZERO`, defined before the first function and its comment)."""
    c, n = _SELECT.subn(lambda m: b"if_else_zero(" + m[1] + b"," + m[2] + b")", c)  # a function: as plain's
    if n == 0:
        return c
    first = _FIRST_FUNCTION.search(c)
    return c[:first.start()] + IF_ELSE_ZERO.lstrip() + b"\n" + c[first.start():]


def spelled(c: bytes) -> bytes:
    """CasADi's generated C as the FMU compiles it: :func:`without_null_checks`
    (entry points included) and :func:`branch_free`."""
    return branch_free(without_null_checks(c, entries=True))
