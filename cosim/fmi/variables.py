"""Variable access by name and by type, a part of
:class:`cosim.fmi.fmu.FmuComponent` (:class:`VariableAccess`), for
FMI 2.0 and 3.0 (docs/cosim.md, "Signal types"): a signal name resolved to
its variable or an element of an FMI 3.0 array, the typed get and set calls
(one call per type, an array whole with ``nValues``), start values set one
by one so that a refusal names the variable, inputs set by name outside the
step loop in the mode the standard asks, and Real/Float64 values read and
set by name (a linearizer's, a calibrator's, a learned state's). The
per-step calls of the bound signals are :mod:`cosim.fmi.step`'s.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np
from fmpy.fmi1 import FMICallException

from ..component import element_of, typed_value
from .description import TYPE_OF, shape_of
from ..errors import FmuCallError

__all__ = ["VariableAccess", "takes_typed_calls", "array_start"]


def takes_typed_calls(variables: Mapping[str, Any], names) -> bool:
    """Whether values of ``names`` take the typed calls, not the one-call
    Float64 fast path: a name that is no variable of ``variables`` (an array
    element), an array, or a variable of another type than Float64."""
    return any(n not in variables or variables[n].dimensions or TYPE_OF.get(variables[n].type) != "Float64"
               for n in names)


def array_start(var, owner: str) -> list:
    """The start values of an array variable (its modelDescription's, one
    per element, row-major), the values of elements no connection sets;
    ``owner``, the instance's name, in a refusal."""
    port_type = TYPE_OF.get(var.type, var.type)
    tokens = str(var.start).split() if var.start is not None else []
    size = int(np.prod(shape_of(var))) if shape_of(var) else 1
    zero = {"String": "", "Binary": b"", "Boolean": False}.get(port_type, 0)
    values = [typed_value(port_type, t, f"{owner}.{var.name} start") for t in tokens[:size]]
    return values + [zero] * (size - len(values))


class VariableAccess:
    """Values by name and type of :class:`cosim.fmi.fmu.FmuComponent`'s
    instance (a part of that class, not used alone)."""

    def _set_start_values(self, values: Mapping[str, Any], together: bool = False) -> None:
        """Each start value by its type's set call (:meth:`_set_typed`), one by
        one, so a refusal names the variable and quotes the FMU. ``together``
        (the instance just instantiated or reset): first all of them by one
        call per type (a study's run sets about 60, and each call releases
        the GIL, which the thread then waits to take back from the study's
        other threads); when the FMU refuses that call, it is reset (out of
        whatever state the refusal left it in, FMI 2.0 §4.2.4 / FMI 3.0
        §2.3.4) and given them one by one, to name the refused one."""
        if together and len(values) > 1:
            try:
                self._set_typed(values)
                return
            except FMICallException:
                try:
                    self._slave.reset()
                except FMICallException as exc:
                    raise self._fail("reset", exc) from None
                self.messages.clear()
        for key, value in values.items():
            try:
                self._set_typed({key: value})
            except FMICallException as exc:
                what = "parameter" if self.variables[key].causality == "parameter" else "the start value of"
                raise self._fail(f"setting {what} {key} = {value!r}", exc, variable=key, value=value) from None

    def _element(self, name: str) -> tuple[object, int]:
        """``(variable, k)``: the variable a signal name is (``k`` = -1) or
        the element ``k`` (0-based, row-major) of an array it names."""
        var = self.variables.get(name)
        if var is not None:
            return var, -1
        base, index = element_of(name)
        var = self.variables.get(base)
        shape = shape_of(var) if var is not None else ()
        if var is None or index is None or len(index) != len(shape) or \
                not all(1 <= i <= k for i, k in zip(index, shape)):
            raise KeyError(f"{self.name} has no variable(s) {[name]}")
        k = 0
        for i, size in zip(index, shape):
            k = k * size + (i - 1)
        return var, k

    def _calls(self, port_type: str):
        """``(get, set)`` of the instance for values of ``port_type``: FMI 2.0
        getReal/Integer/Boolean/String (an Enumeration is an Integer), FMI
        3.0 getFloat32 .. getBinary (an Enumeration is an Int64, section
        2.2.6.1), each taking ``nValues`` for arrays."""
        s = self._slave
        if self.fmi_version == 2:
            name = {"Float64": "Real", "Int32": "Integer", "Enumeration": "Integer"}.get(port_type, port_type)
            get, set_ = getattr(s, "get" + name), getattr(s, "set" + name)
            return (lambda vrs, n: get(vrs)), set_
        name = "Int64" if port_type == "Enumeration" else port_type
        return getattr(s, "get" + name), getattr(s, "set" + name)

    def _get_typed(self, names: Sequence[str]) -> list:
        """The values of ``names`` (variables or array elements) as Python
        values (:func:`cosim.component.typed_value`), one get call per type."""
        wanted = [self._element(n) for n in names]
        by_type: dict[str, list] = {}
        for var, _ in wanted:
            group = by_type.setdefault(TYPE_OF.get(var.type, var.type), [])
            if var not in group:
                group.append(var)
        got: dict[int, list] = {}
        for port_type, variables in by_type.items():
            sizes = [int(np.prod(shape_of(v))) if v.dimensions else 1 for v in variables]
            values = self._calls(port_type)[0]([v.valueReference for v in variables], sum(sizes))
            offset = 0
            for v, size in zip(variables, sizes):
                got[id(v)] = values[offset:offset + size]
                offset += size
        out = []
        for (var, k), name in zip(wanted, names):
            value = got[id(var)][max(k, 0)]
            port_type = TYPE_OF.get(var.type, var.type)
            if isinstance(value, bytes) and port_type == "String":  # fmpy's FMI 2.0 getString
                value = value.decode("utf-8", "replace")
            elif port_type == "Binary" and value is None:
                value = b""
            elif port_type == "Enumeration" and abs(int(value)) > 2 ** 53:
                raise FmuCallError(self.name, self.path, f"Enumeration {name} = {int(value)}: beyond 2^53, no "
                                   f"double holds it exactly (the master holds an Enumeration as a double)")
            out.append(value)
        return out

    def _set_typed(self, values: Mapping[str, object]) -> None:
        """Set ``values`` (by variable or array element name) with one set
        call per type, an array whole: its elements not given keep their
        start values. A value the type cannot hold is refused in one line
        (:func:`cosim.component.typed_value`), never rounded. Numbers for
        Float64 scalars only (a start's usual values) take the one-call
        fast path, their references found once per set of names."""
        if all(type(v) is float or type(v) is int for v in values.values()):  # not a bool, a str, bytes
            refs = self._float_references(tuple(values))
            if refs is not None:
                return self.real_calls()[1](refs, [float(v) for v in values.values()])
        arrays: dict[int, list] = {}
        by_type: dict[str, dict[int, Any]] = {}  # type -> its variables by id, in the order first given
        for name, value in values.items():
            var, k = self._element(name)
            port_type = TYPE_OF.get(var.type, var.type)
            try:
                value = typed_value(port_type, value, f"{self.name}.{name}")
            except ValueError as exc:
                raise FmuCallError(self.name, self.path, str(exc), name, value) from None
            by_type.setdefault(port_type, {})[id(var)] = var
            if var.dimensions:
                if id(var) not in arrays:
                    arrays[id(var)] = array_start(var, self.name)
                if k < 0:
                    raise FmuCallError(self.name, self.path, f"{name}: an array variable is set by its elements",
                                       name, value)
                arrays[id(var)][k] = value
            else:
                arrays[id(var)] = [value]
        for port_type, variables in by_type.items():
            flat = [x for v in variables.values() for x in arrays[id(v)]]
            self._calls(port_type)[1]([v.valueReference for v in variables.values()], flat)

    def _float_references(self, names: tuple[str, ...]) -> list[int] | None:
        """The value references of ``names`` when each is a Float64 scalar
        variable, else ``None`` (:func:`takes_typed_calls`); kept per set of
        names (a study starts an FMU with the same names thousands of times;
        a few sets are kept)."""
        kept = self._float_refs
        if names not in kept:
            if len(kept) >= 16:
                kept.clear()
            kept[names] = None if takes_typed_calls(self.variables, names) else \
                [self.variables[n].valueReference for n in names]
        return kept[names]

    def set_inputs(self, values: Mapping[str, float], t: float) -> None:
        """Set some inputs by name (the slow path, outside the step loop);
        elements of arrays (``u[2]``) and values of any type (docs/cosim.md,
        "Signal types") by their typed calls."""
        if not values:
            return
        if self._tick_pending:
            self._activate_clock(t)
        vrs = self._float_references(tuple(values))
        if vrs is None:
            return self._set_values(values, t)
        set_values = lambda: self.real_calls()[1](vrs, [float(v) for v in values.values()])  # noqa: E731
        try:
            self._set_in_mode(set_values, values, t)
        except FMICallException as exc:
            shown = ", ".join(f"{n} = {float(v)!r}" for n, v in values.items())
            raise self._fail(f"setting inputs ({shown})", exc, t) from None

    def _set_values(self, values: Mapping[str, object], t: float) -> None:
        """:meth:`_set_typed`, a refusal of the FMU told with the values set."""
        try:
            self._set_in_mode(lambda: self._set_typed(values), values, t)
        except FMICallException as exc:
            shown = ", ".join(f"{n} = {v!r}" for n, v in values.items())
            raise self._fail(f"setting inputs ({shown})", exc, t) from None

    def _set_in_mode(self, setter, names, t: float) -> None:
        """``setter()`` (setting the inputs ``names``) in the mode the standard
        asks: a Model Exchange instance out of initialization sets a discrete
        input in Event Mode, followed by the event iteration (an input
        event), and a continuous one in Continuous-Time Mode, restarting
        its solver (FMI 2.0 §3.2.3, FMI 3.0 §3.2.1); any other instance at once."""
        if self.system is None or not self.system.running or self._initializing:
            return setter()
        if any(self._element(n)[0].variability != "continuous" for n in names):
            self.system.event(t, setter)
        else:
            setter()
            self.system.restart()
        self._u_set = None

    def real_calls(self):
        """``(get, set)``: the instance's calls for Real (FMI 2.0) or Float64
        (FMI 3.0) values by value references."""
        s = self._slave
        return (s.getReal, s.setReal) if self.fmi_version == 2 else (s.getFloat64, s.setFloat64)

    def _references(self, names) -> list[int]:
        missing = [n for n in names if n not in self.variables]
        if missing:
            raise KeyError(f"{self.path.name} has no variable(s) {missing}")
        return [self.variables[n].valueReference for n in names]

    def get_reals(self, names: Sequence[str], t: float | None = None) -> dict[str, float]:
        """The Real/Float64 values of ``names`` (one get; a refusal is an
        :class:`~cosim.errors.FmuCallError` quoting the FMU)."""
        names = list(names)
        if not names:
            return {}
        refs = self._references(names)
        try:
            return dict(zip(names, map(float, self.real_calls()[0](refs))))
        except FMICallException as exc:
            raise self._fail(f"getting {', '.join(names)}", exc, t) from None

    def set_reals(self, values: Mapping[str, float], t: float | None = None, where: str = "",
                  restore: bytes | None = None) -> None:
        """Set Real/Float64 variables by name, one by one so that a refusal
        (an :class:`~cosim.errors.FmuCallError`) names the variable and the
        value and quotes the FMU's reason; ``where`` says when (e.g. "in a
        restored state").

        ``restore``: a serialized FMU state the instance is in before the
        call. The values are then set in one call (a linearizer's difference
        sets about 100 per evaluation: one call per value was half of its
        time); if the FMU refuses them, that state is set back (after an
        error FMI lets an importer restart from a stored state: FMI 2.0
        section 2.1.3, FMI 3.0 section 2.2.3) and they are set one by one as
        above, so the refusal is the same one line."""
        refs = self._references(list(values))
        set_real = self.real_calls()[1]
        if restore is not None:
            try:
                set_real(refs, [float(v) for v in values.values()])
                return
            except FMICallException:
                self.restore_state(restore)  # clears the log: the error below quotes the refusal one by one
        for ref, (name, value) in zip(refs, values.items()):
            try:
                set_real([ref], [float(value)])
            except FMICallException as exc:
                raise self._fail(f"setting {name} = {value!r}{' ' + where if where else ''}", exc, t, name,
                                 value) from None
