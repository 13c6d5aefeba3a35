"""An FMU as the compiled loop calls it: the three FMI calls a failure names
(:class:`Call`) and the structure that hands one FMU instance to C
(:class:`KernelFmu`). Declared here, beside the FMU component that fills
them (:meth:`cosim.fmi.fmu.FmuComponent.kernel_entry`); the loop's own
structures and the header ``kernel.c`` is compiled with are in
:mod:`cosim.loop.kernel`."""
from __future__ import annotations

import ctypes
import enum

from ..native import F64P, I64, I64P, PTR, U32P

__all__ = ["Call", "KernelFmu", "FMU_FIELDS"]


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
    ("version", I64, "FMI 2 or 3"),
    ("component", PTR, "the fmi2Component / fmi3Instance"),
    ("set", PTR, "fmi2SetReal / fmi3SetFloat64"),
    ("get", PTR, "fmi2GetReal / fmi3GetFloat64"),
    ("step", PTR, "fmi2DoStep / fmi3DoStep"),
    ("in_vr", U32P, "value references of the bound inputs"),
    ("n_in", I64, "how many"),
    ("in_idx", I64P, "signal slots of their sources"),
    ("u", F64P, "the inputs, gathered"),
    ("out_vr", U32P, "value references of the outputs and internals read"),
    ("n_out", I64, "how many"),
    ("y", F64P, "their slots in the signal array (contiguous)"),
    ("direct", I64, "evaluated at t_n (feedthrough ordering), else its inputs are set at the exchange"),
    ("n_conv", I64, "inputs with a unit conversion (FmuBlock.converted)"),
    ("conv_idx", I64P, "their indices among the bound inputs"),
    ("conv_factor", F64P, "u = factor * source + offset"),
    ("conv_offset", F64P, ""),
    ("python", I64, "driven by Python calls (Plan.python_calls): set, get and step called even with nothing bound"),
)


class KernelFmu(ctypes.Structure):
    """One FMU as the plan binds it (cosim.plan.FmuBlock)."""

    _fields_ = [(name, kind) for name, kind, _ in FMU_FIELDS]
