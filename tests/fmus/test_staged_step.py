"""The EKFs' step generated as a chain of functions (fmu_models/export/staged.py,
docs/estimation.md "The generated C"): the same numbers as the step with its
laws inlined, bit for bit (the generated C's null checks: test_c_spelling.py)."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_models.models.estimator import ESTIMATOR, ESTIMATOR_GM


@pytest.mark.parametrize("model", [ESTIMATOR, ESTIMATOR_GM], ids=lambda m: m.identifier)
def test_the_step_in_pieces_is_the_inlined_step_bit_for_bit(model):
    """Outputs and next discrete state of ``dstep`` (an MX chain of pieces and
    called laws) and of ``inlined_step`` (one SX graph, every law inlined)
    are the same doubles over 60 noisy steps with fresh fixes and outliers."""
    step, inlined = model.functions["dstep"], model.inlined_step
    assert step.class_name() == "MXFunction" and inlined.class_name() == "SXFunction"
    names = [v.name for v in model.inputs]
    rng = np.random.default_rng(3)
    p = model.parameter_values(z_0=-10.0)
    z = np.array(model.functions["dinit"](p, [])).ravel()
    for n in range(60):
        u = np.array(model.input_values(), float) + rng.normal(scale=0.05, size=len(names))
        u[names.index("fresh")] = n % 3 == 0
        u[names.index("t_imu")] = u[names.index("t_fix")] = n * 0.01
        u[names.index("x_m")] += 10.0 if n % 20 > 12 else 0.0  # outliers the gate refuses (E19)
        y, z_next = (np.array(a).ravel() for a in step(n * 0.01, u, p, z))
        y_inline, z_inline = (np.array(a).ravel() for a in inlined(n * 0.01, u, p, z))
        assert y.tobytes() == y_inline.tobytes() and z_next.tobytes() == z_inline.tobytes(), n
        z = z_next

