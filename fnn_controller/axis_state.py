"""The layout of one axis's learned state: the type-1 FNN's
(:mod:`fnn_controller.fnn`, whose docstring tables it) and the interval
type-2 FNN's (:mod:`fnn_controller.it2`). Plain numbers, no law: a
variant's metadata (its state size and ports) is read from here without
importing CasADi.
"""
from __future__ import annotations

__all__ = ["N_MF", "N_RULES", "AXIS_STATE_SIZE", "AXIS_STATE_PORTS", "C1", "C2", "SIGMA1", "SIGMA2", "F", "ALPHA",
           "X1_PREV", "X2_PREV", "PRIMED", "IT2_Q", "IT2_X1_PREV", "IT2_X2_PREV", "IT2_PRIMED", "IT2_AXIS_STATE_SIZE",
           "IT2_AXIS_STATE_PORTS"]

N_MF = 3  # I = J, membership functions per input
N_RULES = N_MF * N_MF  # I * J rules

C1 = slice(0, 3)
C2 = slice(3, 6)
SIGMA1 = slice(6, 9)
SIGMA2 = slice(9, 12)
F = slice(12, 21)
ALPHA = 21
X1_PREV = 22
X2_PREV = 23
PRIMED = 24
AXIS_STATE_SIZE = 25

# Name and unit of every element of the axis state, in layout order: how the
# learned parameters are published (``f_12`` is the rule of MF 1 of x1 and MF
# 2 of x2; the co-simulation component appends the axis, ``f_12_x``).
AXIS_STATE_PORTS: tuple[tuple[str, str], ...] = (
    *((f"c1_{i}", "m") for i in range(1, N_MF + 1)),
    *((f"c2_{j}", "m/s") for j in range(1, N_MF + 1)),
    *((f"sigma1_{i}", "m") for i in range(1, N_MF + 1)),
    *((f"sigma2_{j}", "m/s") for j in range(1, N_MF + 1)),
    *((f"f_{i}{j}", "m/s") for j in range(1, N_MF + 1) for i in range(1, N_MF + 1)),  # k = j * I + i
    ("alpha", "m/s2"), ("x1_prev", "m"), ("x2_prev", "m/s"), ("primed", "1"),
)
assert len(AXIS_STATE_PORTS) == AXIS_STATE_SIZE

# The IT2 layout (fnn_controller.it2, which names these Q, X1_PREV, ...): the type-1 layout with q
# inserted after alpha.
IT2_Q = ALPHA + 1
IT2_X1_PREV, IT2_X2_PREV, IT2_PRIMED = IT2_Q + 1, IT2_Q + 2, IT2_Q + 3
IT2_AXIS_STATE_SIZE = AXIS_STATE_SIZE + 1

IT2_AXIS_STATE_PORTS: tuple[tuple[str, str], ...] = (
    *AXIS_STATE_PORTS[:IT2_Q], ("q", "1"), *AXIS_STATE_PORTS[IT2_Q:],
)
assert len(IT2_AXIS_STATE_PORTS) == IT2_AXIS_STATE_SIZE
