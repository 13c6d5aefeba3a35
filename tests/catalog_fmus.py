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
"""
from __future__ import annotations

from pathlib import Path

import quadrotor_paper  # noqa: F401  (registers the shipped models)
from cosim import registry
from fmu_models.export.build import cached_fmu

__all__ = ["catalog_fmu"]


def catalog_fmu(model, version: int = 2) -> Path:
    """The FMU of ``model`` (FMI ``version``): the registered model's if
    ``model`` is the object its definition returns, else ``cached_fmu``'s."""
    registered = registry.fmu_models().get(model.identifier)
    if registered is not None and registered.definition is not None and registered.definition() is model:
        return registered.build(version)
    return cached_fmu(model, version)
