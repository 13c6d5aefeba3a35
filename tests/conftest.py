"""Shared fixtures: FMUs are built once per test session (content-addressed
cache, so an unchanged model is not rebuilt across sessions either).

With several workers (``make test``: pytest-xdist) the controller builds
every shipped FMU before the workers start, side by side on every core
(:func:`cosim.registry.build_fmu_models`): each FMU is built once, not by
whichever workers first need it at the same time, and a fresh clone's first
build takes the compilers' time over the cores. A run on one process builds
what its tests use, when they use it."""
from __future__ import annotations

import pytest

from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import QUADROTOR


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session):
    if session.config.pluginmanager.has_plugin("dsession"):  # the xdist controller, before its workers
        import quadrotor_paper  # noqa: F401  (registers the shipped models)
        from cosim import registry
        from fmu_models.export.build import FMI_VERSIONS

        registry.build_fmu_models(sorted(FMI_VERSIONS))


@pytest.fixture(scope="session")
def quadrotor_fmu2():
    """Path of the FMI 2.0 (ME + CS) quadrotor FMU."""
    return cached_fmu(QUADROTOR, 2)
