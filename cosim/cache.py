"""What the engine keeps in the registered cache folder
(:func:`cosim.registry.register_cache`): JSON data, written whole, read as
data (never pickle: a cache folder is a place others may write,
docs/security.md), each entry kept only while what it was derived from is
unchanged.

Four entries use it: the installed plugins (:mod:`cosim.registry`),
validated scenarios and the parse of scenario files
(:func:`cosim.scenario.load_scenario`) and what was read of FMU files
(:mod:`cosim.description_cache`). Which folder is this
module's to hold (:func:`register_cache`, :func:`cache_folder`), so a module
below the registry reads it too. An entry that
cannot be read is derived again; a folder that cannot be written keeps
nothing: a cache is never an error.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path
from typing import Any, Callable

from .files import write_whole

__all__ = ["keep", "kept", "code_files", "unchanged", "keep_code", "code_unchanged", "register_cache", "cache_folder"]

_CACHE: list[Callable[[], Path]] = []  # at most one: where derived data may be kept


def register_cache(folder: Callable[[], Path]) -> None:
    """Where the engine may keep derived data: ``folder()`` is asked each
    time (it may follow the environment). One per process: a second,
    different one is refused (:func:`cosim.registry.register_cache` is
    this function)."""
    if _CACHE and _CACHE[0] != folder:
        raise ValueError("a cache folder is registered twice, differently")
    if not _CACHE:
        _CACHE.append(folder)


def cache_folder() -> Path | None:
    """The registered cache folder (:func:`register_cache`), or ``None``."""
    return _CACHE[0]() if _CACHE else None


def keep(path: Path, data: Any) -> None:
    """``data`` written as JSON at ``path``, whole or not at all (a parallel
    process never reads half of it)."""
    try:
        write_whole(path, json.dumps(data))  # NaN and infinities kept as Python writes them: a parameter's range
    except (OSError, TypeError, ValueError):  # no room, no right to write, data that is not JSON: nothing kept
        pass


def kept(path: Path) -> Any:
    """What :func:`keep` wrote at ``path``, or ``None`` (none yet, or not
    readable)."""
    try:
        return json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError):
        return None


def code_files() -> list[list[Any]]:
    """The file of every module loaded now, with its size and modification
    time (ns): the code a result derived now may depend on, whatever
    package it is in (Python's own bytecode cache trusts a source's size and
    modification time the same way, to the second)."""
    out = []
    for path in sorted({getattr(m, "__file__", None) or "" for m in list(sys.modules.values())} - {""}):
        try:
            stat = os.stat(path)
        except OSError:
            continue
        out.append([path, stat.st_size, stat.st_mtime_ns])
    return out


def unchanged(files: Any) -> bool:
    """Whether every file of a :func:`code_files` list still has its size
    and modification time."""
    if not isinstance(files, list):
        return False
    for entry in files:
        try:
            path, size, mtime = entry
            stat = os.stat(path)
        except (OSError, TypeError, ValueError):
            return False
        if stat.st_size != size or stat.st_mtime_ns != mtime:
            return False
    return True


def keep_code(folder: Path) -> str:
    """The :func:`code_files` of now, kept once in ``folder/code`` under
    their digest (entries derived by the same code share one list); the
    digest."""
    files = code_files()
    text = json.dumps(files)
    digest = hashlib.sha256(text.encode()).hexdigest()[:32]
    path = folder / "code" / f"{digest}.json"
    if not path.exists():
        keep(path, files)
    return digest


_UNCHANGED: dict[str, bool] = {}  # digest -> checked in this process (its modules are loaded: they stay as read)


def code_unchanged(folder: Path, digest: Any) -> bool:
    """Whether the code list kept under ``digest`` (:func:`keep_code`) is
    unchanged (:func:`unchanged`)."""
    if not isinstance(digest, str) or not digest.isalnum():
        return False
    if digest not in _UNCHANGED:
        _UNCHANGED[digest] = unchanged(kept(folder / "code" / f"{digest}.json"))
    return _UNCHANGED[digest]
