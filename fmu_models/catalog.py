"""Every FMU model of the project, by identifier.

``fnn-cosim build-fmu`` builds each of them; scenarios name them here. A
model's module is imported (and its CasADi equations built) only when the
model is asked for: listing the names costs nothing.
"""
from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Iterator, Mapping

if TYPE_CHECKING:
    from .export.model import FmuModel

__all__ = ["MODELS", "MODEL_NAMES", "model"]

# identifier -> (module, attribute): one line per model
_WHERE: dict[str, tuple[str, str]] = {
    "Quadrotor": ("fmu_models.models.quadrotor", "QUADROTOR"),
    "WindGust": ("fmu_models.models.wind_gust", "WIND_GUST"),
    "ReferenceHover": ("fmu_models.models.reference", "REFERENCE_HOVER"),
    "ReferenceTwoCircles": ("fmu_models.models.reference", "REFERENCE_TWO_CIRCLES"),
    "ReferenceFigureEight": ("fmu_models.models.reference", "REFERENCE_FIGURE_EIGHT"),
    "Measurement12": ("fmu_models.models.sensors", "MEASUREMENT_12"),
    "CommandLink4": ("fmu_models.models.sensors", "COMMAND_LINK_4"),
    "VelocityLink3": ("fmu_models.models.sensors", "VELOCITY_LINK_3"),
    "GNSS6": ("fmu_models.models.sensors", "GNSS_6"),
    "GNSS6GM": ("fmu_models.models.sensors", "GNSS_6_GM"),
    "IMU": ("fmu_models.models.imu", "IMU"),
    "Magnetometer3": ("fmu_models.models.magnetometer", "MAGNETOMETER"),
    "Estimator": ("fmu_models.models.estimator", "ESTIMATOR"),
    "EstimatorMag": ("fmu_models.models.estimator", "ESTIMATOR_MAG"),
    "EstimatorGM": ("fmu_models.models.estimator", "ESTIMATOR_GM"),
    "EstimatorMocap": ("fmu_models.models.estimator", "ESTIMATOR_MOCAP"),
    "Mocap9": ("fmu_models.models.sensors", "MOCAP_9"),
}
MODEL_NAMES: tuple[str, ...] = tuple(_WHERE)


def model(name: str) -> "FmuModel":
    """The model called ``name``; a ``KeyError`` listing the known names otherwise."""
    try:
        module, attribute = _WHERE[name]
    except KeyError:
        raise KeyError(f"unknown FMU model {name!r}; known models: {', '.join(sorted(_WHERE))}") from None
    return getattr(import_module(module), attribute)


class _Models(Mapping):
    """``MODELS[name]``: the models by identifier, each imported on first use."""

    def __getitem__(self, name: str) -> "FmuModel":
        if name not in _WHERE:
            raise KeyError(name)
        return model(name)

    def __iter__(self) -> Iterator[str]:
        return iter(_WHERE)

    def __len__(self) -> int:
        return len(_WHERE)


MODELS: Mapping[str, "FmuModel"] = _Models()
