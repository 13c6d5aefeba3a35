"""The calibrator's Levenberg-Marquardt (cosim/calibration/marquardt.py): the
Schur step, bounds, rejected trial points; the estimated states' bounds from
the model description (issue 42, items 4 and 6; docs/calibration.md)."""
from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from cosim.calibration.marquardt import levenberg_marquardt, schur_step


def _shooting_jacobian(rng, nt: int, ne: int, nseg: int, rows: int = 7) -> sparse.csr_matrix:
    """A Jacobian of multiple shooting's layout: each segment's rows on the
    fitted names and its own states, a continuity row on the names and two
    neighbouring segments' states."""
    n = nt + ne * nseg
    blocks = []
    for i in range(nseg):
        b = np.zeros((rows, n))
        b[:, :nt] = rng.standard_normal((rows, nt))
        b[:, nt + i * ne:nt + (i + 1) * ne] = rng.standard_normal((rows, ne))
        blocks.append(b)
    for i in range(nseg - 1):
        c = np.zeros((ne, n))
        c[:, :nt] = rng.standard_normal((ne, nt))
        c[:, nt + i * ne:nt + (i + 1) * ne] = 1e3 * rng.standard_normal((ne, ne))
        c[:, nt + (i + 1) * ne:nt + (i + 2) * ne] = -1e3 * np.eye(ne)
        blocks.append(c)
    return sparse.csr_matrix(np.vstack(blocks))


def test_the_schur_step_is_the_dense_normal_equations_step():
    rng = np.random.default_rng(0)
    nt, ne, nseg = 3, 4, 5
    J = _shooting_jacobian(rng, nt, ne, nseg)
    g = J.T @ rng.standard_normal(J.shape[0])
    H = (J.T @ J).tocsr()
    damping = 1e-2 * H.diagonal()
    dense = np.linalg.solve(H.toarray() + np.diag(damping), -g)
    free = np.ones(g.size, bool)
    for A in (H, H.toarray()):  # sparse and dense alike
        step = schur_step(A, g, damping, nt, ne, free)
        assert np.allclose(step, dense, rtol=1e-9, atol=1e-12 * np.abs(dense).max())
    # held unknowns (a fitted name and a state at a bound): out of the system, the rest solved without them
    free[[1, nt + 6]] = False
    Hd = H.toarray()[np.ix_(free, free)] + np.diag(damping[free])
    expected = np.zeros(g.size)
    expected[free] = np.linalg.solve(Hd, -g[free])
    assert np.allclose(schur_step(H, g, damping, nt, ne, free), expected, rtol=1e-9,
                       atol=1e-12 * np.abs(expected).max())


def _exponentials(t, y):
    """Residuals of y = a exp(-k t) + c, unknowns (a, k, c), and their Jacobian."""
    def fun(z):
        return z[0] * np.exp(-z[1] * t) + z[2] - y

    def jac(z):
        e = np.exp(-z[1] * t)
        return np.column_stack([e, -z[0] * t * e, np.ones_like(t)])
    return fun, jac


def test_without_states_it_reaches_least_squares_optimum_and_holds_an_active_bound():
    t = np.linspace(0, 4, 60)
    y = 2.0 * np.exp(-0.7 * t) + 0.3 + 0.01 * np.random.default_rng(1).standard_normal(t.size)
    fun, jac = _exponentials(t, y)
    z0 = np.array([1.0, 2.0, 0.0])
    for upper in (np.full(3, np.inf), np.array([np.inf, np.inf, 0.1])):  # c's bound below its optimum: active
        lower = np.array([0.0, 0.0, -np.inf])
        ours = levenberg_marquardt(fun, jac, z0, lower, upper, np.ones(3), 3, 0, 1e-12, 1e-12, 1e-12, 100)
        ref = least_squares(fun, z0, jac=jac, bounds=(lower, upper), ftol=1e-12, xtol=1e-12, gtol=1e-12)
        assert ours.status > 0 and ours.nfev < 30
        assert ours.cost <= ref.cost * (1 + 1e-9)
        assert np.allclose(ours.x, ref.x, rtol=1e-6, atol=1e-8)
        assert np.all(ours.x <= upper) and np.all(ours.x >= lower)
    assert ours.x[2] == 0.1  # at the bound exactly: held there, not approached


def test_a_trial_point_whose_residuals_are_not_finite_is_rejected_and_the_step_shortened():
    # the FMU refuses k above 0.75 (a simulation that fails: infinite residuals); the optimum, k = 0.7, is below
    t = np.linspace(0, 4, 60)
    y = 2.0 * np.exp(-0.7 * t) + 0.3
    fun, jac = _exponentials(t, y)
    tried = []

    def refusing(z):
        tried.append(z[1])
        return np.full(t.size, np.inf) if z[1] > 0.75 else fun(z)

    result = levenberg_marquardt(refusing, jac, np.array([4.0, 0.2, 0.0]), np.full(3, -np.inf), np.full(3, np.inf),
                                 np.ones(3), 3, 0, 1e-14, 1e-14, 1e-14, 200)
    assert max(tried) > 0.75  # it did step there
    assert result.status > 0 and np.allclose(result.x, [2.0, 0.7, 0.3], rtol=1e-8)


def test_multiple_shooting_with_states_bounded_below():
    # x' = -k x on three segments, each's start estimated (a state bounded below by 0.5: the first segment's
    # optimum start, 1.0, is feasible; the truth's later starts below 0.5 are not: held at 0.5), continuity weighted
    k_true, h, rows, nseg = 0.8, 0.1, 10, 3
    t = np.arange(rows) * h
    y = [np.exp(-k_true * (t + i * rows * h)) for i in range(nseg)]
    w = 1e3

    def fun(z):
        k, x0 = z[0], z[1:]
        out = [x0[i] * np.exp(-k * t) - y[i] for i in range(nseg)]
        out += [w * (x0[i] * np.exp(-k * rows * h) - x0[i + 1]) for i in range(nseg - 1)]
        return np.concatenate([np.atleast_1d(o) for o in out])

    def jac(z):
        k, x0 = z[0], z[1:]
        J = np.zeros((nseg * rows + nseg - 1, 1 + nseg))
        for i in range(nseg):
            J[i * rows:(i + 1) * rows, 0] = -t * x0[i] * np.exp(-k * t)
            J[i * rows:(i + 1) * rows, 1 + i] = np.exp(-k * t)
        for i in range(nseg - 1):
            e = np.exp(-k * rows * h)
            J[nseg * rows + i, [0, 1 + i, 2 + i]] = [-w * rows * h * x0[i] * e, w * e, -w]
        return sparse.csr_matrix(J)

    lower = np.array([0.0, 0.5, 0.5, 0.5])
    z0 = np.array([0.3, 1.0, 0.9, 0.8])
    ours = levenberg_marquardt(fun, jac, z0, lower, np.full(4, np.inf), np.ones(4), 1, 1, 1e-12, 1e-12, 1e-12, 200)
    ref = least_squares(fun, z0, jac=lambda z: jac(z).toarray(), bounds=(lower, np.inf), ftol=1e-12, xtol=1e-12,
                        gtol=1e-12)
    assert ours.status > 0 and np.all(ours.x >= lower)
    assert ours.cost <= ref.cost * (1 + 1e-8)
    assert np.allclose(ours.x, ref.x, rtol=1e-5)


def test_the_plants_estimated_states_are_bounded_by_the_model_description():
    # Omega_r_1 has no min, the parameter that starts it, Omega_r_1_0, has min 0 (issue 42: a fit drove it to
    # -1185 and the FMU refused it); theta_0 is within +-1.55 rad
    from cosim.calibration.solve import state_bounds
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model as catalog_model

    class Model:  # what state_bounds reads of a LogModel
        pass

    from cosim.fmi.fmu import FmuComponent

    comp = FmuComponent("plant", built_fmu("Quadrotor", 2, lambda: catalog_model("Quadrotor")))
    try:
        m = Model()
        m.cs, m.states = comp, ["x", "theta", "Omega_r_1"]
        m.setters = {s: f"{s}_0" for s in m.states}
        lo, hi = state_bounds(m)
    finally:
        comp.close()
    assert lo.tolist() == [-np.inf, -1.55, 0.0] and hi.tolist() == [np.inf, 1.55, np.inf]
