"""What an FMU component reads of an FMU file, kept in the cache folder
(:func:`cosim.cache.cache_folder`) under the file's content hash, so a
run of FMUs it has seen before parses no XML and opens no archive before
extracting it: fmpy's parse of the modelDescription (lxml, imported for it,
and the Python objects fmpy builds), the sampled-data period the FMU
declares (an annotation fmpy does not read) and the archive's entry names
(where the binary is looked for, what is extracted); and the run-time
entries of an FMU this tool built, extracted there once
(:func:`claim_extracted`). docs/cosim.md, "Start-up of a run".

The entry is JSON data (``descriptions/<sha256>.json``, written whole and
checked against its key when read by :func:`cosim.cache.read`), never pickle: decoding makes objects of fmpy's
own model-description classes only (:func:`_classes`) and sets only their
declared fields, so a file in a folder others may write can at worst
describe an FMU wrongly, as a modelDescription.xml could (docs/security.md).
The key is the file's bytes (SHA-256) with what the reading depended on:
fmpy's version, this format's, and the limits the archive was checked
against (:mod:`cosim.limits`). A file is kept only after it was read and
checked in full (:func:`cosim.fmi.fmu.read_description`), so the same
bytes give the same answer and the same refusals; a validated reading
(``validate=True``) is never served from here. An entry that cannot be read
or decoded is deleted and derived again; a cache that cannot be written
keeps nothing; both kinds are bounded and pruned by :mod:`cosim.cache`.
"""
from __future__ import annotations

import contextlib
import contextvars
import functools
import hashlib
import os
import stat
import threading
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..cache import FileMemo

__all__ = ["KeptDescription", "kept_description", "keep_description", "claim_extracted", "shared_extraction",
           "in_cache_folder"]

FORMAT = 1  # bumped when what is kept, or how, changes
MAX_HASHED_BYTES = 64 * 2 ** 20  # a larger FMU is parsed every time: hashing it would cost more than the parse


@dataclass(frozen=True)
class KeptDescription:
    """An FMU file as :class:`~cosim.fmi.fmu.FmuComponent` reads it.

    ``model_description``: fmpy's ``ModelDescription``; ``period``: whether
    the FMU declares a period annotation, and the parameter it names (the
    attribute as written, ``None`` if missing); ``names``: the archive's
    entry names."""

    model_description: Any
    period: tuple[bool, str | None]
    names: tuple[str, ...]
    digest: str = ""  # the key it is kept under (not kept itself)


@functools.cache
def _classes() -> dict[str, tuple[type, frozenset[str], bool]]:
    """fmpy's model-description classes (``attrs`` classes) by name, each
    with its fields and whether it takes no argument: the only objects an
    entry may hold, and the only attributes it may set."""
    import attrs
    import fmpy.model_description as module

    out = {}
    for name, cls in vars(module).items():
        if isinstance(cls, type) and cls.__module__ == module.__name__ and attrs.has(cls):
            fields = attrs.fields(cls)
            out[cls.__name__] = (cls, frozenset(a.name for a in fields), all(a.default is not attrs.NOTHING
                                                                             for a in fields))
    return out


_PYTHON_TYPES = {t.__name__: t for t in (float, int, bool, str, bytes)}  # ModelVariable._python_type
_MEMO = FileMemo(256)  # an FMU file -> what was read of it in this process (while its size and mtime are unchanged)


def _digest(path: Path) -> tuple[str, os.stat_result] | None:
    """The SHA-256 of the regular file ``path`` with what its reading depends
    on, and its status; ``None`` for anything else (read the usual way, whose
    refusals name it)."""
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_HASHED_BYTES:
            return None
        with open(path, "rb") as f:
            data = f.read(MAX_HASHED_BYTES + 1)
    except OSError:
        return None
    from fmpy import __version__ as fmpy_version

    from ..limits import MAX_ARCHIVE_BYTES, MAX_DOCUMENT_BYTES, MAX_ENTRY_BYTES, MAX_RATIO

    h = hashlib.sha256(data)
    h.update(f"|{FORMAT}|{fmpy_version}|{MAX_ARCHIVE_BYTES}|{MAX_DOCUMENT_BYTES}|{MAX_ENTRY_BYTES}|"
             f"{MAX_RATIO}".encode())
    return h.hexdigest(), info


def kept_description(path: Path) -> KeptDescription | None:
    """What was kept of the FMU file ``path`` (its bytes), or ``None``."""
    path = Path(path)
    try:
        info = path.stat()
    except OSError:
        return None
    memo = _MEMO.get(path, info)
    if memo is not None:
        return memo
    found = _digest(path)
    if found is None:
        return None
    from ..cache import drop, read

    data = read("descriptions", found[0])
    if data is None:
        return None
    try:
        out = KeptDescription(_decode(data["description"], _classes(), []),
                              (bool(data["period"][0]), data["period"][1]), tuple(data["names"]), found[0])
        if not (type(out.model_description) is _classes()["ModelDescription"][0]
                and isinstance(out.period[1], (str, type(None))) and all(isinstance(n, str) for n in out.names)):
            raise ValueError("not a model description")
    except (TypeError, KeyError, IndexError, ValueError, AttributeError, RecursionError):
        drop("descriptions", found[0])  # not what this module writes: never trusted, the file read again
        return None
    _MEMO.put(path, found[1], out)
    return out


def keep_description(path: Path, kept: KeptDescription) -> None:
    """Keep what was read of the FMU file ``path``, checked in full."""
    found = _digest(Path(path))
    if found is None:
        return
    from ..cache import cache_folder, write

    if cache_folder() is None:
        return
    try:
        encoded = _encode(kept.model_description, {}, _classes())
    except (TypeError, ValueError, RecursionError):  # something fmpy may hold that this format does not carry
        return
    write("descriptions", found[0], {"description": encoded, "period": list(kept.period), "names": list(kept.names)})
    _MEMO.put(path, found[1], replace(kept, digest=found[0]))


# ---- the extracted folder -------------------------------------------------------------------

_CLAIMED: set[str] = set()  # extracted folders an instance of this process loaded its library from
_CLAIM = threading.Lock()
_SHARED = contextvars.ContextVar("cosim_shared_extraction", default=False)


@contextlib.contextmanager
def shared_extraction():
    """While in this block (this thread's context), :func:`claim_extracted`
    serves a folder already claimed in this process again: every instance
    of an FMU this tool built loads the one library extracted in the cache.
    For a study's masters (:class:`cosim.study.runner.MasterCache`), which
    share its FMUs' libraries already (docs/studies.md: the FMUs this tool
    builds keep no writable global state), so that a master built after the
    first extracts nothing and removes nothing when closed."""
    token = _SHARED.set(True)
    try:
        yield
    finally:
        _SHARED.reset(token)


def in_cache_folder(path: Path) -> bool:
    """Whether ``path`` is inside the registered cache folder (an FMU this
    tool built, which :func:`claim_extracted` may serve)."""
    from ..cache import cache_folder

    folder = cache_folder()
    if folder is None:
        return False
    try:
        return Path(path).resolve().is_relative_to(Path(folder).resolve())
    except OSError:
        return False


def claim_extracted(path: Path, kept: KeptDescription, names: set[str]) -> Path | None:
    """The folder of the cache where the entries ``names`` of the FMU file
    ``path`` (kept as ``kept``) are extracted once, for all processes, under
    its content hash (``extracted/<sha256>/``, made whole by a rename), for
    the first instance of this process that asks; ``None`` (extract it for
    the instance, as before) for a file outside the cache folder (the FMUs
    this tool built: they write nothing into their folder), when no cache
    is registered, when the folder cannot be made, and for any later
    instance of this process: a library loaded from one path is one library
    for the process, and may outlive its instance (one that returned
    fmiFatal is never freed; unloading is the system's ``dlclose``), so every
    later instance loads a copy of its own, with its own global state, as
    before (a study's second run in a process starts from a fresh library,
    not from what the first left in it); within :func:`shared_extraction`,
    every instance that asks gets the folder."""
    from ..cache import LIMITS, cache_folder, note_written, used

    folder = cache_folder()
    if folder is None or not kept.digest or not in_cache_folder(path):
        return None
    target = Path(folder) / "extracted" / kept.digest
    with _CLAIM:
        if str(target) in _CLAIMED and not _SHARED.get():
            return None
        if target.is_dir():
            used(target)  # its use renewed: the least recently used go first (cosim.cache.prune)
        else:
            import shutil
            import tempfile

            from ..errors import ScenarioError
            from ..files import extract_zip

            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                made = Path(tempfile.mkdtemp(prefix=f".{kept.digest[:16]}-", dir=target.parent))
                extract_zip(path, made, "cannot extract the archive", only=names)
                try:
                    os.rename(made, target)
                except OSError:  # another process made it first (a folder is renamed onto no folder but an empty one)
                    shutil.rmtree(made, ignore_errors=True)
            except (OSError, ScenarioError):  # no room, no right to write, an entry that does not extract: as before
                return None
            if not target.is_dir():
                return None
            note_written(target.parent, sum(f.stat().st_size for f in target.rglob("*") if f.is_file()),
                         LIMITS["extracted"])
        _CLAIMED.add(str(target))
    return target


# ---- the format ------------------------------------------------------------------------------
# JSON values as they are; a list as a list; then one-key objects: {"o": [class, {field: value}]} an
# object of fmpy's classes (the fields a new one would not have), {"r": n} the n-th object again (variables
# are shared: a derivative, an output's dependencies), {"t": [...]} a tuple, {"d": {...}} a dict of
# strings, {"p": name} a Python type.

def _encode(value: Any, seen: dict[int, int], classes: dict[str, tuple[type, frozenset[str], bool]]) -> Any:
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, list):
        return [_encode(v, seen, classes) for v in value]
    if isinstance(value, tuple):
        return {"t": [_encode(v, seen, classes) for v in value]}
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise TypeError("a dict with keys other than strings")
        return {"d": {k: _encode(v, seen, classes) for k, v in value.items()}}
    if isinstance(value, type) and _PYTHON_TYPES.get(value.__name__) is value:
        return {"p": value.__name__}
    cls = type(value)
    if classes.get(cls.__name__, (None,))[0] is not cls:
        raise TypeError(f"a {cls.__name__} in a model description")
    if id(value) in seen:
        return {"r": seen[id(value)]}
    seen[id(value)] = len(seen)
    defaults = _defaults(cls) if classes[cls.__name__][2] else {}
    fields = {}
    for a in cls.__attrs_attrs__:
        v = getattr(value, a.name)
        d = defaults.get(a.name, _NONE)
        if d is _NONE or type(v) is not type(d) or v != d:  # only what differs from a new object's
            fields[a.name] = _encode(v, seen, classes)
    return {"o": [cls.__name__, fields]}


_NONE = object()


def _defaults(cls: type) -> dict[str, Any]:
    """The fields of a new ``cls()``."""
    new = cls()
    return {a.name: getattr(new, a.name) for a in cls.__attrs_attrs__}


_SCALARS = (str, float, int, bool, type(None))


def _decode(value: Any, classes: dict[str, tuple[type, frozenset[str], bool]], made: list) -> Any:
    if type(value) in _SCALARS:
        return value
    if type(value) is list:
        return [v if type(v) in _SCALARS else _decode(v, classes, made) for v in value]
    (key, body), = value.items()
    if key == "o":
        name, fields = body
        cls, names, plain = classes[name]
        # a new object holds the defaults (new lists each); a class that takes arguments has every field written
        obj = cls() if plain else object.__new__(cls)
        made.append(obj)  # before its fields: they may name it again
        if not names.issuperset(fields):
            raise ValueError(f"{name} has no field {sorted(set(fields) - names)[0]!r}")
        for field, v in fields.items():
            object.__setattr__(obj, field, v if type(v) in _SCALARS else _decode(v, classes, made))
        return obj
    if key == "r":
        return made[body]
    if key == "t":
        return tuple(_decode(v, classes, made) for v in body)
    if key == "d":
        return {k: _decode(v, classes, made) for k, v in body.items()}
    if key == "p":
        return _PYTHON_TYPES[body]
    raise ValueError(f"unknown tag {key!r}")
