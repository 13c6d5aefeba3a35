"""The periodic wind gust of the paper's section 5.3 (Fig. 5), as an FMU model.

A model without states: its outputs are functions of time and parameters only,
so it is exported, built and validated by exactly the same code as the plant.

Gust (section 5.3): the wind blows with speed ``v_w`` along the unit vector
``d = dir / |dir|`` (the paper: dir = [-1, -1, 0]) for ``t < t_switch_1``
(17 s), along ``-d`` from ``t_switch_1`` and along ``d`` again from
``t_switch_2`` (34 s)::

    v_gust(t) = v_w * s(t) * d
    s(t) = 1 - 2 r(t - t_switch_1) + 2 r(t - t_switch_2)
    r(tau) = clip(tau / ramp_time, 0, 1)   if ramp_time > 0
    r(tau) = 1 if tau >= -1e-9 else 0     if ramp_time = 0

``ramp_time = 0`` (the default) gives the exact square wave of Fig. 5 (the
1 ns tolerance makes a switch at 17 s happen at the step t = 1700 * 0.01
whichever way that product rounds). The plant
holds its inputs constant over each communication step (zero-order hold) and
integrates with fixed-step RK4 inside it, so a jump between two steps costs the
integrator no accuracy; ``ramp_time > 0`` turns each reversal into a linear
ramp starting at the switching time, for users who want a bounded wind rate.

Turbulence (optional, off by default): a deterministic sum of ``N_SINES``
sines per axis on top of the gust,

    v_turb_a(t) = sum_k A_k sin(2 pi f_k t + phi_{a,k}),     a in {x, y, z}

with frequencies f_k log-spaced over [0.05, 2] Hz, amplitudes
A_k ~ f_k^(-5/6) (the -5/3 slope of the Kolmogorov/von Karman velocity
spectrum) scaled so that each axis has RMS ``turbulence`` (m/s), and phases
phi_{a,k} = 2 pi frac(43758.5453 sin(12.9898 (seed + 1) + 78.233 (3k + a)))
(a fixed hash of the integer-valued parameter ``turbulence_seed``), so a run
is reproducible from its parameters alone.
"""
from __future__ import annotations

import math

from fmu_models.lazy_casadi import ca

from ..export.model import FmuModel
from ..export.variables import output, parameter

__all__ = ["WIND_GUST", "N_SINES", "TURBULENCE_BAND", "SWITCH_TOLERANCE", "gust_speed_factor"]

SWITCH_TOLERANCE = 1e-9  # s
# m/s: the strongest wind the model takes, gust or turbulence RMS. Beaufort 12 (a hurricane) starts at
# 32.7 m/s and the strongest gusts measured near 113 m/s; a small quadrotor meets far less (the paper:
# 1-5 m/s). A larger value is a typing slip, refused with its range (docs/plant-model.md).
MAX_WIND = 100.0

N_SINES = 6
TURBULENCE_BAND = (0.05, 2.0)  # Hz
_FREQUENCIES = tuple(TURBULENCE_BAND[0] * (TURBULENCE_BAND[1] / TURBULENCE_BAND[0]) ** (k / (N_SINES - 1))
                     for k in range(N_SINES))
_RAW = tuple(f ** (-5.0 / 6.0) for f in _FREQUENCIES)
# sum_k (A_k^2 / 2) = 1 for unit RMS
_AMPLITUDES = tuple(a / math.sqrt(sum(r * r for r in _RAW) / 2.0) for a in _RAW)
_AXES = ("x", "y", "z")

_VARIABLES = (
    output("v_wind_x", "m/s", "wind velocity north (world frame, NED)"),
    output("v_wind_y", "m/s", "wind velocity east (world frame, NED)"),
    output("v_wind_z", "m/s", "wind velocity down (world frame, NED)"),
    parameter("v_w", "m/s", "gust speed (section 5.3: 1, 3 or 5 m/s)", 3.0, min=0.0, max=MAX_WIND),
    parameter("dir_x", "1", "gust direction, north component (normalized inside)", -1.0),
    parameter("dir_y", "1", "gust direction, east component (normalized inside)", -1.0),
    parameter("dir_z", "1", "gust direction, down component (normalized inside)", 0.0),
    parameter("t_switch_1", "s", "time at which the gust reverses (section 5.3: 17 s)", 17.0, min=0.0),
    parameter("t_switch_2", "s", "time at which the gust reverses back (section 5.3: 34 s)", 34.0, min=0.0),
    parameter("ramp_time", "s", "duration of each reversal (0: exact step as in Fig. 5)", 0.0, min=0.0),
    parameter("turbulence", "m/s", "RMS per axis of the sum-of-sines turbulence (0: none)", 0.0, min=0.0,
              max=MAX_WIND),
    parameter("turbulence_seed", "1", "integer selecting the turbulence phases", 0.0, min=0.0),
)


def gust_speed_factor(t, t_switch_1, t_switch_2, ramp_time):
    """s(t) of the module docstring: +1, then -1 from t_switch_1, +1 from t_switch_2.

    Works on CasADi symbols and on floats (``ca.fmin``/``ca.fmax`` accept both).
    """
    width = ca.fmax(ramp_time, 1e-12)

    def ramp(tau):
        # tau >= -1 ns counts as switched: t = n h computed in floating point
        # lands a few ulp either side of a switching time such as 17 s
        exact = ca.if_else(tau >= -SWITCH_TOLERANCE, 1.0, 0.0)
        linear = ca.fmin(ca.fmax(tau / width, 0.0), 1.0)
        return ca.if_else(ramp_time > 0, linear, exact)

    return 1.0 - 2.0 * ramp(t - t_switch_1) + 2.0 * ramp(t - t_switch_2)


def _phase(seed, k: int, axis: int):
    hashed = 43758.5453 * ca.sin(12.9898 * (seed + 1.0) + 78.233 * (3 * k + axis))
    return 2.0 * math.pi * (hashed - ca.floor(hashed))


def _equations(t, s):
    direction = ca.vertcat(s["dir_x"], s["dir_y"], s["dir_z"])
    unit = direction / ca.fmax(ca.norm_2(direction), 1e-12)
    gust = s["v_w"] * gust_speed_factor(t, s["t_switch_1"], s["t_switch_2"], s["ramp_time"]) * unit
    outputs = {}
    for a, name in enumerate(_AXES):
        turbulence = sum(amp * ca.sin(2.0 * math.pi * f * t + _phase(s["turbulence_seed"], k, a))
                         for k, (f, amp) in enumerate(zip(_FREQUENCIES, _AMPLITUDES)))
        outputs[f"v_wind_{name}"] = gust[a] + s["turbulence"] * turbulence
    return {}, outputs


WIND_GUST = FmuModel(
    identifier="WindGust",
    description="Periodic wind gust of the LM-FNN paper (section 5.3, Fig. 5), with optional "
                "sum-of-sines turbulence; world frame NED",
    variables=_VARIABLES,
    equations=_equations,
    initial_state=lambda s: {},
)
