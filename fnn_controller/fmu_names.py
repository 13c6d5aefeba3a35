"""What the controller's FMUs are called and how they are seeded, known
without building them (no CasADi): the whole controller of a variant
(:mod:`fnn_controller.controller_fmu`) and its two loops
(:mod:`fnn_controller.split`). A run of already-built FMUs reads these only.
"""
from __future__ import annotations

from fmu_models.export.variables import seed_parameter

from .variants import variant as lookup

__all__ = ["fmu_identifier", "outer_identifier", "INNER_IDENTIFIER", "FNN_SEED", "seed_parameter_name"]

INNER_IDENTIFIER = "VelocityController"  # the inner loop is one FMU for every variant

# numpy's default_rng(seed) draws f_ij(0) in the FMU as in the Python path
FNN_SEED = seed_parameter("seed", "seed of numpy's default_rng that draws f_ij(0) (section 5.1)")


def fmu_identifier(variant: str) -> str:
    """``ControllerPDLM`` for ``pd+lm``: the FMU's model identifier (a C name)."""
    return "Controller" + "".join(ch for ch in variant.upper() if ch.isalnum())


def outer_identifier(variant: str) -> str:
    """``PositionControllerPDLM`` for ``pd+lm``: the outer FMU's model identifier."""
    return "PositionController" + "".join(ch for ch in variant.upper() if ch.isalnum())


def seed_parameter_name(variant: str) -> str | None:
    """The seed parameter of ``variant``'s FMUs (``None`` when the variant
    draws nothing at reset)."""
    return FNN_SEED.name if lookup(variant).n_random else None
