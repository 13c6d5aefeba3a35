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
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import fmpy

from .codegen import GENERIC_C_DIR, GENERIC_C_FILES, generate_sources
from .model import FmuModel
from .model_description import fmi2_model_description, fmi3_build_description, fmi3_model_description

__all__ = ["build_fmu", "cached_fmu", "cache_root", "FmuBuildError", "FMI_VERSIONS"]

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


def _compile(model: FmuModel, fmi_version: int, root: Path) -> None:
    sources = root / "sources"
    c_files = sorted(str(p) for p in sources.glob("*.c"))
    binary_dir = root / "binaries" / FMI_VERSIONS[fmi_version].binary_dir
    binary_dir.mkdir(parents=True, exist_ok=True)
    out = binary_dir / f"{model.identifier}{fmpy.sharedLibraryExtension}"
    cmd = [_compiler(), *CFLAGS, f"-I{sources}", *c_files, "-o", str(out), "-lm"]
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise FmuBuildError(f"compiling {model.identifier} (FMI {fmi_version}) failed:\n"
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


def cache_root() -> Path:
    """Where built FMUs are kept: $FNN_COSIM_CACHE, else build/ in a source
    checkout, else ~/.cache/fnn-cosim."""
    if os.environ.get("FNN_COSIM_CACHE"):
        return Path(os.environ["FNN_COSIM_CACHE"])
    repo = Path(__file__).resolve().parents[2]
    if (repo / "pyproject.toml").exists():
        return repo / "build" / "fmu-cache"
    return Path.home() / ".cache" / "fnn-cosim"


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
    if not target.exists():
        build_fmu(model, target.parent.parent, fmi_version)
    _KNOWN[(id(model), fmi_version)] = (model, target)  # the model held: its id is never reused
    return target
