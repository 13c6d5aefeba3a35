"""Compile a model into an FMU: generated sources + generic C layer -> .fmu.

Each FMU holds its complete sources (so users on other platforms can compile
it; FMI 3.0 adds ``sources/buildDescription.xml``) and the binary for this
platform, compiled here with the system C compiler, under
``binaries/<platform>``: ``linux64`` in FMI 2.0, the platform tuple
``x86_64-linux`` in FMI 3.0.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import fmpy

from ..cache import cache_root
from .codegen import GENERIC_C_DIR, GENERIC_C_FILES, generate_sources
from .model import FmuModel
from .model_description import fmi2_model_description, fmi3_build_description, fmi3_model_description

__all__ = ["build_fmu", "cached_fmu", "FmuBuildError", "FMI_VERSIONS"]

_FMPY_HEADERS = Path(fmpy.__file__).parent / "c-code"
CFLAGS = ("-shared", "-fPIC", "-O2", "-std=gnu11", "-fvisibility=hidden", "-Wall", "-Wno-unused-function")


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
    for name in GENERIC_C_FILES + (flavour.api_source,):
        shutil.copy(GENERIC_C_DIR / name, sources / name)
    for name in flavour.headers:
        shutil.copy(_FMPY_HEADERS / name, sources / name)
    (root / "modelDescription.xml").write_text(flavour.model_description(model, guid))
    for relative, text in flavour.extra_files(model).items():
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).write_text(text)
    return root


def _version_specific() -> set[str]:
    """Names of the source files that differ between FMI versions (the API
    layer and its headers); every other source file is the same in both."""
    return {name for f in FMI_VERSIONS.values() for name in (f.api_source, *f.headers)}


def _run_compilers(commands: list[tuple[list[str], str]]) -> None:
    """Run the compiler commands concurrently, at most one per core (a build
    uses every core); raise naming the first that failed with its output."""
    jobs = max(1, os.cpu_count() or 1)
    pending, running, failed = list(commands), [], []
    while pending or running:
        while pending and len(running) < jobs:
            cmd, what = pending.pop(0)
            running.append((subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True),
                            cmd, what))
        proc, cmd, what = running.pop(0)
        output = proc.communicate()[0]
        if proc.returncode != 0 and not failed:
            failed.append(f"compiling {what} failed:\n{' '.join(cmd)}\n{output}")
    if failed:
        raise FmuBuildError(failed[0])


def _compile(model: FmuModel, fmi_version: int, root: Path) -> None:
    """Compile ``root/sources`` into the FMU's shared library.

    Each C file is compiled to an object (``-c``) and the objects linked in
    the order of the file names, exactly what one ``cc *.c`` does, so the
    machine code is the same. The objects of the files both FMI versions
    share (the generated model, the core; all but the API layer) are kept in
    the cache under a digest of the compiler, the flags and every shared
    source file: the FMI 3.0 build of a model links the objects its FMI 2.0
    build compiled (the generated C of the largest model takes most of a
    minute at -O2). Objects are written beside their name and renamed, so
    concurrent builders never see half of one."""
    sources = root / "sources"
    c_files = sorted(sources.glob("*.c"))
    specific = _version_specific()
    cc = _compiler()
    compile_flags = [f for f in CFLAGS if f != "-shared"]
    digest = hashlib.sha256(" ".join([cc, *compile_flags]).encode())
    for path in sorted(sources.iterdir()):
        if path.suffix in (".c", ".h") and path.name not in specific:  # not buildDescription.xml (FMI 3.0 only)
            digest.update(path.name.encode())
            digest.update(path.read_bytes())
    shared_dir = cache_root() / "objects" / digest.hexdigest()[:16]
    with tempfile.TemporaryDirectory(prefix=f"{model.identifier}-objects-") as tmp:
        objects, commands, renames = [], [], []
        for c_file in c_files:
            if c_file.name in specific:
                obj = Path(tmp) / f"{c_file.stem}.o"
            else:
                obj = shared_dir / f"{c_file.stem}.o"
                if obj.exists():
                    objects.append(obj)
                    continue
                shared_dir.mkdir(parents=True, exist_ok=True)
            part = obj.with_name(f"{obj.stem}.{os.getpid()}-{uuid.uuid4().hex[:8]}.o.part")
            renames.append((part, obj))
            commands.append(([cc, *compile_flags, f"-I{sources}", "-c", str(c_file), "-o", str(part)],
                             f"{c_file.name} of {model.identifier} (FMI {fmi_version})"))
            objects.append(obj)
        _run_compilers(commands)
        for part, obj in renames:
            os.replace(part, obj)
        binary_dir = root / "binaries" / FMI_VERSIONS[fmi_version].binary_dir
        binary_dir.mkdir(parents=True, exist_ok=True)
        out = binary_dir / f"{model.identifier}{fmpy.sharedLibraryExtension}"
        cmd = [cc, *CFLAGS, *(str(o) for o in objects), "-o", str(out), "-lm"]
        result = subprocess.run(cmd, capture_output=True, text=True)
        if result.returncode != 0:
            raise FmuBuildError(f"linking {model.identifier} (FMI {fmi_version}) failed:\n"
                                f"{' '.join(cmd)}\n{result.stderr}")


def _zip(root: Path, target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    # write beside the target and rename: parallel builders never see half an FMU
    fd, tmp = tempfile.mkstemp(suffix=".fmu.part", dir=target.parent)
    os.close(fd)
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
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
        root = _stage(model, fmi_version, Path(tmp))
        digest = hashlib.sha256(" ".join(CFLAGS).encode())
        for path in sorted(root.rglob("*")):
            if path.is_file():
                digest.update(path.relative_to(root).as_posix().encode())
                digest.update(path.read_bytes())
        target = cache_root() / digest.hexdigest()[:16] / f"fmi{fmi_version}" / f"{model.identifier}.fmu"
        if not target.exists():  # the tree just hashed is the one compiled: sources generated once
            _compile(model, fmi_version, root)
            _zip(root, target)
    _KNOWN[(id(model), fmi_version)] = (model, target)  # the model held: its id is never reused
    return target
