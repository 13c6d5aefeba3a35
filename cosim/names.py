"""Variable names as FMI writes them, and the one place that parses them.

FMI 2.0 §2.2.9 ("Variable Naming Conventions", ``variableNamingConvention =
"structured"``) names a variable::

    name       := identifier | "der(" name ["," unsignedInteger] ")"
    identifier := B-name ["[" arrayIndices "]"] {"." B-name ["[" arrayIndices "]"]}
    B-name     := nondigit {digit | nondigit} | Q-name
    Q-name     := "'" (Q-char | escape) {Q-char | escape} "'"

so ``x[1]``, ``a.b[2,3]``, ``der(x[1])`` and ``'x y'.z`` are names of one
scalar each (FMI 3.0 §2.4.7.5 keeps the grammar). A user's reference is
resolved against the component's own variable list first; only a name that is
no variable there is read as an element ``y[2]`` of an FMI 3.0 array ``y``
(1-based, row-major). A reference that is neither is refused naming the
nearest names (:func:`resolve`).

An endpoint ``instance.variable`` splits at the longest known instance name
(instance names may hold dots: an SSP archive's nested systems are flattened
to ``SuT.edrive_mass``), else at the first dot outside brackets, quotes and
parentheses (:func:`split_endpoint`).
"""
from __future__ import annotations

from typing import Iterable

__all__ = ["split_endpoint", "split_top", "find_top", "top_groups"]

_OPEN, _CLOSE = "[({", "])}"


def _scan(text: str):
    """``(index, character, depth)`` for each character of ``text`` outside a
    quoted Q-name (``'...'`` with ``\\'`` escapes, FMI 2.0 §2.2.9); depth
    counts the brackets, parentheses and braces open before it."""
    depth, quoted, escaped = 0, False, False
    for i, ch in enumerate(text):
        if quoted:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == "'":
                quoted = False
            continue
        if ch == "'":
            quoted = True
            continue
        if ch in _CLOSE:
            depth = max(depth - 1, 0)
        yield i, ch, depth
        if ch in _OPEN:
            depth += 1


def find_top(text: str, sep: str) -> int:
    """The index of the first ``sep`` (one character) in ``text`` outside
    quotes, brackets, parentheses and braces; -1 if there is none."""
    return next((i for i, ch, depth in _scan(text) if ch == sep and depth == 0), -1)


def split_top(text: str, sep: str) -> list[str]:
    """``text`` split at each ``sep`` outside quotes, brackets, parentheses
    and braces: ``"x[1,2],'a,b'"`` -> ``["x[1,2]", "'a,b'"]``."""
    cuts = [i for i, ch, depth in _scan(text) if ch == sep and depth == 0]
    return [text[a + 1:b] for a, b in zip([-1] + cuts, cuts + [len(text)])]


def split_endpoint(text: str, instances: Iterable[str] = ()) -> tuple[str, str] | None:
    """``"instance.variable"`` -> ``(instance, variable)``: at the longest of
    ``instances`` that ``text`` starts with (followed by a dot), else at the
    first dot outside quotes, brackets and parentheses; ``None`` when there
    is no such dot or either side is empty."""
    for name in sorted(instances, key=len, reverse=True):
        if len(text) > len(name) + 1 and text.startswith(name) and text[len(name)] == ".":
            return name, text[len(name) + 1:]
    cut = find_top(text, ".")
    if cut <= 0 or cut == len(text) - 1:
        return None
    return text[:cut], text[cut + 1:]


def top_groups(text: str) -> list[tuple[int, int]]:
    """``(start, end)`` of each ``{...}`` group of ``text`` outside quotes and
    brackets (the indices of its braces)."""
    groups, start = [], None
    for i, ch, depth in _scan(text):
        if ch == "{" and depth == 0:
            start = i
        elif ch == "}" and depth == 0 and start is not None:
            groups.append((start, i))
            start = None
    return groups
