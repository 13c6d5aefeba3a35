"""The toy registrations the engine's scenario and SSP tests name, made for
each test module and undone after it (``registry.scoped``)."""
from __future__ import annotations

import pytest

import toy_models
from cosim.scenario import registry


@pytest.fixture(scope="module")
def toys():
    with registry.scoped():
        toy_models.register_toys()
        yield
