"""What the engine keeps in the registered cache folder
(:func:`cosim.scenario.registry.register_cache`): JSON data, written whole, read as
data (never pickle: a cache folder is a place others may write,
docs/security.md), each entry kept only while what it was derived from is
unchanged.

Four entries use it: the installed plugins (:mod:`cosim.scenario.registry`),
validated scenarios and the parse of scenario files
(:func:`cosim.scenario.definition.load_scenario`) and what was read of FMU files
(:mod:`cosim.fmi.description_cache`). Which folder is this
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
    different one is refused (:func:`cosim.scenario.registry.register_cache` is
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


_SEEN: dict[str, tuple[int, int]] = {}  # a loaded module's file -> its size and mtime when first listed
_LISTED: tuple[tuple[Any, ...], list[tuple[str, int, int]]] = ((), [])  # the modules last listed, and their list


def code_files() -> list[list[Any]]:
    """The file of every module loaded now, with its size and modification
    time (ns): the code a result derived now may depend on, whatever
    package it is in (Python's own bytecode cache trusts a source's size and
    modification time the same way, to the second).

    A file is looked at once per process, as :func:`code_unchanged` checks
    a list once (its module is loaded, and runs as read whatever the file
    becomes), and the list is made again only when the loaded modules
    changed: a test process with SciPy, matplotlib and python-control loaded
    has ~1600 files, 13 ms of CPU for every validated scenario kept."""
    return [list(entry) for entry in _listed()]


def _listed() -> list[tuple[str, int, int]]:
    """:func:`code_files`, as tuples, the list itself."""
    global _LISTED
    modules = tuple(sys.modules.values())
    if modules != _LISTED[0]:  # modules compare by identity
        listed = []
        for path in sorted({getattr(m, "__file__", None) or "" for m in modules} - {""}):
            seen = _SEEN.get(path)
            if seen is None:
                try:
                    stat = os.stat(path)
                except OSError:
                    continue
                seen = _SEEN[path] = (stat.st_size, stat.st_mtime_ns)
            listed.append((path, *seen))
        _LISTED = (modules, listed)
    return _LISTED[1]


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
    files = _listed()
    key = (str(folder), tuple(path for path, _, _ in files))  # their sizes and times are the first seen (code_files)
    digest = _KEPT_CODE.get(key)
    if digest is None:
        digest = hashlib.sha256(json.dumps(files).encode()).hexdigest()[:32]
        path = folder / "code" / f"{digest}.json"
        if not path.exists():
            keep(path, files)
        _KEPT_CODE[key] = digest
    return digest


_KEPT_CODE: dict[tuple[str, tuple[str, ...]], str] = {}  # (folder, the files listed) -> their digest, kept


_UNCHANGED: dict[str, bool] = {}  # digest -> checked in this process (its modules are loaded: they stay as read)


def code_unchanged(folder: Path, digest: Any) -> bool:
    """Whether the code list kept under ``digest`` (:func:`keep_code`) is
    unchanged (:func:`unchanged`)."""
    if not isinstance(digest, str) or not digest.isalnum():
        return False
    if digest not in _UNCHANGED:
        _UNCHANGED[digest] = unchanged(kept(folder / "code" / f"{digest}.json"))
    return _UNCHANGED[digest]
