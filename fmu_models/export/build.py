"""Compile a model into an FMU: generated sources + generic C layer -> .fmu.

Each FMU holds its complete sources (so users on other platforms can compile
it; FMI 3.0 adds ``sources/buildDescription.xml``) and the binary for this
platform, compiled here with the system C compiler, under
``binaries/<platform>``: ``linux64`` in FMI 2.0, the platform tuple
``x86_64-linux`` in FMI 3.0.
"""
from __future__ import annotations

import hashlib
import heapq
import itertools
import os
import re
import shutil
import subprocess
import tempfile
import threading
import uuid
import zipfile
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import fmpy

from cosim.cache import BUILDS, LIMITS, FileMemo, note_written, used

from ..cache import cache_root
from .codegen import GENERIC_C_DIR, GENERIC_C_FILES, generate_sources
from .model import FmuModel
from .model_description import fmi2_model_description, fmi3_build_description, fmi3_model_description

__all__ = ["build_fmu", "cached_fmu", "FmuBuildError", "FMI_VERSIONS"]

_FMPY_HEADERS = Path(fmpy.__file__).parent / "c-code"
CFLAGS = ("-shared", "-fPIC", "-O1", "-std=gnu11", "-fvisibility=hidden", "-Wall", "-Wno-unused-function")


class FmuBuildError(RuntimeError):
    """The FMU could not be generated or compiled."""


@dataclass(frozen=True)
class _Flavour:
    """What differs between FMI versions: the API file, headers, XML writer,
    and the name of the binary directory of this platform."""
    api_source: str
    headers: tuple[str, ...]
    model_description: Callable[[FmuModel, str], str]
    extra_files: Callable[[FmuModel], dict[str, str]]
    binary_dir: str


FMI_VERSIONS: dict[int, _Flavour] = {
    2: _Flavour(
        api_source="fmi2_functions.c",
        headers=("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
        model_description=fmi2_model_description,
        extra_files=lambda model: {},
        binary_dir=fmpy.platform,  # e.g. linux64: where fmpy looks for FMI 2.0 binaries
    ),
    3: _Flavour(
        api_source="fmi3_functions.c",
        headers=("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"),
        model_description=fmi3_model_description,
        extra_files=lambda model: {"sources/buildDescription.xml": fmi3_build_description(model)},
        binary_dir=fmpy.platform_tuple,  # e.g. x86_64-linux, FMI 3.0 naming
    ),
}


def _compiler() -> str:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise FmuBuildError("no C compiler found: install gcc or set CC")
    return cc


def _stage(model: FmuModel, fmi_version: int, root: Path) -> Path:
    """Write the unpacked FMU tree under ``root`` (binary not yet compiled)."""
    try:
        flavour = FMI_VERSIONS[fmi_version]
    except KeyError:
        raise FmuBuildError(f"FMI version {fmi_version!r} is not supported; choose from {sorted(FMI_VERSIONS)}")
    sources = root / "sources"
    guid = generate_sources(model, sources)
    for folder, names in ((GENERIC_C_DIR, GENERIC_C_FILES + (flavour.api_source,)), (_FMPY_HEADERS, flavour.headers)):
        for name in names:
            (sources / name).write_bytes(_read(folder / name))
    (root / "modelDescription.xml").write_text(flavour.model_description(model, guid))
    for relative, text in flavour.extra_files(model).items():
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).write_text(text)
    return root


_READ = FileMemo(64)  # a generic C file or FMI header -> its bytes (the eleven of every FMU's sources, and more)


def _read(path: Path) -> bytes:
    """The bytes of a generic C file or FMI header, read again only when its size or modification time
    changed: every FMU's sources hold the same eleven files (a first build of the shipped FMUs wrote them 560
    times with ``shutil.copy``, which opens the copy's source too and copies its mode: ~0.2 CPU-s of
    staging); written, they get their mode from the umask, as the other staged files do."""
    return _READ.derived(path, Path.read_bytes)


_INCLUDE = re.compile(rb'^\s*#\s*include\s*"([^"]+)"', re.MULTILINE)


def _object_digest(c_file: Path, compiler: list[str]) -> str:
    """What compiling ``c_file`` depends on: the compiler and its flags, the
    file and every header of its folder it includes, directly or not. Two
    builds whose file and headers are the same get the same object: the
    core and the API layers include no model's header (they read the
    model's descriptor in ``model_start.c`` at run time), so every model
    links the same objects of them; a model compiles its generated C and
    ``model_start.c``, and built with other start values its
    ``model_start.c`` only (:func:`fmu_models.export.codegen.generate_sources`)."""
    digest = hashlib.sha256(" ".join(compiler).encode() + b"\0")
    seen, pending = set(), [c_file.name]
    while pending:
        name = pending.pop()
        path = c_file.parent / name
        if name in seen or not path.is_file():  # a system header, or one the compiler finds elsewhere
            continue
        seen.add(name)
        text = path.read_bytes()
        digest.update(name.encode() + b"\0" + hashlib.sha256(text).digest())
        pending += [m.decode() for m in _INCLUDE.findall(text)]
    return digest.hexdigest()[:16]


class _CompilerSlots:
    """One compiler per core in the whole process, however many builds run at
    once (:func:`cosim.scenario.registry.build_fmu_models` builds every FMU on a
    thread of its own): a thread waiting for a slot holds none, so builds
    never wait on each other. A slot that frees goes to the largest compile
    waiting (its C file's size estimates its time), not to the first come:
    longest first, so a first build does not start the estimators' generated
    C, a quarter of all its compiling each, last while the other core idles."""

    def __init__(self, slots: int) -> None:
        self._free = slots
        self._changed = threading.Condition()
        self._waiting: list[tuple[int, int]] = []  # heap of (-cost, arrival)
        self._arrivals = itertools.count()

    @contextmanager
    def held(self, cost: int) -> Iterator[None]:
        ticket = (-cost, next(self._arrivals))
        with self._changed:
            heapq.heappush(self._waiting, ticket)
            while not (self._free and self._waiting[0] == ticket):
                self._changed.wait()
            heapq.heappop(self._waiting)
            self._free -= 1
            self._changed.notify_all()  # the next largest may take another free slot
        try:
            yield
        finally:
            with self._changed:
                self._free += 1
                self._changed.notify_all()


_COMPILER_SLOTS = _CompilerSlots(max(1, os.cpu_count() or 1))

# Staging (a model's CasADi functions built, their C generated, the sources
# written) is Python, one thread at a time under the GIL anyway: builds on
# several threads stage one after the other, in the order they came, so each
# one's compiles are queued as soon as it is staged, instead of every
# thread's staging advancing slowly at once while the compilers wait for C.
_STAGING = threading.RLock()


def staging():
    """Hold the process's staging turn (:data:`_STAGING`), e.g. while loading a model to build."""
    return _STAGING


def _compile_one(cmd: list[str]) -> subprocess.CompletedProcess:
    """Compile the object ``cmd`` names last (``-o <object>``) unless a
    builder made it before, holding that object's lock alone: written
    beside its name and renamed, so no builder ever sees half of one. A
    builder waiting for another's object holds no other lock, nor a
    compiler slot, so the builds of one process or several never wait for
    each other's compiles beyond that object's."""
    obj = Path(cmd[-1])
    with _exclusive(obj.parent):
        if obj.exists():  # compiled by the builder that held the lock before us
            return subprocess.CompletedProcess(cmd, 0, "")
        part = obj.with_name(f"{obj.stem}.{os.getpid()}-{uuid.uuid4().hex[:8]}.o.part")
        with _COMPILER_SLOTS.held(Path(cmd[cmd.index("-c") + 1]).stat().st_size):
            result = subprocess.run([*cmd[:-1], str(part)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if result.returncode == 0:
            os.replace(part, obj)
        return result


def _run_compilers(commands: list[tuple[list[str], str]]) -> None:
    """Run the compiler commands (each ends ``-o <object>``, :func:`_compile_one`)
    concurrently, at most one per core across every build of this process,
    the largest first; raise naming the first that failed with its output."""
    if not commands:
        return
    with ThreadPoolExecutor(len(commands)) as pool:
        results = list(pool.map(_compile_one, [cmd for cmd, _ in commands]))
    for (cmd, what), result in zip(commands, results):
        if result.returncode != 0:
            raise FmuBuildError(f"compiling {what} failed:\n{' '.join(cmd)}\n{result.stdout}")


def _exclusive(folder: Path):
    """Hold ``folder``'s lock: one builder (thread or process) compiles an
    object while the others wait, then find it compiled (:func:`cosim.file_lock.exclusive`)."""
    from cosim.file_lock import exclusive

    folder.mkdir(parents=True, exist_ok=True)
    return exclusive(folder / ".lock")


def _compile(model: FmuModel, fmi_version: int, root: Path) -> None:
    """Compile ``root/sources`` into the FMU's shared library.

    Each C file is compiled to an object (``-c``) and the objects linked in
    the order of the file names, exactly what one ``cc *.c`` does, so the
    machine code is the same. Every object is kept in the cache under the
    digest of what it was compiled from (:func:`_object_digest`) and
    compiled only if no build made it before: the generated C of the
    largest model takes most of the time of a first build. One builder at a
    time compiles a missing object (a lock in its folder: the other threads
    and processes wait, then link what it compiled, :func:`_compile_one`)."""
    sources = root / "sources"
    cc = _compiler()
    compile_flags = [cc, *(f for f in CFLAGS if f != "-shared")]
    objects = {c_file: cache_root() / "objects" / _object_digest(c_file, compile_flags) / f"{c_file.stem}.o"
               for c_file in sorted(sources.glob("*.c"))}
    missing = [obj for obj in objects.values() if not obj.exists()]
    for obj in set(objects.values()) - set(missing):
        used(obj.parent)  # its use renewed: the least recently used go first (cosim.cache.prune)
    _run_compilers([([*compile_flags, f"-I{sources}", "-c", str(c_file), "-o", str(obj)],
                     f"{c_file.name} of {model.identifier} (FMI {fmi_version})")
                    for c_file, obj in objects.items() if obj in missing])
    if missing:
        note_written(cache_root() / "objects", sum(o.stat().st_size for o in missing if o.exists()), LIMITS["objects"])
    binary_dir = root / "binaries" / FMI_VERSIONS[fmi_version].binary_dir
    binary_dir.mkdir(parents=True, exist_ok=True)
    out = binary_dir / f"{model.identifier}{fmpy.sharedLibraryExtension}"
    cmd = [cc, *CFLAGS, *(str(o) for o in objects.values()), "-o", str(out), "-lm"]
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise FmuBuildError(f"linking {model.identifier} (FMI {fmi_version}) failed:\n"
                            f"{' '.join(cmd)}\n{result.stderr}")


def _zip(root: Path, target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    # write beside the target and rename: parallel builders never see half an FMU
    fd, tmp = tempfile.mkstemp(suffix=".fmu.part", dir=target.parent)
    os.close(fd)
    # deflate at level 1: a first build of every shipped FMU compresses 29 MB (sources, binaries, XML) in
    # 0.26 CPU-s instead of 1.09 s at the default level 6, into 8.0 MB instead of 6.7 MB
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for path in sorted(root.rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(root).as_posix())
    os.replace(tmp, target)


def build_fmu(model: FmuModel, out_dir: Path | str, fmi_version: int = 2) -> Path:
    """Generate, compile and pack ``model`` as ``out_dir/fmi<version>/<identifier>.fmu``."""
    with tempfile.TemporaryDirectory(prefix=f"{model.identifier}-fmi{fmi_version}-") as tmp:
        root = _stage(model, fmi_version, Path(tmp))
        _compile(model, fmi_version, root)
        target = Path(out_dir) / f"fmi{fmi_version}" / f"{model.identifier}.fmu"
        _zip(root, target)
    return target




_KNOWN: dict[tuple[int, int], tuple[FmuModel, Path]] = {}  # (id(model), version) -> (model, its FMU)


def cached_fmu(model: FmuModel, fmi_version: int = 2) -> Path:
    """Path of the FMU of ``model``, built on first use and whenever the
    model, its variable table or the C layer changes (content-addressed).
    Within a process a model object's FMU is found once (generating its
    sources to hash them costs tens of milliseconds): a study builds a
    master per case and grid point."""
    known = _KNOWN.get((id(model), fmi_version))
    if known is not None and known[0] is model and known[1].exists():
        return known[1]
    with tempfile.TemporaryDirectory() as tmp:
        with _STAGING:
            root = _stage(model, fmi_version, Path(tmp))
            digest = hashlib.sha256(" ".join(CFLAGS).encode())
            for path in sorted(root.rglob("*")):
                if path.is_file():
                    digest.update(path.relative_to(root).as_posix().encode())
                    digest.update(path.read_bytes())
        target = cache_root() / digest.hexdigest()[:16] / f"fmi{fmi_version}" / f"{model.identifier}.fmu"
        if target.exists():
            used(target.parents[1])  # its use renewed: the least recently used go first (cosim.cache.prune)
        else:  # the tree just hashed is the one compiled: sources generated once
            _compile(model, fmi_version, root)
            _zip(root, target)
            note_written(cache_root(), target.stat().st_size, LIMITS["builds"], match=BUILDS)
    _KNOWN[(id(model), fmi_version)] = (model, target)  # the model held: its id is never reused
    return target
