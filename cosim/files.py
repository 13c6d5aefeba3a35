"""Files users give and folders results go to, handled in one place.

A scenario, a study, a learned state, an SSP archive: a file from anyone is
data (``docs/security.md``). Reading one refuses in one line what is not a
regular file of reasonable size in UTF-8 (a folder, ``/dev/zero``, a FIFO,
a 1 GB "scenario", bytes that are no text, integers of thousands of digits,
nesting deep enough to exhaust the interpreter); an output folder or file is
checked before anything runs, so a run is never lost for want of a place to
write it; a name taken from a file becomes one path component.
"""
from __future__ import annotations

import json
import os
import posixpath
import re
import shutil
import stat
import tomllib
import zipfile
from pathlib import Path
from typing import Any, Iterable

from .errors import ScenarioError, one_line
from .limits import MAX_ARCHIVE_BYTES, MAX_DOCUMENT_BYTES, MAX_ENTRY_BYTES, MAX_RATIO

__all__ = ["regular_file", "read_text", "read_toml", "read_json", "write_json", "is_ssp", "SSD_NAME", "safe_name", "output_folder", "output_file",
           "zip_members", "extract_zip"]



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
    """A TOML file as a mapping, or a one-line :class:`ScenarioError` naming the file and the fault."""
    text = read_text(path, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {one_line(str(exc))}") from None
    except (ValueError, RecursionError) as exc:  # an integer of thousands of digits, nesting without end
        raise ScenarioError(f"{path}: not a document this tool reads: {one_line(str(exc))[:200]}") from None


def read_json(path: str | Path, what: str) -> Any:
    """A JSON file as Python data, or a one-line :class:`ScenarioError`."""
    text = read_text(path, what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ScenarioError(f"{what} {str(path)!r}: not JSON ({exc.msg}, line {exc.lineno})") from None
    except (ValueError, RecursionError) as exc:
        raise ScenarioError(f"{what} {str(path)!r}: not a document this tool reads: "
                            f"{one_line(str(exc))[:200]}") from None


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


def extract_zip(path: str | Path, target: str | Path, what: str, only: set[str] | None = None) -> Path:
    """Extract the zip archive ``path`` (all its entries, or the names in
    ``only``) into the folder ``target``, checking each entry
    (:func:`zip_members`) and counting the bytes written (a header may lie);
    a corrupt archive (not a zip, a bad CRC, an unsupported compression) is
    a one-line :class:`ScenarioError`. The folder is left as it was found
    (removed if this made it) when extraction fails."""
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
                with archive.open(info) as source, open(destination, "wb") as sink:
                    while chunk := source.read(2 ** 20):
                        written += len(chunk)
                        if written > info.file_size or written > MAX_ENTRY_BYTES:
                            raise ScenarioError(f"{what}: entry {info.filename!r} is larger than its header says")
                        sink.write(chunk)
    except ScenarioError:
        if made:
            shutil.rmtree(target, ignore_errors=True)
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, RuntimeError, EOFError, OSError,
            ValueError) as exc:
        if made:
            shutil.rmtree(target, ignore_errors=True)
        raise ScenarioError(f"{what}: a broken archive ({type(exc).__name__}: {one_line(str(exc))})") from None
    return target


def write_json(path: str | Path, data: Any) -> Path:
    """``data`` as JSON at ``path``, written whole or not at all (a temporary file renamed)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(json.dumps(data, indent=1, default=_json_default))
    os.replace(tmp, path)
    return path


def _json_default(obj):
    import numpy as np

    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


SSD_NAME = "SystemStructure.ssd"  # the system structure at an SSP archive's root (the name SSP 1.0 fixes)


def is_ssp(path: str | Path) -> bool:
    """Whether ``path`` names an SSP archive for :func:`cosim.ssp.load_ssp` rather than a
    TOML scenario: a ``.ssp`` or ``.ssd`` file, or a folder holding
    ``SystemStructure.ssd`` (an extracted archive)."""
    path = Path(path)
    if path.is_dir():
        return (path / SSD_NAME).is_file()
    return path.suffix.lower() in (".ssp", ".ssd")
