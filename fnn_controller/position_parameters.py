"""The position controller's parameters (section 5.1), apart from its laws.

The laws (:mod:`fnn_controller.position`, the variants' axis laws) read
these fields, and the variant registry checks a variant's ``parameters``
against them; both import this module, and it imports neither, so the laws
and the registry need not import each other.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .fnn import FnnInit
from .it2 import IT2Params
from .learning import LearningBounds
from .parameters import check_ranges, param

__all__ = ["PositionParams"]


@dataclass(frozen=True)
class PositionParams:
    """Gains of the position controller, paper values (section 5.1)."""

    kp: float = param(2.5, "1/s", "proportional gain of eq. 19")  # any sign: the stability analysis sweeps it
    kd: float = param(0.005, "1", "derivative gain of eq. 19 (s/s)")
    dt: float = param(0.01, "s", "learning (and controller) step", min=1e-4, max=1.0)
    gamma_smc: tuple[float, float, float] = param((1.5, 1.5, 1.5), "1/s", "gamma of eq. 38 for x, y, z", min=0.0)
    nu: tuple[float, float, float] = param((0.85, 0.85, 0.2), "s", "nu of eq. 38 for x, y, z", min=0.0)
    gamma_lm: tuple[float, float, float] = param((1.5, 1.5, 1.5), "m/s2", "gamma of eq. 61 for x, y, z", min=0.0)
    alpha_bar: tuple[float, float, float] = param((1.1, 1.1, 0.9), "1", "alpha_bar of eq. 62 for x, y, z",
                                                  min=0.0)
    feedforward: float = param(0.0, "1", "gain of the reference velocity fed forward around the PD: "
                               "v* = tau_c - tau_n + feedforward dp*/dt (0: the paper's law)", min=0.0, max=1.0)
    accel_feedforward: float = param(0.0, "1", "gain of the reference acceleration d2p*/dt2 passed to the velocity "
                                     "controller: a_ref = accel_feedforward d2p*/dt2 (0: the paper's law)",
                                     min=0.0, max=1.0)
    phi: tuple[float, float, float] = param((0.0, 0.0, 0.0), "m/s",
                                            "boundary layer of the learning laws' sgn(tau_c) for x, y, z: "
                                            "sat(tau_c / phi) in its place (0: the paper's sgn)", min=0.0)
    init: FnnInit = field(default_factory=FnnInit)  # initial FNN values (section 5.1)
    it2: IT2Params = field(default_factory=IT2Params)  # the interval type-2 FNN's own (variants pd+it2-*)
    bounds: LearningBounds = field(default_factory=LearningBounds)  # eqs. 27-29 and floors

    def __post_init__(self) -> None:
        check_ranges(self)
