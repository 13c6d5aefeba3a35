"""The engine's linearizer on a controller FMU (Co-Simulation, sampled
data): its one-period map z+ = A z + B u, y = C z + D u agrees with the
CasADi Jacobian of the step function the product runs
(``parametric_step_function``), the learned state part of z."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from cosim.linearize.linearization import linearize_fmu
from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import STATE_NAMES
from fnn_controller.controller_fmu import ACCELERATION_INPUTS, REFERENCE_INPUTS, controller_model
from fnn_controller.parametric import parameter_vector, parametric_step_function
from fnn_controller.step import OUTPUTS

REFS = [name for name, _, _ in REFERENCE_INPUTS]
ACCS = [name for name, _, _ in ACCELERATION_INPUTS]


def _point(rng):
    """A point near hover: plant at rest, tilted 0.01 rad, references 0.015 m and 0.006 m/s off it.
    Every rotor command stays inside its range (the rotor inversion's clip is not differentiable at its
    edges), also with the first step's rate of the velocity command from its zero initial value."""
    x = np.r_[rng.normal(size=3), np.zeros(3), rng.normal(size=3) * 0.006, rng.normal(size=3) * 0.015]
    refs = np.r_[x[:3] + rng.normal(size=3) * 0.015, rng.normal(size=3) * 0.006]
    return dict(zip(REFS, refs)) | dict(zip(STATE_NAMES, x)) | dict(zip(ACCS, rng.normal(size=3) * 0.01))


def _casadi_jacobian(variant, z, u):
    f = parametric_step_function(variant)
    sym = {n: ca.MX.sym(n, f.sparsity_in(n)) for n in f.name_in()}
    out = f.call(sym)
    knowns = ca.vertcat(sym["state"], sym["p_ref"], sym["p_ref_dot"], sym["x"], sym["p_ref_ddot"])
    unknowns = ca.vertcat(out["state_next"], out["y"])
    jac = ca.Function("j", list(sym.values()), [ca.densify(ca.jacobian(unknowns, knowns))])
    values = {"p_ref": [u[n] for n in REFS[:3]], "p_ref_dot": [u[n] for n in REFS[3:]],
              "x": [u[n] for n in STATE_NAMES], "psi_ref": 0.0, "state": z, "p": parameter_vector(variant),
              "p_ref_ddot": [u[n] for n in ACCS]}
    return np.array(jac(*[values[n] for n in f.name_in()]))


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("variant", ["pd", "pd+lm"])
def test_controller_fmu_linearization_is_the_jacobian_of_its_step(variant, version):
    path = cached_fmu(controller_model(variant), version)
    u = _point(np.random.default_rng(19))
    lin = linearize_fmu(path, inputs=u, parameters={"seed": 3} if variant != "pd" else {})
    assert lin.system.dt == 0.01
    z_names, in_names = list(lin.system.state_labels), list(lin.system.input_labels)
    assert in_names == REFS + list(STATE_NAMES) + ACCS
    assert list(lin.system.output_labels) == [name for name, _, _ in OUTPUTS]
    z = np.array([lin.operating_point[n] for n in z_names])
    J = _casadi_jacobian(variant, z, u)
    nz = len(z_names)
    fmu = np.block([[lin.A, lin.B], [lin.C, lin.D]])
    assert fmu.shape == J.shape
    # central differences: round-off eps^(2/3) relative to each row's scale
    scale = np.maximum(np.max(np.abs(J), axis=1, keepdims=True), 1.0)
    assert np.max(np.abs(fmu - J) / scale) <= 1e-6
    assert lin.error_estimate <= 1e-5 * np.max(np.abs(J))
    if variant == "pd+lm":
        assert nz > 0 and np.any(lin.A != np.eye(nz))  # the learned state moves with the step
