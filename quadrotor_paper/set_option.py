"""``--set KEY=VALUE``: dotted scenario keys and their values, read once for
every ``fnn-cosim`` command that takes them (``quadrotor_paper.cli``, its
``calibrate``, and ``quadrotor_paper.stability.cli`` alike)."""
from __future__ import annotations

from typing import Any, Sequence

__all__ = ["overrides"]


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
