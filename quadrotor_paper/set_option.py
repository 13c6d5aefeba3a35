"""``--set KEY=VALUE``: dotted scenario keys and their values, read once for
every ``fnn-cosim`` command that takes them (:mod:`quadrotor_paper.commands`);
and ``NAME=VALUE`` pairs of an FMU's variables (``linearize``'s
``--parameter``, ``calibrate``'s ``--fix``)."""
from __future__ import annotations

import math
from typing import Any, Sequence

__all__ = ["overrides", "named_values"]


def overrides(pairs: Sequence[str]) -> dict[str, Any]:
    """``--set KEY=VALUE`` pairs as dotted keys and values, each checked as a
    document's key and value are (:func:`cosim.scenario.definition.dotted_key`,
    :func:`cosim.files.toml_value`): a bare word is text."""
    from cosim.errors import ScenarioError, shown_text
    from cosim.files import toml_value
    from cosim.scenario.definition import dotted_key

    from cosim.names import partition_top

    out = {}
    for pair in pairs:  # the first = outside a quoted FMI name ('a=b') ends the key
        key, eq, value = partition_top(pair, "=")
        if not eq or not key.strip():
            raise ScenarioError(f"--set {shown_text(pair)!r}: expected KEY=VALUE, e.g. --set wind.speed=5")
        key = key.strip()
        parts = dotted_key(key, f"--set {shown_text(key)!r}")
        out[key] = toml_value(value.strip(), f"--set {shown_text(key)}", len(parts))
    return out


def named_values(pairs: Sequence[str], option: str) -> dict[str, float]:
    """``NAME=VALUE`` pairs of ``option``, every value a finite number (one line otherwise)."""
    from cosim.errors import ScenarioError, shown_text
    from cosim.names import partition_top

    out = {}
    for pair in pairs:  # a variable name as FMI writes it: x[1], der(x), 'a=b' (cosim.names)
        name, eq, text = partition_top(pair, "=")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not eq or not name.strip() or not math.isfinite(value):
            raise ScenarioError(f"{option} {shown_text(pair)!r}: expected NAME=VALUE with a finite number, e.g. "
                                f"{option} m=1.2")
        out[name.strip()] = value
    return out
