"""A built FMU found by the sources that define it, without building its model.

:func:`fmu_models.export.build.cached_fmu` finds an FMU by the content of
its generated sources: to know which FMU a model is, it builds the model's
CasADi functions and generates their C (tens of milliseconds a model, and
CasADi imported). A run of already-built FMUs needs none of that.
:func:`built_fmu` keeps, beside the cache, an index from a *recipe* to the
FMU ``cached_fmu`` returned for it: the model's identifier, the FMI version,
the start values it is built with where they are not its own (an SSP
archive's self-contained FMUs, :mod:`cosim.ssp.export`), the installed
CasADi and fmpy (the generated C, the FMI headers: where each is installed,
its ``__init__.py``'s size and modification time) and the bytes
of every source file that can change the model or its FMU (the packages
``fmu_models`` and ``fnn_controller``, where every model and controller
variant of the project is defined, and any ``extra`` file, such as a module
that registered a controller variant of its own). Any change of any of these
gives another recipe, so the index can only miss, never point to a stale
FMU: on a miss the model is loaded and built by ``cached_fmu`` as before.
"""
from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from importlib.machinery import PathFinder
from pathlib import Path
from typing import Callable, Iterable, Mapping

from cosim.cache import drop, read, used, write

from .cache import cache_root

__all__ = ["built_fmu"]

_PACKAGES = (Path(__file__).resolve().parent, Path(__file__).resolve().parents[1] / "fnn_controller")
_SUFFIXES = {".py", ".c", ".h"}


def _digest_files(digest, files: Iterable[Path], root: Path | None = None) -> None:
    for path in files:
        digest.update(str(path.relative_to(root) if root else path).encode() + b"\0")
        digest.update(path.read_bytes())


def _installed(package: str) -> str:
    """Where ``package`` is installed and the size and modification time of
    its ``__init__.py``, which installing another version rewrites (read
    without importing the package, and faster than its distribution's metadata)."""
    origin = Path(PathFinder.find_spec(package).origin)  # sys.path, not sys.modules: a lazily loaded module stays unloaded
    stat = origin.stat()
    return f"{origin}:{stat.st_size}:{stat.st_mtime_ns}"


def _source_files(package: Path) -> list[Path]:
    files = []
    for folder, subfolders, names in os.walk(package):
        subfolders[:] = [d for d in subfolders if d != "__pycache__"]
        files += [Path(folder, name) for name in names if Path(name).suffix in _SUFFIXES]
    return sorted(files)


@lru_cache(maxsize=None)
def _sources_digest() -> bytes:
    """The digest of the tools and of every source file of the packages that define the models (once a process)."""
    digest = hashlib.sha256(f"{_installed('casadi')}\n{_installed('fmpy')}\n".encode())
    for package in _PACKAGES:
        _digest_files(digest, _source_files(package), package.parent)
    return digest.digest()


def _recipe(identifier: str, fmi_version: int, extra: Iterable[Path],
            values: Mapping[str, float] | None = None) -> str:
    digest = hashlib.sha256(_sources_digest())
    digest.update(f"{identifier} fmi{fmi_version}".encode())
    _digest_files(digest, sorted({Path(p).resolve() for p in extra}))
    if values is not None:  # repr: a float's exact digits; sorted: the table, not the mapping, orders them
        digest.update(f"\0values {sorted((k, float(v)) for k, v in values.items())!r}".encode())
    return digest.hexdigest()


def built_fmu(identifier: str, fmi_version: int, load: Callable[[], object], extra: Iterable[Path] = (),
              values: Mapping[str, float] | None = None) -> Path:
    """The FMU of the model ``load()`` returns (``identifier``, FMI
    ``fmi_version``): the one the index holds for its recipe if that file
    still exists, else ``cached_fmu(load(), fmi_version)``, then recorded.
    ``extra``: source files beyond ``fmu_models`` and ``fnn_controller``
    that define the model. ``values``: the start values ``load()`` builds
    the model with (``FmuModel.with_defaults``: an SSP archive's
    self-contained FMUs), part of the recipe; a value ``load()`` refuses is
    refused at every call (no FMU is recorded for it)."""
    root, recipe = cache_root(), _recipe(identifier, fmi_version, extra, values)
    known = read("index", recipe, root)  # the FMU's path in the cache, as recorded below
    if isinstance(known, str):
        built = (root / known).resolve()
        # a built FMU of the cache only (a recorded path reaches nothing else), still there
        if built.is_relative_to(root.resolve()) and built.suffix == ".fmu" and built.is_file():
            used(built.parents[1])  # its build's use renewed (cosim.cache.prune)
            return built
        drop("index", recipe, root)  # not yet recorded, or the cache moved: build (or find) it as cached_fmu does
    from .export.build import cached_fmu, staging

    with staging():  # building the model's CasADi functions is staging too: one builder thread at a time
        model = load()
    path = cached_fmu(model, fmi_version)
    try:
        write("index", recipe, path.resolve().relative_to(root.resolve()).as_posix(), root)
    except ValueError:  # an FMU outside the cache ($FNN_COSIM_CACHE changed meanwhile): not recorded
        pass
    return path
