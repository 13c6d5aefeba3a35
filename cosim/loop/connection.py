"""Connections between components, declared by variable name, and their check.

A connection is written ``"Source.variable -> Destination.variable"``, e.g.
``"Source.y -> Plant.u"``. One brace group per side expands
pairwise, so ``"Plant.{x,y,z} -> controller.{x,y,z}"`` is three
connections; a single source fans out to a group of destinations,
``"Source.y -> Plant.{u1,u2}"`` (two connections from one output).

An FMI 3.0 array variable is connected whole (``"A.y -> B.u"``, both of one
shape: element k to element k) or element by element (``"A.y[2] -> B.v"``,
1-based, ``name[i,j]`` for a matrix, row-major as FMI 3.0 serializes arrays).

:func:`check_connections` runs before the first step and refuses, with a
message naming the connection, any of: an unknown component or variable, a
source that is not an output, a destination that is not an input, an input
fed twice, different types (no widening: a Boolean is no Float64, an Int32 no
Int64; docs/cosim.md, "Signal types"), different shapes, units that are not
one quantity (where both sides declare one; :mod:`cosim.fmi.units`).

Units are compared by meaning: where both are one quantity but differ by
scale or offset (``km/h`` into ``m/s``), the checked connection carries the
conversion, ``destination = factor * source + offset``. A scenario may also
write a connection as a table that states the conversion itself or marks it
unchecked (:func:`parse_connections`; ``docs/cosim.md``, "Units").
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Iterable, Mapping

from ..fmi import units
from ..component import Port, element_of, element_ports
from ..errors import ConnectionCheckError, shown_text
from ..limits import MAX_GROUP
from ..names import arrows_of, nearest_told, split_endpoint, split_top, top_groups

__all__ = ["Connection", "parse_connection", "parse_connections", "check_connections", "Endpoint", "TABLE_KEYS",
           "unit_conversion"]

@dataclass(frozen=True)
class Endpoint:
    component: str
    variable: str

    def __str__(self) -> str:
        return f"{self.component}.{self.variable}"


@dataclass(frozen=True)
class Connection:
    """``source -> destination``. ``conversion``: ``(factor, offset)``, the
    destination receives ``factor * source + offset`` (stated by the
    scenario, or found by :func:`check_connections` from the units);
    ``unchecked``: the units are not compared (the scenario says so)."""

    source: Endpoint
    destination: Endpoint
    conversion: tuple[float, float] | None = None
    unchecked: bool = False

    def __str__(self) -> str:
        return f"{self.source} -> {self.destination}"


def _endpoint(text: str, whole: str, instances: Iterable[str]) -> Endpoint:
    split = split_endpoint(text.strip(), instances)
    if split is None:
        raise ConnectionCheckError(f"connection {shown_text(repr(whole))}: {shown_text(repr(text.strip()))} is not "
                                   f"of the form Component.variable")
    return Endpoint(*split)


def _expand(side: str, whole: str) -> list[str]:
    """The endpoints a side's brace group stands for, in time linear in the
    side's length (the text around the group is joined to each item, not
    searched again per item), at most :data:`~cosim.limits.MAX_GROUP` of them.
    A group's items split at commas outside brackets and quotes
    (``A.{x[1,2],'a,b'}`` is two names; :mod:`cosim.names`)."""
    groups = top_groups(side)
    if not groups:
        return [side]
    if len(groups) > 1:
        raise ConnectionCheckError(f"connection {shown_text(repr(whole))}: at most one {{a,b,...}} group per side")
    start, end = groups[0]
    items = split_top(side[start + 1:end], ",")
    if len(items) > MAX_GROUP:
        raise ConnectionCheckError(f"connection {shown_text(repr(whole))}: a group of {len(items)} "
                                   f"names; at most {MAX_GROUP}")
    before, after = side[:start], side[end + 1:]
    return [before + item.strip() + after for item in items]


def parse_connection(text: str, instances: Iterable[str] = ()) -> list[Connection]:
    """Parse one connection string (with optional brace expansion). An
    endpoint splits at the longest of ``instances`` it starts with (instance
    names may hold dots), else at its first dot outside brackets and quotes
    (:func:`cosim.names.split_endpoint`)."""
    arrows = arrows_of(text) if isinstance(text, str) else []
    if len(arrows) != 1:
        raise ConnectionCheckError(f"connection {shown_text(repr(text))} must be a string 'A.out -> B.in'")
    left, right = text[:arrows[0]], text[arrows[0] + 2:]
    sources, destinations = _expand(left, text), _expand(right, text)
    if len(sources) == 1 and len(destinations) > 1:  # fan-out: one output feeds every destination
        sources = sources * len(destinations)
    if len(sources) != len(destinations):
        raise ConnectionCheckError(
            f"connection {shown_text(repr(text))}: {len(sources)} sources but {len(destinations)} destinations (a group "
            f"pairs with a group of the same size; one source may feed a group)")
    instances = tuple(instances)
    return [Connection(_endpoint(s, text, instances), _endpoint(d, text, instances))
            for s, d in zip(sources, destinations)]


# the keys of a connection written as a table (validated by the scenario's schema, cosim.scenario.definition.ConnectionTable)
TABLE_KEYS = ("connect", "factor", "offset", "units")


def _from_table(entry: Mapping[str, Any], instances: Iterable[str]) -> list[Connection]:
    """A connection table: ``connect`` (the string), and either a conversion
    (``factor``, ``offset``: destination = factor * source + offset) or
    ``units = "unchecked"``."""
    converts = "factor" in entry or "offset" in entry
    if (set(entry) - set(TABLE_KEYS) or "connect" not in entry or entry.get("units", "unchecked") != "unchecked"
            or converts == ("units" in entry)):
        raise ConnectionCheckError(f"connection {shown_text(repr(dict(entry)))}: expected 'connect' and either a conversion "
                                   f"(factor, offset) or units = 'unchecked'")
    conversion = (float(entry.get("factor", 1.0)), float(entry.get("offset", 0.0))) if converts else None
    unchecked = "units" in entry
    return [replace(c, conversion=conversion, unchecked=unchecked) for c in parse_connection(entry["connect"], instances)]


def parse_connections(texts: Iterable[str | Mapping[str, Any]], instances: Iterable[str] = ()) -> list[Connection]:
    """Parse connection strings, and tables (:data:`TABLE_KEYS`) that add a
    conversion or the unchecked marker to the connections of their ``connect``;
    ``instances``: the scenario's instance names (:func:`parse_connection`)."""
    out: list[Connection] = []
    instances = tuple(instances)
    for text in texts:
        out.extend(_from_table(text, instances) if isinstance(text, Mapping) else parse_connection(text, instances))
    return out


def _find(ports: tuple[Port, ...], name: str) -> Port | None:
    """The port ``name`` (a scalar or a whole array), or the element port
    ``name[i]`` of an array port; ``None`` if there is none."""
    for p in ports:
        if p.name == name:
            return p
    base, index = element_of(name)
    if index is not None:
        for p in ports:
            if p.name == base and p.shape:
                return next((e for e in element_ports((p,)) if e.name == name), None)
    return None


def _elements(c: Connection, out_port: Port, in_port: Port) -> list[Connection]:
    """A whole-array connection as its element connections (element k to
    element k, each keeping whatever else the connection carries); a scalar
    one as itself."""
    if not out_port.shape:
        return [c]
    return [replace(c, source=Endpoint(c.source.component, a.name),
                    destination=Endpoint(c.destination.component, b.name))
            for a, b in zip(element_ports((out_port,)), element_ports((in_port,)))]


def unit_conversion(c: Connection, out_port: Port, in_port: Port) -> tuple[float, float] | None:
    """The conversion connection ``c`` needs from ``out_port``'s unit to
    ``in_port``'s (:func:`cosim.fmi.units.conversion`, each unit by its port's
    definition, else by its name), ``None`` when none is needed (one unit,
    or a side that declares none); a one-line error naming both units and
    the two ways out when they are not one quantity."""
    if not out_port.unit or not in_port.unit:
        return None
    if out_port.unit_definition is None and in_port.unit_definition is None and out_port.unit == in_port.unit:
        return None  # one name, defined nowhere: one unit (and no pint on the common path)
    source = units.unit_of(out_port.unit, out_port.unit_definition)
    destination = units.unit_of(in_port.unit, in_port.unit_definition)
    try:
        factor, offset = units.conversion(source or out_port.unit, destination or in_port.unit)
    except ConnectionCheckError as exc:
        why = str(exc).partition("not one quantity")[2]  # e.g. why Hz and rad/s are not (cosim.fmi.units.radian_dropped)
        raise ConnectionCheckError(
            f"connection {c}: unit mismatch, {c.source} is in {units.describe(out_port.unit, source)} but "
            f"{c.destination} is in {units.describe(in_port.unit, destination)}, not one quantity{why}; "
            f"state the conversion, {{ connect = \"{c}\", factor = ..., offset = ... }} "
            f"({c.destination} = factor * {c.source} + offset), or mark it "
            f"{{ connect = \"{c}\", units = \"unchecked\" }}") from None
    if source is not None and destination is not None and not source.same_quantity(destination):
        from ..notes import note  # logging loaded only for a note (tests/paper/test_run_startup.py)

        note(__name__, "connection %s: %s and %s are one unit but for the radian, which %s leaves out "
             "(docs/fmi-support.md, \"Angles\"); connected with factor %.17g", c,
             units.describe(out_port.unit, source), units.describe(in_port.unit, destination),
             out_port.unit if source.exponents[-1] == 0 else in_port.unit, factor)
    return None if (factor, offset) == (1.0, 0.0) else (factor, offset)


def check_connections(connections: Iterable[Connection], components: Mapping[str, object]) -> list[Connection]:
    """Check every connection against the components' declared ports.

    ``components`` maps a component name to an object with ``inputs`` and
    ``outputs`` (tuples of :class:`~cosim.component.Port`); FMUs additionally
    have ``variables`` (every variable of the modelDescription), which lets
    the message say *why* a name is not an output or input (e.g. "is a
    parameter"). Returns the connections as a list, a whole-array
    connection as its element connections (``A.y[1] -> B.u[1]``, ...); raises
    :class:`ConnectionCheckError` at the first wrong one.
    """
    checked: list[Connection] = []
    fed: dict[str, Connection] = {}
    for c in connections:
        ports: list[Port] = []
        for end, role, group in ((c.source, "source", "outputs"), (c.destination, "destination", "inputs")):
            comp = components.get(end.component)
            if comp is None:
                raise ConnectionCheckError(
                    f"connection {c}: unknown component {end.component!r}; components are: "
                    f"{', '.join(sorted(components))}")
            port = _find(getattr(comp, group), end.variable)
            if port is None:
                variables = getattr(comp, "variables", {})
                if end.variable in variables:
                    causality = variables[end.variable].causality
                    reason = f"is a{'n' if causality[0] in 'aeiou' else ''} {causality}, not an {group[:-1]}"
                elif _find(getattr(comp, "inputs" if group == "outputs" else "outputs"), end.variable):
                    reason = f"is an {'input' if group == 'outputs' else 'output'}, not an {group[:-1]}"
                else:
                    names = [p.name for p in getattr(comp, group)]
                    close = nearest_told(end.variable, names)
                    reason = (f"does not exist{close}" if close else
                              f"does not exist (its {group} are: {', '.join(names) or 'none'})")
                raise ConnectionCheckError(f"connection {c}: {role} {end} {reason}")
            ports.append(port)
        out_port, in_port = ports
        if out_port.type != in_port.type:
            raise ConnectionCheckError(
                f"connection {c}: type mismatch, {c.source} is {out_port.type} but {c.destination} is {in_port.type}")
        if out_port.shape != in_port.shape:
            def shape(p: Port) -> str:
                return f"an array of shape {p.shape}" if p.shape else "a scalar"
            raise ConnectionCheckError(
                f"connection {c}: shape mismatch, {c.source} is {shape(out_port)} but {c.destination} is "
                f"{shape(in_port)} (connect whole arrays of one shape, or element by element: name[1], 1-based)")
        if c.conversion is None and not c.unchecked:
            conversion = unit_conversion(c, out_port, in_port)
            if conversion is not None:
                c = replace(c, conversion=conversion)
        if c.conversion is not None and out_port.type not in ("Float64", "Float32"):
            raise ConnectionCheckError(f"connection {c}: a unit conversion is for Float signals, not "
                                       f"{out_port.type}")
        for e in _elements(c, out_port, in_port):
            key = str(e.destination)  # an element fed twice: also as an element and in its whole array
            if key in fed:
                raise ConnectionCheckError(f"connection {c}: {e.destination} is already fed by {fed[key]}")
            fed[key] = c
            checked.append(e)
    return checked
