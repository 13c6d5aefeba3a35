"""The closed loop from the FMUs (plant ME + controller CS step, through the
engine's linearizer) is the loop of the CasADi analysis for the PD baseline,
and gives a spectral radius for a learning variant."""
from __future__ import annotations

import numpy as np
import pytest

from quadrotor_paper.stability import LoopModel, forward_flight, hover
from quadrotor_paper.stability.fmu_loop import fmu_closed_loop


@pytest.mark.parametrize("make_op", [hover, lambda: forward_flight(2.5)], ids=["hover", "forward"])
def test_pd_loop_from_the_fmus_has_the_casadi_loops_spectral_radius(make_op):
    op = make_op()
    loop = fmu_closed_loop(op, "pd")
    casadi = np.max(np.abs(np.linalg.eigvals(np.asarray(LoopModel(op, dt=op.position.dt).closed_loop().A))))
    assert loop.system.dt == op.position.dt
    assert loop.spectral_radius < 1.0
    assert loop.spectral_radius == pytest.approx(casadi, abs=1e-6)
    # the PD's FNN weights are inert; the velocity controller's memory is not
    assert 0 < len(loop.inert) < loop.system.nstates - 12


def test_the_sign_law_is_not_differentiable_at_the_equilibrium_and_the_error_estimate_says_so():
    """At the trimmed point the sliding variable is 0, where the paper's
    sign law (phi = 0) jumps: the differences of the step do not converge
    and the estimate is large. The boundary layer's smooth law (phi > 0)
    has a linearization there, and the estimate is at round-off level."""
    sign = fmu_closed_loop(hover(), "pd+lm", controller_parameters={"seed": 1})
    smooth = fmu_closed_loop(hover(), "pd+lm", controller_parameters={"seed": 1, "phi_x": 0.05, "phi_y": 0.05,
                                                                      "phi_z": 0.05})
    assert sign.controller.error_estimate > 1.0
    assert smooth.controller.error_estimate < 1e-3
    assert np.isfinite(smooth.spectral_radius) and smooth.system.nstates > 12
