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

import re
from typing import Iterable, Mapping

from .errors import ConnectionCheckError, shown_text

__all__ = ["arrows_of", "split_endpoint", "split_top", "find_top", "partition_top", "top_groups", "is_name", "array_element", "resolve",
           "nearest", "nearest_told", "base_variable", "split_variable"]

# FMI 2.0 section 2.2.9: B-name := nondigit {digit|nondigit} | Q-name; arrayIndices := unsignedInteger {"," ...}
_B_NAME = r"(?:[A-Za-z_][A-Za-z0-9_]*|'(?:[^'\\]|\\.)+')"
_INDICES = r"(?:\[\s*[0-9]+\s*(?:,\s*[0-9]+\s*)*\])"
_IDENTIFIER = rf"{_B_NAME}{_INDICES}?(?:\.{_B_NAME}{_INDICES}?)*"
_IDENTIFIER_RE = re.compile(_IDENTIFIER)
_DER_RE = re.compile(r"der\((.*?)(?:,\s*[0-9]+\s*)?\)")

_OPEN, _CLOSE = "[(", "])"


def _scan(text: str):
    """``(index, character, depth)`` for each character of ``text`` outside a
    quoted Q-name (``'...'`` with ``\\'`` escapes, FMI 2.0 §2.2.9); depth
    counts the brackets and parentheses open before it."""
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
    quotes, brackets and parentheses; -1 if there is none."""
    return next((i for i, ch, depth in _scan(text) if ch == sep and depth == 0), -1)


def partition_top(text: str, sep: str) -> tuple[str, str, str]:
    """``str.partition`` at the first ``sep`` outside quotes, brackets and
    parentheses: ``"'a=b'=1"`` -> ``("'a=b'", "=", "1")``; ``(text, "", "")``
    when there is none."""
    cut = find_top(text, sep)
    return (text[:cut], sep, text[cut + 1:]) if cut >= 0 else (text, "", "")


def arrows_of(text: str) -> list[int]:
    """Where ``->`` stands in ``text`` outside quoted names (``'a->b'`` is a name)."""
    return [i for i, ch, _ in _scan(text) if ch == "-" and text.startswith("->", i)]


def split_top(text: str, sep: str) -> list[str]:
    """``text`` split at each ``sep`` outside quotes, brackets and
    parentheses: ``"x[1,2],'a,b'"`` -> ``["x[1,2]", "'a,b'"]``."""
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
    """``(start, end)`` of each ``{...}`` group of ``text`` outside quotes
    (the indices of its braces; a group may stand in an index, ``u[{1,2}]``)."""
    groups, start = [], None
    for i, ch, _ in _scan(text):
        if ch == "{" and start is None:
            start = i
        elif ch == "}" and start is not None:
            groups.append((start, i))
            start = None
    return groups


def is_name(name: str) -> bool:
    """Whether ``name`` is a structured FMI name (FMI 2.0 section 2.2.9:
    ``x``, ``a.b[2,3]``, ``der(x[1])``, ``der(x,2)``, ``'x y'.z``). Names of
    the flat convention (any string) are variables too: :func:`resolve`
    matches them exactly; this grammar only decides what an index is."""
    der = _DER_RE.fullmatch(name)
    return is_name(der[1]) if der else _IDENTIFIER_RE.fullmatch(name) is not None


def array_element(name: str) -> tuple[str, tuple[int, ...]] | None:
    """``"y[2]"`` -> ``("y", (2,))``, ``"a.A[1,2]"`` -> ``("a.A", (1, 2))``:
    the array and the 1-based index a name's trailing ``[...]`` (outside
    quotes) names as an FMI 3.0 array element; ``None`` if it has none."""
    if not name.endswith("]"):
        return None
    opens = [i for i, ch, depth in _scan(name) if ch == "[" and depth == 0]
    if not opens or opens[-1] == 0:
        return None
    base, index = name[:opens[-1]], name[opens[-1] + 1:-1]
    try:
        return base, tuple(int(i) for i in index.split(","))
    except ValueError:
        return None


def nearest(reference: str, names: Iterable[str], n: int = 5) -> list[str]:
    """The names most like ``reference``: the elements ``reference[...]`` of
    an FMI 2.0 array written as scalars first, then
    :func:`difflib.get_close_matches`."""
    names = list(names)
    elements = [m for m in names if m.startswith(reference + "[")]
    import difflib  # only when a name matched nothing: a run's start-up loads none

    return (elements + [m for m in difflib.get_close_matches(reference, names, n=n, cutoff=0.5)
                        if m not in elements])[:n]


def nearest_told(reference: str, names: Iterable[str]) -> str:
    """``"; nearest: a, b"``, the names most like ``reference``, for the end
    of a refusal (empty when none is near)."""
    close = nearest(reference, names)
    return f"; nearest: {_shown_names(close)}" if close else ""


def _shown_names(names: list[str], limit: int = 10) -> str:
    shown = ", ".join(shown_text(n, 60) for n in names[:limit])
    return shown + (f", ... ({len(names)} in all)" if len(names) > limit else "")


def resolve(reference: str, shapes: Mapping[str, tuple[int, ...]], where: str, owner: str,
            kind: str = "variable", error: type[Exception] = ConnectionCheckError) -> tuple[str, tuple[int, ...] | None]:
    """``(variable, index)`` a user's ``reference`` names among ``shapes``
    (``owner``'s variable names -> array shape, ``()`` for a scalar): the
    variable of that very name first (an FMI 2.0 scalar named ``x[1]`` is that
    variable, ``index`` None), else the element ``index`` (1-based,
    row-major, FMI 3.0 section 2.4.6.1) of an array variable ``y`` that
    ``y[i,...]`` names; else one line, ``where: owner has no kind 'reference';
    nearest: ...``, raised as ``error``."""
    if reference in shapes:
        return reference, None
    element = array_element(reference)
    if element is not None and shapes.get(element[0]):
        base, index = element
        shape = shapes[base]
        if len(index) == len(shape) and all(1 <= i <= k for i, k in zip(index, shape)):
            return base, index
        raise error(f"{where}: index {list(index)} outside {base}'s shape {tuple(shape)} (indices count from 1)")
    close = nearest(reference, shapes)
    told = f"nearest: {_shown_names(close)}" if close else f"it has: {_shown_names(list(shapes))}"
    raise error(f"{where}: {owner} has no {kind} {shown_text(repr(reference))}; {told}")


def base_variable(name: str, known: Iterable[str] | Mapping[str, object]) -> str:
    """The variable a signal name belongs to: ``name`` itself if it is one
    of ``known`` (an FMI 2.0 scalar ``x[1]``), else the array whose element it
    names (``y[2]`` -> ``y``), else ``name``."""
    if name in known:
        return name
    element = array_element(name)
    return element[0] if element is not None else name


def split_variable(text: str, variables: Iterable[str] | Mapping[str, object]) -> tuple[str, str] | None:
    """``(prefix, variable)`` of ``"prefix.variable"`` where ``variable`` is
    one of ``variables`` (its names may hold dots, ``a.b[2]``; the shortest
    prefix wins: a results column ``SuT.mass.x`` of the variable ``x`` of
    ``SuT.mass`` when ``mass.x`` is no variable); ``None`` if none is."""
    for i, ch in enumerate(text):
        if ch == "." and i and text[i + 1:] in variables:
            return text[:i], text[i + 1:]
    return None
