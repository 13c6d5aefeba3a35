"""The FMU of a model as a run finds it.

``cached_fmu(model)`` finds an FMU by the content of its generated sources,
so each process generates them again to know which FMU a model is: about
1-1.7 s of CPU for each of the four estimators (CasADi's code generation of
their filter and the Jacobian of their dependencies), paid by every test
process that touches one. A registered model that is the one of the
catalog (or a controller variant's) is looked up as a run looks it up
instead, by the sources that define it (:func:`fmu_models.built.built_fmu`,
through the registry): the same file, found without generating anything once
the session's build (tests/conftest.py) or any earlier process recorded it.
A model changed in a test (another start value, another law) is not the
registered one and is found by ``cached_fmu``, as before.

The tests' own fmpy harnesses extract an FMU for each instance they make
(:func:`extracted`): into this process's one temporary folder, which
tests/conftest.py removes when the session ends, where fmpy's ``extract``
alone leaves each folder in the system's temporary folder for good (a
suite left about 160 of them, some 120 MB, at every run). The harnesses that
make many instances of one FMU (tests/fmus/sensor_harness.py, the controller
and clocked-controller files) take its reading and its folder from
:func:`loaded`, once per process: the FMUs this tool builds keep no
writable global state (docs/studies.md), so instances that load the one
library are as independent as a study's masters are, and each instance no
longer paid for a parse of its modelDescription (5-14 ms, fmpy's validating
read) and an extraction of every entry (about 10 ms with its removal).
"""
from __future__ import annotations

import ctypes
import functools
import shutil
import tempfile
from pathlib import Path

import fmpy

import quadrotor_paper  # noqa: F401  (registers the shipped models)
from cosim.scenario import registry
from cosim.fmi.lifecycle import _fmpy_class, _load_functions
from fmu_models.export.build import cached_fmu

__all__ = ["catalog_fmu", "extracted", "fmpy_class", "loaded", "remove_extracted", "simulated"]

_FOLDER: list[Path] = []  # this process's temporary folder, made on first use


def catalog_fmu(model, version: int = 2) -> Path:
    """The FMU of ``model`` (FMI ``version``): the registered model's if
    ``model`` is the object its definition returns, else ``cached_fmu``'s."""
    registered = registry.fmu_models().get(model.identifier)
    if registered is not None and registered.definition is not None and registered.definition() is model:
        return registered.build(version)
    return cached_fmu(model, version)


def extracted(path) -> str:
    """fmpy's ``extract`` of the FMU ``path`` into a new folder of this
    process's temporary folder (removed by :func:`remove_extracted`)."""
    if not _FOLDER:
        _FOLDER.append(Path(tempfile.mkdtemp(prefix="fnn-cosim-tests-")))
    return fmpy.extract(str(path), unzipdir=tempfile.mkdtemp(dir=_FOLDER[0]))


@functools.cache
def _loaded(path: str):
    return fmpy.read_model_description(path), extracted(path)


def loaded(path):
    """fmpy's reading of the FMU ``path``'s modelDescription and a folder it
    is extracted to (:func:`extracted`), made once per process for every
    instance a harness makes of that FMU (the same path is the same FMU:
    the cache's paths are named by content)."""
    return _loaded(str(path))


# (fmpy's class, a loaded library's handle) -> (the library, fmpy's table of its FMI functions for that
# class), kept for the process. fmpy's freeInstance unloads the library (dlclose), each instance its
# own load; the library is loaded once more when it is kept and never unloaded for that (``pin``), so
# it stays loaded at that handle while the process lives, whoever else loads and unloads it: a later
# instance's load of the same file returns the same handle, and the same function pointers with the
# same signatures serve it. The FMUs keep no writable global state (see above), so an
# instance of a library that stayed loaded starts as one of a library loaded afresh.
_LOADED: dict[tuple[type, int], tuple[ctypes.CDLL, dict]] = {}


@functools.cache
def fmpy_class(base: type) -> type:
    """fmpy's ``base`` as the tool makes it (:func:`cosim.fmi.lifecycle._fmpy_class`), taking the
    function table of a library it loaded before (see ``_LOADED``). Each instance had its library
    mapped and relocated again (the last instance's freeInstance had unloaded it) and its table made
    again, a ``dlsym`` and three attributes a function: 1200 instances of the plant made and freed in
    one process took 1.0-1.1 s of CPU, now 0.25 s (the range test of every parameter makes some 1200)."""
    if _fmpy_class(base) is base:  # fmpy without the _loadFunctions the tool reaches into: fmpy's own class
        return base

    def load(self) -> None:
        key = (base, self.dll._handle)
        kept = _LOADED.get(key)
        if kept is None:
            _load_functions(self)  # the tool's: fmpy's for the first instance of base, its signatures after
            pin = ctypes.CDLL(self.dll._name)  # a load of the library that nothing unloads
            assert pin._handle == self.dll._handle, self.dll._name
            _LOADED[key] = (pin, dict(self._functions))
        else:
            self.dll = kept[0]
            self._functions.update(kept[1])

    return type(base.__name__, (base,), {"_loadFunctions": load, "__module__": __name__, "__doc__": base.__doc__})


def simulated(path, **options):
    """fmpy's ``simulate_fmu`` of the FMU ``path`` with ``options``, given its
    reading and folder of :func:`loaded`: fmpy's own call extracted the FMU
    again, read (and by default validated) its modelDescription again, and
    removed the folder, some 10-20 ms of every call for what the process
    has already."""
    description, folder = loaded(path)
    return fmpy.simulate_fmu(folder, model_description=description, **options)


def remove_extracted() -> None:
    """Remove every folder :func:`extracted` made in this process (at the session's end)."""
    _loaded.cache_clear()
    while _FOLDER:
        shutil.rmtree(_FOLDER.pop(), ignore_errors=True)
