"""Shared fixtures: FMUs are built once per test session (content-addressed
cache, so an unchanged model is not rebuilt across sessions either)."""
from __future__ import annotations

import pytest

from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import QUADROTOR


@pytest.fixture(scope="session")
def quadrotor_fmu2():
    """Path of the FMI 2.0 (ME + CS) quadrotor FMU."""
    return cached_fmu(QUADROTOR, 2)
