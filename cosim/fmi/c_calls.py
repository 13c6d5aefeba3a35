"""An FMU as the compiled loop calls it: the three FMI calls a failure names
(:class:`Call`) and the structure that hands one FMU instance to C
(:class:`KernelFmu`). Declared here, beside the FMU component that fills
them (:meth:`cosim.fmi.fmu.FmuComponent.kernel_entry`); the loop's own
structures and the header ``kernel.c`` is compiled with are in
:mod:`cosim.loop.kernel`."""
from __future__ import annotations

import ctypes
import enum

__all__ = ["Call", "KernelFmu", "FMU_FIELDS"]

_i64, _f64, _ptr = ctypes.c_int64, ctypes.c_double, ctypes.c_void_p
_u32p, _i64p, _f64p = (ctypes.POINTER(t) for t in (ctypes.c_uint32, ctypes.c_int64, ctypes.c_double))


class Call(enum.IntEnum):
    """The loop's three FMI calls, as a failure names them."""

    SET = 0  # fmi2SetReal / fmi3SetFloat64 of the bound inputs
    GET = 1  # fmi2GetReal / fmi3GetFloat64 of the bound outputs and internals
    STEP = 2  # fmi2DoStep / fmi3DoStep

    @property
    def label(self) -> str:
        return ("set inputs", "get outputs", "doStep")[self]


# (name, ctypes type, what it is): the fields of each structure, in order
FMU_FIELDS = (
    ("version", _i64, "FMI 2 or 3"),
    ("component", _ptr, "the fmi2Component / fmi3Instance"),
    ("set", _ptr, "fmi2SetReal / fmi3SetFloat64"),
    ("get", _ptr, "fmi2GetReal / fmi3GetFloat64"),
    ("step", _ptr, "fmi2DoStep / fmi3DoStep"),
    ("in_vr", _u32p, "value references of the bound inputs"),
    ("n_in", _i64, "how many"),
    ("in_idx", _i64p, "signal slots of their sources"),
    ("u", _f64p, "the inputs, gathered"),
    ("out_vr", _u32p, "value references of the outputs and internals read"),
    ("n_out", _i64, "how many"),
    ("y", _f64p, "their slots in the signal array (contiguous)"),
    ("direct", _i64, "evaluated at t_n (feedthrough ordering), else its inputs are set at the exchange"),
    ("n_conv", _i64, "inputs with a unit conversion (FmuBlock.converted)"),
    ("conv_idx", _i64p, "their indices among the bound inputs"),
    ("conv_factor", _f64p, "u = factor * source + offset"),
    ("conv_offset", _f64p, ""),
    ("python", _i64, "driven by Python calls (Plan.python_calls): set, get and step called even with nothing bound"),
)


class KernelFmu(ctypes.Structure):
    """One FMU as the plan binds it (cosim.plan.FmuBlock)."""

    _fields_ = [(name, kind) for name, kind, _ in FMU_FIELDS]
