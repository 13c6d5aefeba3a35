"""The position controller's parameters (section 5.1), apart from its laws.

The laws (:mod:`fnn_controller.position`, the variants' axis laws) read
these fields, and the variant registry checks a variant's ``parameters``
against them; both import this module, and it imports neither, so the laws
and the registry need not import each other. The nested tables (the FNN's
initial values, the learning bounds, the IT2 FNN's parameters) are here too,
their laws' modules (:mod:`~fnn_controller.fnn`, :mod:`~fnn_controller.learning`,
:mod:`~fnn_controller.it2`) export them as well: a scenario's
``[controller]`` table is declared without importing CasADi.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .parameters import check_ranges, param

__all__ = ["PositionParams", "FnnInit", "IT2Params", "LearningBounds", "check_one_step", "FLOWN_KD_MIN"]

FLOWN_KD_MIN = 0.0  # the smallest derivative gain a scenario flies (the stability analysis goes below)


@dataclass(frozen=True)
class FnnInit:
    """Initial values of the FNN of one axis (section 5.1)."""

    c1: tuple[float, float, float] = param((-3.0, 1e-4, 3.0), "m", "initial centres of the MFs of x1 = e")
    c2: tuple[float, float, float] = param((-30.0, 1e-4, 30.0), "m/s", "initial centres of the MFs of x2 = de/dt")
    sigma1: float = param(1.5, "m", "initial width of every MF of x1", min=1e-9)
    sigma2: float = param(15.0, "m/s", "initial width of every MF of x2", min=1e-9)
    alpha: float = param(1e-3, "m/s2", "initial adaptive learning rate (rate of tau_n in eq. 37; see learning.py)",
                         min=0.0)
    f_high: float = param(1e-3, "m/s", "f_ij(0) ~ U[0, f_high]", min=0.0)

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class LearningBounds:
    """Bounds of eqs. (27)-(29) and the floor of eqs. (35)-(36) (not in the paper)."""

    # Every bound is positive: at least 1e-9 in its unit (FMI ranges are inclusive).
    x1_max: float = param(20.0, "m", "B_x for x1 = e (eq. 27); the FNN input is clipped to +-x1_max", min=1e-9)
    x2_max: float = param(50.0, "m/s", "B_x for x2 = de/dt (eq. 27); the FNN input is clipped to +-x2_max",
                          min=1e-9)
    c1_max: float = param(50.0, "m", "B_c for each element of c1 (eq. 28)", min=1e-9)
    c2_max: float = param(150.0, "m/s", "B_c for each element of c2 (eq. 28)", min=1e-9)
    sigma1_min: float = param(0.05, "m", "smallest width of an MF of x1", min=1e-9)
    sigma1_max: float = param(15.0, "m", "B_sigma for each element of sigma1 (eq. 28)", min=1e-9)
    sigma2_min: float = param(0.5, "m/s", "smallest width of an MF of x2", min=1e-9)
    sigma2_max: float = param(150.0, "m/s", "B_sigma for each element of sigma2 (eq. 28)", min=1e-9)
    f_max: float = param(10.0, "m/s", "B_f of eq. 29 for each f_ij", min=1e-9)
    alpha_max: float = param(10.0, "m/s2", "upper bound of the adaptive learning rate alpha", min=1e-9)
    a_min: float = param(0.5, "1", "floor of |A| = |x - c| / sigma in eqs. 35-36 / 59-60", min=1e-9)

    def __post_init__(self) -> None:
        check_ranges(self)
        for low, high in (("sigma1_min", "sigma1_max"), ("sigma2_min", "sigma2_max")):
            if not getattr(self, low) < getattr(self, high) < math.inf:
                raise ValueError(f"LearningBounds needs 0 < {low} < {high} < inf")


@dataclass(frozen=True)
class IT2Params:
    """Parameters of the interval type-2 FNN, the nested field
    ``PositionParams.it2`` (read by the variants ``pd+it2-*`` only)."""

    spread: float = param(0.2, "1", "width uncertainty d: upper MF width (1 + d) sigma, lower MF width sigma",
                          min=0.0, max=10.0)
    q0: float = param(0.5, "1", "initial weight q of the lower firing strengths in the type reduction",
                      min=0.0, max=1.0)
    gamma_q: float = param(0.5, "1/m", "gain of the q law q_dot = -gamma_q (y_lower - y_upper) sgn(tau_c) "
                           "(0: q held at q0)", min=0.0)

    def __post_init__(self) -> None:
        check_ranges(self)



@dataclass(frozen=True)
class PositionParams:
    """Gains of the position controller, paper values (section 5.1)."""

    # A negative kp flew, silently, a loop that pushes away from the reference; kp = 0 has no equilibrium
    # (e* = v*/kp). kd takes any sign here: the stability analysis maps and flies kd < 0 (below -1 the
    # velocity feedback cancels and the vehicle runs away); a scenario's flight takes kd >= FLOWN_KD_MIN.
    kp: float = param(2.5, "1/s", "proportional gain of eq. 19 (positive: at least 1e-9)", min=1e-9)
    kd: float = param(0.005, "1", "derivative gain of eq. 19 (s/s); a scenario flies kd >= 0")
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


def check_one_step(position_dt: float, geometric_dt: float) -> None:
    """The position and the velocity controller run in one step (Fig. 2: the
    velocity command v* of eq. 26 is used in the step that computes it), so
    ``geometric.dt`` must be ``position.dt``: ``ValueError`` naming both
    otherwise. The one check of this rule (the scenario's controller table,
    the parametric step's parameter table)."""
    if geometric_dt != position_dt:
        raise ValueError(f"geometric.dt = {geometric_dt!r} s: the position and the velocity controller run in one "
                         f"step, it must equal position.dt = {position_dt!r} s")
