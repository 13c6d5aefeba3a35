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
Int64; docs/cosim.md, "Signal types"), different shapes, different units
(where both sides declare one).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Iterable, Mapping

from .component import Port, element_of, element_ports
from .errors import ConnectionCheckError

__all__ = ["Connection", "parse_connection", "parse_connections", "check_connections", "Endpoint"]

_BRACES = re.compile(r"\{([^{}]*)\}")


@dataclass(frozen=True)
class Endpoint:
    component: str
    variable: str

    def __str__(self) -> str:
        return f"{self.component}.{self.variable}"


@dataclass(frozen=True)
class Connection:
    source: Endpoint
    destination: Endpoint

    def __str__(self) -> str:
        return f"{self.source} -> {self.destination}"


def _endpoint(text: str, whole: str) -> Endpoint:
    component, dot, variable = text.strip().partition(".")
    if not dot or not component or not variable:
        raise ConnectionCheckError(
            f"connection {whole!r}: {text.strip()!r} is not of the form Component.variable")
    return Endpoint(component, variable)


def _expand(side: str, whole: str) -> list[str]:
    groups = _BRACES.findall(side)
    if not groups:
        return [side]
    if len(groups) > 1:
        raise ConnectionCheckError(f"connection {whole!r}: at most one {{a,b,...}} group per side")
    items = [g.strip() for g in groups[0].split(",")]
    return [_BRACES.sub(lambda _, item=item: item, side, count=1) for item in items]  # no escapes in names


def parse_connection(text: str) -> list[Connection]:
    """Parse one connection string (with optional brace expansion)."""
    if not isinstance(text, str) or text.count("->") != 1:
        raise ConnectionCheckError(f"connection {text!r} must be a string 'A.out -> B.in'")
    left, right = text.split("->")
    sources, destinations = _expand(left, text), _expand(right, text)
    if len(sources) == 1 and len(destinations) > 1:  # fan-out: one output feeds every destination
        sources = sources * len(destinations)
    if len(sources) != len(destinations):
        raise ConnectionCheckError(
            f"connection {text!r}: {len(sources)} sources but {len(destinations)} destinations (a group "
            f"pairs with a group of the same size; one source may feed a group)")
    return [Connection(_endpoint(s, text), _endpoint(d, text)) for s, d in zip(sources, destinations)]


def parse_connections(texts: Iterable[str]) -> list[Connection]:
    out: list[Connection] = []
    for text in texts:
        out.extend(parse_connection(text))
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
                    known = ", ".join(p.name for p in getattr(comp, group)) or "none"
                    reason = f"does not exist (its {group} are: {known})"
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
        if out_port.unit and in_port.unit and out_port.unit != in_port.unit:
            raise ConnectionCheckError(
                f"connection {c}: unit mismatch, {c.source} is in {out_port.unit} but {c.destination} "
                f"is in {in_port.unit}")
        for e in _elements(c, out_port, in_port):
            key = str(e.destination)  # an element fed twice: also as an element and in its whole array
            if key in fed:
                raise ConnectionCheckError(f"connection {c}: {e.destination} is already fed by {fed[key]}")
            fed[key] = c
            checked.append(e)
    return checked
