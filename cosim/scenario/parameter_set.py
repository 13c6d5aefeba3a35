"""SSP parameter sets (``ssv:ParameterSet``, SSP 1.0 SystemStructureParameterValues): read.

The one reader of a parameter set's values, for an archive's inline sets and
``.ssv`` files it references (:mod:`cosim.ssp.archive`) and for a scenario's
``parameter_set`` key (:mod:`cosim.scenario.definition`); on its own so that the
scenario reads one without importing the SSP archive's reader and writer
(which imports the scenario).
"""
from __future__ import annotations

import math
from pathlib import Path

from lxml import etree

from ..errors import ScenarioError
from ..files import given_twice

__all__ = ["read_parameter_set", "parameter_set", "number", "NS"]

NS = {"ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}


def number(where: str, text: str | None, what: str) -> float:
    """``text`` as a finite float, or a one-line :class:`ScenarioError` naming ``where`` and ``what``."""
    try:
        value = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ScenarioError(f"{where}: {what} = {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ScenarioError(f"{where}: {what} = {text!r} is not a finite number")
    return value


def read_parameter_set(path: str | Path) -> dict[str, float]:
    """The values of an SSP parameter set file (``.ssv``: an
    ``ssv:ParameterSet``, e.g. ``fnn-cosim calibrate``'s ``parameters.ssv``),
    or a one-line :class:`ScenarioError` naming the file."""
    from ..files import read_text

    where = f"parameter set {str(path)!r}"
    try:
        node = etree.fromstring(read_text(path, "parameter set").encode(),
                                etree.XMLParser(resolve_entities=False, no_network=True))
    except etree.XMLSyntaxError as exc:
        raise ScenarioError(f"{where}: not XML ({exc})") from None
    return parameter_set(where, node)


def parameter_set(where: str, node: etree._Element, units: dict[str, str] | None = None) -> dict[str, float]:
    """The values of an ``ssv:ParameterSet`` (numbers only: the engine sets Float64 values); the
    ``unit`` each ``ssv:Real`` states goes into ``units`` when given (an SSP importer converts the value
    into its variable's unit: :mod:`cosim.ssp.archive`)."""
    if node.tag != f"{{{NS['ssv']}}}ParameterSet":
        raise ScenarioError(f"{where}: expected an ssv:ParameterSet, found {etree.QName(node).localname}")
    values: dict[str, float] = {}
    parameters = node.find("ssv:Parameters", NS)
    for i, parameter in enumerate(parameters if parameters is not None else [], 1):
        name = parameter.get("name")
        at = f"{where}: ssv:Parameter {name!r}" if name else f"{where}: ssv:Parameter {i}"
        if not name:
            raise ScenarioError(f"{at}: no name attribute")
        value = next(iter(parameter), None)
        kind = etree.QName(value).localname if value is not None else None
        if name in values:
            raise given_twice(f"{where}: ssv:Parameter", name)
        if kind == "Real":
            values[name] = number(at, value.get("value"), "value")
            if units is not None and value.get("unit"):
                units[name] = value.get("unit")
        elif kind == "Integer":
            whole = number(at, value.get("value"), "value")
            if whole != int(whole):
                raise ScenarioError(f"{at}: value = {value.get('value')!r} is not an integer")
            values[name] = int(whole)
        elif kind == "Boolean":
            text = value.get("value")
            if text not in ("true", "false", "1", "0"):
                raise ScenarioError(f"{at}: value = {text!r} is not a boolean")
            values[name] = 1 if text in ("true", "1") else 0
        else:
            raise ScenarioError(f"{at}: {kind or 'no value'}: only Real, Integer and Boolean values are supported")
        # a unit on the value: converted by the SSP reader (units given); a scenario's parameter_set takes
        # the value in its variable's unit
    return values
