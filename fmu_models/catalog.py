"""Every FMU model of the project, by identifier.

``fnn-cosim build-fmu`` builds each of them; scenarios name them here.
"""
from __future__ import annotations

from .export.model import FmuModel
from .models.quadrotor import QUADROTOR
from .models.wind_gust import WIND_GUST

__all__ = ["MODELS", "model"]

MODELS: dict[str, FmuModel] = {"Quadrotor": QUADROTOR, "WindGust": WIND_GUST}


def model(name: str) -> FmuModel:
    """The model called ``name``; a ``KeyError`` listing the known names otherwise."""
    try:
        return MODELS[name]
    except KeyError:
        raise KeyError(f"unknown FMU model {name!r}; known models: {', '.join(sorted(MODELS))}") from None
