"""Initialization by the standard: connected inputs set in Initialization
Mode until the FMUs' initial outputs settle (FMI 2.0 §3.2.3, FMI 3.0
§2.3.4), an algebraic loop at t0 that does not settle refused by name.

Two running sums (``y = s + u``, a direct feedthrough; ``s`` starts at
``s_0``) fed by each other are an algebraic loop at t0 in the exchange
ordering (the feedthrough ordering refuses it when planning): with
``s_0 = (1, -1)`` the loop ``y_A = 1 + y_B``, ``y_B = -1 + y_A`` has the
solutions ``y_A = y_B + 1``, and the passes settle on ``y_A = 0``,
``y_B = -1`` from the outputs before the first pass (1, -1); with
``s_0 = (1, 1)`` it has none, and every pass adds one."""
from __future__ import annotations

import pytest

from cosim.errors import ConnectionCheckError
from cosim.fmi.fmu import FmuComponent
from cosim.loop.master import Master
from toy_models import sum_fmu_path


def running_sums(version: int, s_a: float, s_b: float) -> Master:
    a = FmuComponent("A", sum_fmu_path(version), parameters={"s_0": s_a})
    b = FmuComponent("B", sum_fmu_path(version), parameters={"s_0": s_b})
    return Master([a, b], [], ["A.y -> B.u", "B.y -> A.u"], 0.01, record=["A.y", "B.y", "A.u"],
                  ordering="exchange")


@pytest.mark.parametrize("version", [2, 3])
def test_a_loop_at_t0_that_settles_starts_consistent(version):
    with running_sums(version, 1.0, -1.0) as master:
        row0 = master.run(0.03).data[0]
    time, y_a, y_b, u_a = row0
    assert (y_a, y_b) == (0.0, -1.0)
    assert u_a == y_b  # the input A started with is the output it is connected to


@pytest.mark.parametrize("version", [2, 3])
def test_a_loop_at_t0_that_does_not_settle_is_refused_naming_it(version):
    with running_sums(version, 1.0, 1.0) as master:
        with pytest.raises(ConnectionCheckError, match=r"initialization at t0 = 0.0 s: the FMUs' outputs did not "
                                                       r"settle after 100 passes .* through A.y -> B.u, B.y -> A.u\): "
                                                       r"break it with a delay"):
            master.run(0.03)


def test_a_chain_declared_against_its_order_settles_too():
    """B feeds A although A comes first: one more pass, the same start."""
    a = FmuComponent("A", sum_fmu_path(2), parameters={"s_0": 2.0})
    b = FmuComponent("B", sum_fmu_path(2), parameters={"s_0": 5.0})
    with Master([a, b], [], ["B.y -> A.u"], 0.01, record=["A.y", "B.y"]) as master:
        time, y_a, y_b = master.run(0.01).data[0]
    assert (y_a, y_b) == (7.0, 5.0)
