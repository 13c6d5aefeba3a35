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



@pytest.mark.parametrize("identifier", ["Quadrotor", "CommandLink4", "Measurement12"])
def test_the_dependency_kinds_are_those_read_entry_by_entry(identifier):
    """The modelDescription's dependencies and their kinds, read from one sparsity
    pattern of the Jacobian's entries in the variable part and the parameters at
    once (fmu_models/export/model_description.py), are what ``ca.depends_on`` says
    of each entry of the Jacobian, one entry and one symbol set at a time: a
    continuous model (derivatives and outputs on states and inputs) and two
    sampled-data ones (outputs on inputs; the command link draws numbers at each step)."""
    from fmu_models.catalog import model as catalog_model
    from fmu_models.export.model_description import dependency_kinds
    from fmu_models.lazy_casadi import ca

    model = catalog_model(identifier)
    s, f = model.symbols, model.functions
    t, x, u, p, z, rs = s["t"], s["x"], s["u"], s["p"], s["z"], s["rs"]
    if model.sampled is not None:  # rs: the fresh random numbers of a step, where the model draws them
        args = (t, u, p, z, rs) if model.sampled.n_random_step else (t, u, p, z)
        unknowns, variable = model.inlined_step(*args)[0], ca.vertcat(t, u, z, rs)
    else:
        unknowns, variable = ca.vertcat(f["ode"](t, x, u, p), f["out"](t, x, u, p)), ca.vertcat(t, x, u)
    jac = ca.jacobian(unknowns, ca.vertcat(x, u))
    rows = [f"der({v.name})" for v in model.states] + [v.name for v in model.outputs]
    known = [v.name for v in model.states + model.inputs]
    expected = {row: [(known[c], "dependent" if ca.depends_on(jac[r, c], variable)
                       else "fixed" if ca.depends_on(jac[r, c], p) else "constant")
                      for c in range(len(known)) if jac.sparsity().has_nz(r, c)]
                for r, row in enumerate(rows)}
    kinds = dependency_kinds(model)
    assert kinds == expected
    assert "dependent" in {kind for deps in kinds.values() for _, kind in deps}  # not vacuous
