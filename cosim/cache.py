"""The one owner of what the engine and the FMU builder keep: on disk and
in memory, each kind with its key, its invalidation, its size limit and its
pruning, and what is done with an entry that is not what was written.

On disk (docs/cosim.md, "Caches"), every kind under one folder:

* JSON entries (:func:`read`, :func:`write`): ``<folder>/<kind>/<key>.json``,
  the key a SHA-256 of everything the entry was derived from (:func:`key_of`),
  so a changed input is another key and the old entry is never read again.
  The file is one header line (this format, the full key, the SHA-256 of
  the payload) and the payload, JSON data written whole (never pickle: a
  cache folder is a place others may write, docs/security.md). An entry
  whose header does not name its key, whose payload does not match its
  digest or does not parse, or that its reader finds is not what it writes
  (:func:`drop`), is deleted and derived again: never trusted, never an error.
* Folders and binaries made by builds (the FMUs, their compiled objects,
  their extracted run-time entries, the loop's compiled libraries): content
  addressed by their makers, bounded here (:func:`prune`).

Every kind has a size limit (:data:`LIMITS`); beyond it the entries least
recently used (their modification time, renewed by :func:`used` at each use)
are removed when an entry is added (:func:`note_written`), at most once per
eighth of the limit written by a process. Which folder is this
module's to hold (:func:`register_cache`, :func:`cache_folder`), so a module
below the registry reads it too. A folder that cannot be written keeps
nothing: a cache is never an error.

In memory: the list of the modules' files below (:func:`code_files`) and
the other modules' caches, each bounded and listed with its reason in
docs/cosim.md, "Caches".
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sys
import threading
import time
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable

from .files import write_whole

__all__ = ["read", "write", "drop", "key_of", "used", "prune", "note_written", "LIMITS", "BUILDS", "library_folder", "Memo", "FileMemo",
           "code_files", "unchanged", "keep_code", "code_unchanged", "register_cache", "cache_folder"]

_CACHE: list[Callable[[], Path]] = []  # at most one: where derived data may be kept

FORMAT = 2  # bumped when the entries' header or layout changes: every older entry is then dropped as unreadable
_MAGIC = b"fnn-cosim-cache"
_MiB = 2 ** 20
LIMITS: dict[str, int] = {  # bytes per kind of entry, beyond which the least recently used go
    "plugins": 1 * _MiB,  # the installed plugins' entry points, one per sys.path (cosim.scenario.registry)
    "documents": 16 * _MiB,  # scenario files' TOML parsed, by their text (cosim.scenario.definition)
    "scenarios": 64 * _MiB,  # validated scenarios (cosim.scenario.definition)
    "code": 64 * _MiB,  # the module files a scenario was validated with (code_files, ~180 kB each)
    "descriptions": 128 * _MiB,  # what was read of FMU files (cosim.fmi.description_cache)
    "quantiles": 1 * _MiB,  # t quantiles per SciPy version (cosim.study.summary)
    "index": 8 * _MiB,  # a model's recipe -> its built FMU (fmu_models.built)
    "extracted": 1024 * _MiB,  # the run-time entries of built FMUs (cosim.fmi.description_cache.claim_extracted)
    "builds": 2048 * _MiB,  # the built FMUs, <16 hex digits>/fmi<N>/<model>.fmu (fmu_models.export.build)
    "objects": 512 * _MiB,  # their compiled C objects (fmu_models.export.build)
    "tables": 1024 * _MiB,  # signal-table FMUs, a built FMU with a recorded table (fmu_models.models.signal_table)
    "libraries": 256 * _MiB,  # the compiled loop and calibration functions (cosim.native.compiled_library)
    "fmpy-validation": 8 * _MiB,  # fmpy's verdicts on the FMUs the tests validate (tests/fmu_validation.py)
}
# A folder or binary may be loaded by another process between its look-up and its use: one used within the
# last hour is never pruned (a JSON entry removed under a reader is only a miss: no grace for them).
GRACE_S = 3600.0
BUILDS = re.compile(r"[0-9a-f]{16}")  # the FMU builds' folders, directly in the cache folder


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


def library_folder() -> Path:
    """Where compiled libraries are kept (:func:`cosim.native.compiled_library`):
    ``$COSIM_CACHE``, else ``$XDG_CACHE_HOME/cosim``, else ``~/.cache/cosim``:
    beside the user's cache rather than the registered folder, as the engine's
    own loop is compiled before, and without, any registration."""
    root = os.environ.get("COSIM_CACHE") or os.path.join(os.environ.get("XDG_CACHE_HOME")
                                                         or os.path.expanduser("~/.cache"), "cosim")
    return Path(root)


# ---- JSON entries ----------------------------------------------------------------------------

def key_of(*parts: Any) -> str:
    """The key of what is derived from ``parts`` (JSON data): their SHA-256, hex."""
    return hashlib.sha256(json.dumps(parts).encode()).hexdigest()


def _where(kind: str, key: str, folder: Path | None) -> Path | None:
    folder = cache_folder() if folder is None else folder
    if folder is None or not (isinstance(key, str) and len(key) >= 32 and key.isalnum() and key.isascii()):
        return None  # no cache, or a key that is no digest: nothing kept, nothing read
    return Path(folder) / kind / f"{key[:32]}.json"


def _header(key: str, payload: bytes) -> bytes:
    return b"%s %d %s %s\n" % (_MAGIC, FORMAT, key.encode(), hashlib.sha256(payload).hexdigest().encode())


def _parse(payload: bytes) -> Any:
    """JSON ``payload`` (orjson, a third of the time of :func:`json.loads`; a
    value orjson does not read, such as a NaN start value, by :func:`json.loads`)."""
    import orjson

    try:
        return orjson.loads(payload)
    except orjson.JSONDecodeError:
        return json.loads(payload)


def read(kind: str, key: str, folder: Path | None = None) -> Any:
    """What :func:`write` kept under ``key`` (in ``folder``, default the
    registered one), or ``None``: none kept, or an entry that is not what was
    written for this key (another key's, changed, cut short, not JSON), which
    is deleted. A hit renews the entry's use (:func:`used`)."""
    where = _where(kind, key, folder)
    if where is None:
        return None
    try:
        raw = where.read_bytes()
    except OSError:
        return None
    header, _, payload = raw.partition(b"\n")
    try:
        if header + b"\n" != _header(key, payload):
            raise ValueError("not this key's entry")
        data = _parse(payload)
    except (ValueError, RecursionError):  # orjson's and json's refusals are ValueErrors
        _remove(where)
        return None
    used(where)
    return data


def write(kind: str, key: str, data: Any, folder: Path | None = None) -> None:
    """``data`` (JSON data) kept under ``key``, whole or not at all (a parallel
    process never reads half of it); the kind pruned when due (:func:`note_written`)."""
    where = _where(kind, key, folder)
    if where is None:
        return
    try:
        payload = json.dumps(data).encode()  # NaN and infinities kept as Python writes them: a parameter's range
        write_whole(where, (_header(key, payload) + payload).decode())
    except (OSError, TypeError, ValueError, RecursionError):  # no room, no right to write, data that is not JSON
        return
    note_written(where.parent, len(payload), LIMITS[kind], grace=0.0)


def drop(kind: str, key: str, folder: Path | None = None) -> None:
    """Delete the entry under ``key``: its reader found it is not what it
    writes (a field missing, a value of another type)."""
    where = _where(kind, key, folder)
    if where is not None:
        _remove(where)


# ---- use and pruning -------------------------------------------------------------------------

def used(path: Path) -> None:
    """Renew the use of a kept entry (file or folder): its modification time,
    by which :func:`prune` orders entries."""
    try:
        os.utime(path)
    except OSError:  # gone, or not ours to touch: it will be the older
        pass


_WRITTEN: dict[str, int] = {}  # a kind's folder -> bytes this process wrote into it since it last pruned it


def note_written(folder: Path, size: int, limit: int, *, match: re.Pattern | None = None,
                 grace: float = GRACE_S) -> None:
    """``size`` bytes were added under ``folder``: prune it (:func:`prune`) at
    the first entry a process adds there, then each time it has added an
    eighth of ``limit`` more: a study that adds an entry a run scans the
    folder seldom, and the folder stays within about ``limit``."""
    written = _WRITTEN.get(str(folder))
    if written is not None and written + size < limit // 8:
        _WRITTEN[str(folder)] = written + size
        return
    _WRITTEN[str(folder)] = 0
    prune(folder, limit, match=match, grace=grace)


def _size(entry: os.DirEntry) -> int:
    if not entry.is_dir(follow_symlinks=False):
        return entry.stat(follow_symlinks=False).st_size
    total = 0
    for root, _, names in os.walk(entry.path):
        for name in names:
            try:
                total += os.lstat(os.path.join(root, name)).st_size
            except OSError:
                pass
    return total


def prune(folder: Path, limit: int, *, match: re.Pattern | None = None, grace: float = GRACE_S,
          now: float | None = None) -> None:
    """Remove the entries of ``folder`` (its files and folders whose name
    ``match`` matches in full, default every one not starting with a dot)
    least recently used first (:func:`used`) until they take at most
    ``limit`` bytes; none used within ``grace`` seconds of ``now`` (the
    clock's, unless given). A folder is renamed out of the way before it is
    deleted: no reader finds half of one."""
    try:
        with os.scandir(folder) as found:
            entries = []
            for e in found:
                if e.name.startswith(".") or (match is not None and not match.fullmatch(e.name)):
                    continue
                entries.append((e.stat(follow_symlinks=False).st_mtime, _size(e), e.name, e.is_dir(follow_symlinks=False)))
    except OSError:
        return
    total = sum(size for _, size, _, _ in entries)
    now = time.time() if now is None else now
    for mtime, size, name, is_dir in sorted(entries):
        if total <= limit:
            break
        if now - mtime < grace:
            continue
        _remove(Path(folder) / name, is_dir)
        total -= size


def _remove(path: Path, is_dir: bool = False) -> None:
    try:
        if is_dir:
            gone = path.with_name(f".{path.name}.{os.getpid()}.pruned")
            os.rename(path, gone)
            shutil.rmtree(gone, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    except OSError:  # not ours to remove, or removed by another process first
        pass


# ---- in memory ---------------------------------------------------------------------------------

class Memo:
    """Values this process derived, by a key that names all they depend on;
    at most ``bound``, the least recently used dropped first. Thread-safe."""

    def __init__(self, bound: int) -> None:
        self.bound = bound
        self._values: OrderedDict[Any, Any] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: Any) -> Any:
        """The value kept under ``key``, or ``None``."""
        with self._lock:
            value = self._values.get(key)
            if value is not None:
                self._values.move_to_end(key)
            return value

    def put(self, key: Any, value: Any) -> None:
        with self._lock:
            self._values[key] = value
            self._values.move_to_end(key)
            while len(self._values) > self.bound:
                self._values.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._values.clear()

    def __len__(self) -> int:
        return len(self._values)


class FileMemo(Memo):
    """A :class:`Memo` of what was derived from files (their bytes, their
    parse), by path: a value is valid while its file has the size and
    modification time it had (the rule Python's bytecode cache trusts)."""

    def get(self, path: Path | str, info: os.stat_result) -> Any:  # type: ignore[override]
        """The value derived from ``path`` when it had the status ``info``, or ``None``."""
        found = super().get(str(path))
        return found[2] if found is not None and found[:2] == (info.st_size, info.st_mtime_ns) else None

    def put(self, path: Path | str, info: os.stat_result, value: Any) -> None:  # type: ignore[override]
        """``value`` derived from ``path`` with the status ``info``."""
        super().put(str(path), (info.st_size, info.st_mtime_ns, value))

    def derived(self, path: Path, derive: Callable[[Path], Any]) -> Any:
        """``derive(path)``, derived again only when the file changed."""
        info = os.stat(path)
        value = self.get(path, info)
        if value is None:
            value = derive(path)
            self.put(path, info, value)
        return value


# ---- the code an entry was derived with --------------------------------------------------------

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
        digest = hashlib.sha256(json.dumps(files).encode()).hexdigest()
        if read("code", digest, folder) is None:
            write("code", digest, files, folder)
        _KEPT_CODE[key] = digest
    return digest


_KEPT_CODE: dict[tuple[str, tuple[str, ...]], str] = {}  # (folder, the files listed) -> their digest, kept


_UNCHANGED: dict[str, bool] = {}  # digest -> checked in this process (its modules are loaded: they stay as read)


def code_unchanged(folder: Path, digest: Any) -> bool:
    """Whether the code list kept under ``digest`` (:func:`keep_code`) is
    unchanged (:func:`unchanged`)."""
    if not isinstance(digest, str):
        return False
    if digest not in _UNCHANGED:
        _UNCHANGED[digest] = unchanged(read("code", digest, folder))
    return _UNCHANGED[digest]
