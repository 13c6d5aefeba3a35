"""Files users give and folders results go to, handled in one place.

A scenario, a study, a learned state, an SSP archive: a file from anyone is
data (``docs/security.md``). Reading one refuses in one line what is not a
regular file of reasonable size in UTF-8 (a folder, ``/dev/zero``, a FIFO,
a 1 GB "scenario", bytes that are no text, integers of thousands of digits,
nesting beyond ``MAX_NESTING`` levels, TOML's dates and times, an archive's
entry that does not decompress); an output folder or file is
checked before anything runs, so a run is never lost for want of a place to
write it; a name taken from a file becomes one path component.
"""
from __future__ import annotations

import datetime
import json
import math
import os
import posixpath
import re
import shutil
import stat
import threading
import zlib
from pathlib import Path
from typing import Any, Iterable

from .errors import ScenarioError, one_line, shown_text
from .limits import MAX_ARCHIVE_BYTES, MAX_DOCUMENT_BYTES, MAX_ENTRY_BYTES, MAX_NESTING, MAX_RATIO

__all__ = ["regular_file", "read_text", "read_toml", "toml_text", "toml_value", "check_document", "read_json", "json_document",
           "repeated", "given_twice", "put_once", "write_whole", "write_json", "is_ssp", "SSD_NAME", "safe_name", "output_folder",
           "not_others_results", "output_file", "room_for", "zip_members", "read_entry", "extract_zip"]


# ---- duplicates: each name given once ---------------------------------------------------------------
# A name given twice in a file (a recorded signal, a parameter binding, an SSP archive's section, a
# JSON object's key) is refused where it is read: the last one silently winning hid a mistake (z
# starting at -50 where the file also said -15), and a list of repeats grew memory with no use.

def repeated(items: Iterable[Any]) -> Any | None:
    """The first item of ``items`` that an earlier one equals (``None`` if
    none does), in one pass."""
    seen = set()
    for item in items:
        if item in seen:
            return item
        seen.add(item)
    return None


def given_twice(where: str, item: Any) -> ScenarioError:
    """The one refusal of a name given twice: ``where: 'x' is given twice; each at most once``."""
    return ScenarioError(f"{where}: {shown_text(repr(item) if isinstance(item, str) else str(item))} is given "
                         f"twice; each at most once")


def put_once(mapping: dict, key: Any, value: Any, where: str) -> None:
    """``mapping[key] = value``, refused (:func:`given_twice`) if ``key`` is there already."""
    if key in mapping:
        raise given_twice(where, key)
    mapping[key] = value


def _object_once(where: str):
    def pairs_once(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in pairs:
            put_once(out, key, value, f"{where}: key")
        return out
    return pairs_once



def regular_file(path: Path, what: str) -> os.stat_result:
    try:
        info = path.stat()
    except FileNotFoundError:
        raise ScenarioError(f"{what} {str(path)!r}: no such file") from None
    except OSError as exc:
        raise ScenarioError(f"{what} {str(path)!r}: cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise ScenarioError(f"{what} {str(path)!r}: a folder, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise ScenarioError(f"{what} {str(path)!r}: not a regular file (a device, a pipe or a socket)")
    return info


def read_text(path: str | Path, what: str = "file", limit: int = MAX_DOCUMENT_BYTES) -> str:
    """The UTF-8 text of a regular file of at most ``limit`` bytes, or a
    one-line :class:`ScenarioError` naming ``what`` and the path."""
    path = Path(path)
    if regular_file(path, what).st_size > limit:
        raise ScenarioError(f"{what} {str(path)!r}: {path.stat().st_size} bytes; at most {limit} are read")
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise ScenarioError(f"{what} {str(path)!r}: cannot be read ({exc.strerror or exc})") from None
    if len(data) > limit:  # grew since it was looked at
        raise ScenarioError(f"{what} {str(path)!r}: more than {limit} bytes; at most {limit} are read")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{what} {str(path)!r}: not UTF-8 text (byte {exc.start})") from None


def read_toml(path: str | Path, what: str = "scenario") -> dict[str, Any]:
    """A TOML file as a mapping, or a one-line :class:`ScenarioError` naming the file and the fault
    (:func:`check_document`: what a document may hold). An SSP archive
    (:func:`is_ssp`) is named as one, and the command that takes it."""
    if is_ssp(path):  # its bytes are a zip's: "not UTF-8 text (byte 11)" said nothing of use
        raise ScenarioError(f"{what} {str(path)!r}: an SSP archive, not a TOML file: `fnn-cosim run {path}` flies it "
                            f"(a study, export-ssp and linearize --scenario take a TOML scenario)")
    return toml_text(read_text(path, what), path)


def toml_text(text: str, path: str | Path) -> dict[str, Any]:
    """The document of ``text``, the TOML read from the file ``path``
    (:func:`read_toml`'s parse and checks; the one-line refusals name ``path``)."""
    import tomllib  # here: a scenario kept by the cache is not parsed again (cosim.scenario.definition.load_scenario)

    try:
        doc = _loads_toml(text, str(path), lines=True)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {one_line(str(exc))}") from None
    check_document(doc, str(path))
    return doc


def toml_value(text: str, where: str, depth: int = 0) -> Any:
    """The value ``text`` as TOML writes one (``--set KEY=VALUE``'s VALUE: a
    number, a quoted string, an array, an inline table), or ``text`` itself
    when it is no TOML value (``--set controller.form=fmu``); checked as a
    document's values are (:func:`check_document`): ``where`` names it in a
    refusal (``--set KEY``), ``depth`` is how deep in a document it goes (the
    key's parts)."""
    import tomllib

    try:
        value = _loads_toml(f"v = {text}", where, lines=False)["v"]
    except tomllib.TOMLDecodeError:
        return text
    check_document(value, where, depth)
    return value


_INT_LIMIT = re.compile(r"limit \((\d+) digits\).*has (\d+) digits")


def _loads_toml(text: str, where: str, lines: bool) -> dict[str, Any]:
    """``tomllib.loads``, its faults other than TOML syntax one line each:
    an integer beyond Python's conversion limit (no physical value has
    thousands of digits), nesting that exhausts the parser."""
    import tomllib

    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        raise
    except ValueError as exc:  # int("1" * 5000): Python's limit of digits in an int-string conversion
        found = _INT_LIMIT.search(str(exc))
        if found is None:
            raise ScenarioError(f"{where}: not a document this tool reads: {one_line(str(exc))[:200]}") from None
        limit, digits = int(found[1]), int(found[2])
        at = re.search(rf"[0-9][0-9_]{{{limit},}}", text) if lines else None
        line = f": line {text.count(chr(10), 0, at.start()) + 1}" if at else ""
        raise ScenarioError(f"{where}{line}: an integer of {digits} digits; at most {limit}") from None
    except RecursionError:
        raise ScenarioError(f"{where}: nested too deep to read; at most {MAX_NESTING} levels") from None


def _place(where: str, keys: tuple) -> str:
    """Where a value is, as a message names it: ``where``, then its key path
    (dotted, ``[i]`` for an array's item, a long one cut)."""
    if not keys:
        return where
    text = "".join(f"[{k}]" if isinstance(k, int) else ("." if i else "") + str(k) for i, k in enumerate(keys[:12]))
    return f"{where}: {shown_text(text)}" + ("..." if len(keys) > 12 else "")


def check_document(data: Any, where: str, depth: int = 0) -> None:
    """Refuse, in one line naming ``where`` and the key, what a parsed document
    (TOML, JSON) may hold that this tool reads from no file: nesting deeper
    than :data:`~cosim.limits.MAX_NESTING` levels (the keys and array items
    on the path to a value; ``data`` itself sits ``depth`` levels deep, e.g.
    the value of a ``--set`` key of that many parts), and TOML's dates and
    times (a document is JSON data: it is copied, fingerprinted and written as
    JSON). Walks without recursion."""
    deepest, path = depth, ()
    stack = [(data, (), depth)]
    while stack:
        node, at, level = stack.pop()
        if level > deepest:
            deepest, path = level, at
        if isinstance(node, dict):
            children = node.items()
        elif isinstance(node, list):
            children = enumerate(node)
        else:
            if isinstance(node, (datetime.date, datetime.time)):  # a datetime is a date too
                shown = node.isoformat()[:40]
                raise ScenarioError(f"{_place(where, at)} = {shown}: a date or time; expected a number, a string "
                                    f"(quote it: \"{shown}\"), a boolean, an array or a table")
            continue
        for key, child in children:  # a path stops growing past the limit: its depth still counts
            stack.append((child, at + (key,) if level <= MAX_NESTING else at, level + 1))
    if deepest > MAX_NESTING:
        raise ScenarioError(f"{_place(where, path)}: nested {deepest} levels deep; at most {MAX_NESTING}")


def read_json(path: str | Path, what: str) -> Any:
    """A JSON file as Python data, or a one-line :class:`ScenarioError`
    (:func:`check_document`: what a document may hold)."""
    return json_document(read_text(path, what), f"{what} {str(path)!r}")


def json_document(text: str, where: str, depth: int = 0) -> Any:
    """``text`` as JSON data (a file's, or a JSON value inside another
    document: an SSP archive's section), or a one-line :class:`ScenarioError`
    naming ``where``: not JSON, a key given twice in an object, or what
    :func:`check_document` refuses (``depth``: the levels above it)."""
    try:
        doc = json.loads(text, object_pairs_hook=_object_once(where))
    except json.JSONDecodeError as exc:
        raise ScenarioError(f"{where}: not JSON ({exc.msg}, line {exc.lineno})") from None
    except (ValueError, RecursionError) as exc:
        raise ScenarioError(f"{where}: not a document this tool reads: {one_line(str(exc))[:200]}") from None
    check_document(doc, where, depth)
    return doc


_UNSAFE = re.compile(r"[^A-Za-z0-9_.+-]+")


def safe_name(name: str, default: str = "unnamed") -> str:
    """``name`` as one path component: no separator, no ``..``, no leading
    dot (a name from a file never writes outside the folder it names a
    place in)."""
    text = _UNSAFE.sub("_", str(name)).strip("._") or default
    return text[:100]


def output_folder(path: str | Path, what: str = "--out") -> Path:
    """A folder results can be written to, made now (before anything runs)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ScenarioError(f"{what} {path}: not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".fnn-cosim-write-probe"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ScenarioError(f"{what} {path}: cannot write there ({exc.strerror or exc})") from None
    return path


def room_for(path: Path, need: int, what: str, remedy: str) -> int:
    """``need`` bytes, refused in one line if the file system of the folder
    ``path`` has less free space (disk is the user's: nothing else bounds a
    results file); ``remedy`` says how to write less."""
    free = shutil.disk_usage(path).free
    if need > free:
        raise ScenarioError(f"{what}: up to {_size(need)}; the file system of {path} has {_size(free)} free "
                            f"({remedy})")
    return need


def _size(n: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} TB"


STUDY_SIDECAR = "study.json"  # what marks a study's folder (cosim.study.run): its definition and progress
RUN_SIDECAR = "results.csv.json"  # what marks a run's folder: the sidecar of its results.csv (cosim.loop.recorder)
_MARKS = {"study": STUDY_SIDECAR, "run": RUN_SIDECAR}  # a command -> the file that says its results are there


def not_others_results(path: Path, command: str, what: str = "--out") -> Path:
    """``path``, refused if it holds another command's results (a study's
    ``study.json``, a run's ``results.csv.json``): both write
    ``summary.json``, so one would overwrite the other's, even while a study
    runs (its lock keeps out other studies only). The same command's results
    are its own to resume or replace. ``command``: ``"run"`` or ``"study"``."""
    for other, mark in _MARKS.items():
        if other != command and (path / mark).exists():
            raise ScenarioError(f"{what} {path}: holds a {other}'s results ({mark}); a {command} would overwrite "
                                f"its summary: choose another folder")
    return path


def output_file(path: str | Path, what: str) -> Path:
    """A file that can be written (its folder made, the name no folder), checked before anything runs."""
    path = Path(path)
    if path.is_dir():
        raise ScenarioError(f"{what} {path}: a folder; give the file to write")
    output_folder(path.parent if str(path.parent) else Path("."), what)
    return path


# ---- zip archives (SSP archives, FMUs) ------------------------------------------------------------



def zip_members(archive: zipfile.ZipFile, what: str) -> dict[str, zipfile.ZipInfo]:
    """The archive's entries by their normalized name, refusing one that
    would leave the folder it is extracted to (absolute, ``..``), an
    encrypted one, or one beyond the limits of size and compression ratio."""
    members = {}
    total = 0
    for info in archive.infolist():
        name = posixpath.normpath(info.filename.replace("\\", "/"))
        if info.is_dir():
            continue
        if name.startswith(("/", "../")) or name == ".." or ":" in name.split("/")[0]:
            raise ScenarioError(f"{what}: entry {info.filename!r} leaves the archive")
        if info.flag_bits & 0x1:
            raise ScenarioError(f"{what}: entry {info.filename!r} is encrypted")
        if info.file_size > MAX_ENTRY_BYTES:
            raise ScenarioError(f"{what}: entry {info.filename!r} is {info.file_size} bytes; at most "
                                f"{MAX_ENTRY_BYTES} are extracted")
        if info.file_size > MAX_RATIO * max(info.compress_size, 1) and info.file_size > 2 ** 20:
            raise ScenarioError(f"{what}: entry {info.filename!r} expands {info.file_size / max(info.compress_size, 1):.0f}"
                                f" times; at most {MAX_RATIO} (a zip bomb?)")
        total += info.file_size
        members[name] = info
    if total > MAX_ARCHIVE_BYTES:
        raise ScenarioError(f"{what}: {total} bytes uncompressed; at most {MAX_ARCHIVE_BYTES} are extracted")
    return members


def run_time_entries(names: Iterable[str]) -> set[str]:
    """The entries of an FMU an instance can use, of all its ``names``:
    all but ``sources/`` and ``documentation/``, which no FMU reads at run
    time (it finds its files under ``resources/``, its libraries under
    ``binaries/``). Leaving the C sources in the archive makes extracting
    one of ours several times faster (they carry up to 0.6 MB of them)."""
    normal = {posixpath.normpath(n.replace("\\", "/")) for n in names if not n.endswith("/")}
    return {n for n in normal if not n.startswith(("sources/", "documentation/"))}


# What reading an entry's data may raise when the data is corrupt: a bad CRC, a deflate stream that
# does not decompress (zlib's "Error -3"), data that ends early, an unsupported compression.
def _corrupt_data() -> tuple[type[BaseException], ...]:
    import zipfile  # here: only what opens an archive loads it

    return zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError, ValueError, OSError


def _corrupt(what: str, info: zipfile.ZipInfo, exc: BaseException) -> ScenarioError:
    entry = f"{what}: entry {shown_text(info.filename)!r}"
    if isinstance(exc, NotImplementedError):
        return ScenarioError(f"{entry}: a compression this tool does not read ({shown_text(str(exc), 200)})")
    kind = "zlib.error" if isinstance(exc, zlib.error) else type(exc).__name__
    return ScenarioError(f"{entry} is corrupt ({kind}: {shown_text(str(exc), 200)})")


def read_entry(archive: zipfile.ZipFile, info: zipfile.ZipInfo, what: str) -> bytes:
    """The data of one entry (already checked by :func:`zip_members`) of
    ``archive``; corrupt data is a one-line :class:`ScenarioError` naming
    ``what`` (the archive) and the entry."""
    try:
        return archive.read(info)
    except _corrupt_data() as exc:
        raise _corrupt(what, info, exc) from None


def extract_zip(path: str | Path, target: str | Path, what: str, only: set[str] | None = None) -> Path:
    """Extract the zip archive ``path`` (all its entries, or the names in
    ``only``) into the folder ``target``, checking each entry
    (:func:`zip_members`) and counting the bytes written (a header may lie);
    a corrupt archive (not a zip, an unsupported compression) or entry (a
    bad CRC, data that does not decompress) is a one-line
    :class:`ScenarioError` naming the archive, and the entry. The folder is
    left as it was found (removed if this made it) when extraction fails."""
    import zipfile

    path, target = Path(path), Path(target)
    regular_file(path, what)
    made = not target.exists()
    try:
        with zipfile.ZipFile(path) as archive:
            members = zip_members(archive, what)
            names = members if only is None else only
            for name in names:
                if name not in members:
                    raise ScenarioError(f"{what}: holds no {name!r}")
                info = members[name]
                destination = target / name
                destination.parent.mkdir(parents=True, exist_ok=True)
                written = 0
                with open(destination, "wb") as sink:
                    try:
                        with archive.open(info) as source:
                            while chunk := source.read(2 ** 20):
                                written += len(chunk)
                                if written > info.file_size or written > MAX_ENTRY_BYTES:
                                    raise ScenarioError(f"{what}: entry {info.filename!r} is larger than its header "
                                                        f"says")
                                sink.write(chunk)
                    except _corrupt_data() as exc:
                        if isinstance(exc, OSError) and exc.errno is not None:  # the disk, not the archive
                            raise
                        raise _corrupt(what, info, exc) from None
    except ScenarioError:
        if made:
            shutil.rmtree(target, ignore_errors=True)
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, RuntimeError, EOFError, OSError,
            ValueError, zlib.error) as exc:
        if made:
            shutil.rmtree(target, ignore_errors=True)
        raise ScenarioError(f"{what}: a broken archive ({type(exc).__name__}: {one_line(str(exc))})") from None
    return target


def write_whole(path: str | Path, text: str) -> Path:
    """``text`` at ``path``, written whole or not at all: a temporary file
    beside it, named for this process and thread (two writers of one path
    never share it), renamed over ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.partial")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_json(path: str | Path, data: Any) -> Path:
    """``data`` as JSON at ``path``, written whole or not at all (:func:`write_whole`)."""
    # strict JSON: a number that is not finite (an undefined metric) is null, as no JSON parser reads NaN
    return write_whole(path, json.dumps(_finite(data), indent=1, default=_json_default, allow_nan=False))


def _finite(data: Any) -> Any:
    """``data`` with every float that is not finite (NaN, infinity) as ``None``."""
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {k: _finite(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [_finite(v) for v in data]
    return data


def _json_default(obj):
    import numpy as np

    if isinstance(obj, (np.floating, np.integer)):
        return _finite(obj.item())
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


SSD_NAME = "SystemStructure.ssd"  # the system structure at an SSP archive's root (the name SSP 1.0 fixes)


def is_ssp(path: str | Path) -> bool:
    """Whether ``path`` names an SSP archive for :func:`cosim.ssp.archive.load_ssp` rather than a
    TOML scenario: a ``.ssp`` or ``.ssd`` file, or a folder holding
    ``SystemStructure.ssd`` (an extracted archive)."""
    path = Path(path)
    if path.is_dir():
        return (path / SSD_NAME).is_file()
    return path.suffix.lower() in (".ssp", ".ssd")
