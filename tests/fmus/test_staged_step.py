"""The EKFs' step generated as a chain of functions (fmu_models/export/staged.py,
docs/estimation.md "The generated C"): the same numbers as the step with its
laws inlined, bit for bit, and the generated C's null checks left out only
where no null pointer can come."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_models.export import staged
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


def test_null_checks_are_left_out_of_called_functions_only():
    """An entry point keeps its checks; a function the step calls loses them;
    with a null pointer passed anywhere the text is left as it was."""
    c = (b"static int casadi_f1(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem) {\n"
         b"  a0=arg[0]? arg[0][3] : 0;\n  if (res[1]!=0) res[1][2]=a0;\n  return 0;\n}\n"
         b"static int casadi_f0(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem) {\n"
         b"  a0=arg[0]? arg[0][3] : 0;\n  if (res[1]!=0) res[1][2]=a0;\n  return 0;\n}\n"
         b"int model_dstep(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem){\n"
         b"  return casadi_f0(arg, res, iw, w, mem);\n}\n")
    out = staged.without_null_checks(c)
    called, entry = out.split(b"static int casadi_f0")
    assert b"a0=arg[0][3];" in called and b"  res[1][2]=a0;" in called and b"?" not in called
    assert entry.count(b"arg[0]? arg[0][3] : 0") == 1 and b"if (res[1]!=0)" in entry
    passed_null = c.replace(b"  return 0;\n}\nstatic int casadi_f0", b"  res1[4]=0;\n  return 0;\n}\nstatic int casadi_f0", 1)
    assert staged.without_null_checks(passed_null) == passed_null
