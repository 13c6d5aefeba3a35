"""fmpy's FMI 2.0 and 3.0 classes, each FMI function's C signature worked out once per class.

fmpy's constructor gives every FMI function it loads from the FMU's library
its C signature (``fmpy.fmi1._FMU._loadFunctions``, fmpy 0.3): it walks the
instance's members (``inspect.getmembers``) and reads the annotations of
every ``fmi2...`` or ``fmi3...`` method (``inspect.signature``), about 1.5 ms
per instance, for an answer that depends on the class only (an FMI 2.0 or
3.0 function has the same name in every library). A run of four FMUs paid it
four times (start-up, docs/cosim.md). The classes here are fmpy's own, their
``_loadFunctions`` running fmpy's for the first instance of a class and
keeping what it set on each function (its C name, ``argnames``,
``argtypes``, ``restype``); a later instance sets the same on its own
library's functions, in the same order (a library missing a function fails
at the same name, with ctypes' own ``AttributeError``). FMI 1.0's function
names carry the model identifier, so fmpy's own classes serve FMI 1.0
(which the master does not drive). Decided: this reaches into fmpy's
``_loadFunctions`` and ``_functions`` (fmpy 0.3); they are checked on
import and when fmpy no longer has them its classes are used as they are.
"""
from __future__ import annotations

from typing import Any

from fmpy.fmi1 import _FMU
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3Slave

__all__ = ["fmpy_class"]

# fmpy class -> ((method name, C function name, argnames, argtypes, restype), ...), as its _loadFunctions set them
_SIGNATURES: dict[type, tuple[tuple[str, str, Any, Any, Any], ...]] = {}


def _load_functions(self) -> None:
    """fmpy's ``_loadFunctions`` for the first instance of a class, the kept signatures for the others."""
    base = type(self).__mro__[1]
    table = _SIGNATURES.get(base)
    if table is None:
        base._loadFunctions(self)
        _SIGNATURES[base] = tuple((name, f.__name__, f.argnames, f.argtypes, f.restype)
                                  for name, f in self._functions.items())
        return
    dll, functions = self.dll, self._functions
    for name, c_name, argnames, argtypes, restype in table:
        f = getattr(dll, c_name)
        f.argnames, f.argtypes, f.restype = argnames, argtypes, restype
        functions[name] = f


def _kept(base: type) -> type:
    # the same class name: fmpy's _loadFunctions picks the FMI version's prefix by it
    return type(base.__name__, (base,), {"_loadFunctions": _load_functions, "__module__": __name__,
                                         "__doc__": base.__doc__})


_FMPY_HAS_IT = callable(getattr(_FMU, "_loadFunctions", None))
_CLASSES = {base: (_kept(base) if _FMPY_HAS_IT else base) for base in (FMU2Slave, FMU2Model, FMU3Slave, FMU3Model)}


def fmpy_class(base: type) -> type:
    """The class to construct for fmpy's ``base`` (``FMU2Slave``, ``FMU2Model``,
    ``FMU3Slave``, ``FMU3Model``): a subclass whose signatures are worked out
    once per process."""
    return _CLASSES[base]
