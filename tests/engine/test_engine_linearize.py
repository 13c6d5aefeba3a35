"""Known answers of the generic linearizer (cosim.linearize.linearization): linear FMUs
exported by the project's exporter from random A, B, C, D come back.

Continuous (Model Exchange): der(x) = A x + B u, y = C x + D u, exactly with
directional derivatives (<= 1e-12), to 1e-6 relative with central
differences. Sampled data (Co-Simulation): z+ = A z + B u, y = C z + D u over
one period, dt on the StateSpace.
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest

from cosim.linearize.linearization import LinearizationError, linearize_fmu
from fmu_models.export.build import cached_fmu
from fmu_models.export.model import FmuModel, Sampled
from fmu_models.export.variables import discrete, input_, output, parameter, state
from tests.engine.toy_models import lag_fmu_path

NX, NU, NY = 3, 2, 2
_RNG = np.random.default_rng(19)
A, B, C, D = (_RNG.normal(size=s) for s in ((NX, NX), (NX, NU), (NY, NX), (NY, NU)))
PERIOD = 0.02


def _affine(M, names, v):
    return [sum(float(M[i, j]) * v[n] for j, n in enumerate(names)) for i in range(M.shape[0])]


X = [f"x{i}" for i in range(NX)]
U = [f"u{j}" for j in range(NU)]
Y = [f"y{i}" for i in range(NY)]


def _linear(v):
    """``(A x + B u, C x + D u)`` by name: the right-hand side (continuous) or the next state
    (discrete), and the outputs."""
    ax, cx = _affine(A, X, v), _affine(C, X, v)
    bu, du = _affine(B, U, v), _affine(D, U, v)
    return {n: ax[i] + bu[i] for i, n in enumerate(X)}, {n: cx[i] + du[i] for i, n in enumerate(Y)}


def _continuous_equations(t, v):
    return _linear(v)


LINEAR = FmuModel(
    identifier="ToyLinearContinuous",
    description="der(x) = A x + B u, y = C x + D u with random A, B, C, D",
    variables=(*(state(n, "m", "state") for n in X), *(input_(n, "N", "input") for n in U),
               *(output(n, "m/s", "output") for n in Y)),
    equations=_continuous_equations,
    initial_state=lambda v: {n: 0.0 for n in X},
)


def _discrete_update(t, v):
    z_next, y = _linear(v)
    return y, z_next


LINEAR_DISCRETE = FmuModel(
    identifier="ToyLinearDiscrete",
    description="z+ = A z + B u, y = C z + D u with random A, B, C, D",
    variables=(*(input_(n, "N", "input") for n in U), *(output(n, "m/s", "output") for n in Y),
               parameter("dt", "s", "sample period", PERIOD, min=1e-6),
               *(discrete(n, "m", "discrete state") for n in X)),
    sampled=Sampled(update=_discrete_update, initial=lambda v, r: {n: 0.0 for n in X}, n_random=0, seed=None,
                    sample_period="dt"),
)


@functools.lru_cache(maxsize=None)
def _fmu(model, version):
    return cached_fmu(model, version)


POINT = dict(start={"x0": 0.3, "x1": -1.2, "x2": 2.0}, inputs={"u0": 0.7, "u1": -0.4})


def _assert_system(lin, tol, relative, states_are_outputs):
    # the exporter makes a continuous model's states outputs too (so they can be connected): rows I and 0
    CC = np.vstack([np.eye(NX), C]) if states_are_outputs else C
    DD = np.vstack([np.zeros((NX, NU)), D]) if states_are_outputs else D
    for got, want in zip((lin.A, lin.B, lin.C, lin.D), (A, B, CC, DD)):
        if relative:
            assert np.max(np.abs(got - want)) <= tol * np.max(np.abs(want))
        else:
            assert np.max(np.abs(got - want)) <= tol
    assert list(lin.system.state_labels) == X
    assert list(lin.system.input_labels) == U
    assert list(lin.system.output_labels) == (X + Y if states_are_outputs else Y)
    assert lin.units["x0"] == "m" and lin.units["u1"] == "N" and lin.units["y0"] == "m/s"


@pytest.mark.parametrize("version", [2, 3])
def test_a_random_linear_model_exchange_fmu_comes_back_exactly_with_directional_derivatives(version):
    lin = linearize_fmu(_fmu(LINEAR, version), **POINT)
    assert lin.method == "directional derivatives"
    assert lin.system.dt == 0
    _assert_system(lin, 1e-12, relative=False, states_are_outputs=True)
    assert lin.operating_point["x1"] == -1.2


@pytest.mark.parametrize("version", [2, 3])
def test_a_random_linear_model_exchange_fmu_comes_back_with_central_differences(version):
    lin = linearize_fmu(_fmu(LINEAR, version), method="differences", **POINT)
    assert lin.method == "central differences"
    _assert_system(lin, 1e-6, relative=True, states_are_outputs=True)
    assert lin.error_estimate <= 1e-6 * np.max(np.abs(A))


@pytest.mark.parametrize("version", [2, 3])
def test_a_random_linear_sampled_fmu_gives_its_one_period_map(version):
    lin = linearize_fmu(_fmu(LINEAR_DISCRETE, version), **POINT)
    assert lin.system.dt == PERIOD
    assert lin.method == "central differences"
    _assert_system(lin, 1e-6, relative=True, states_are_outputs=False)


def test_a_nonlinear_lag_is_linearized_at_its_operating_point():
    lin = linearize_fmu(lag_fmu_path(2), parameters={"tau": 0.25, "k": 3.0}, inputs={"u": 1.0})
    np.testing.assert_allclose([lin.A[0, 0], lin.B[0, 0], lin.C[1, 0], lin.D[1, 0]],
                               [-4.0, 12.0, -4.0, 12.0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("kwargs, words", [
    (dict(inputs={"nope": 1.0}), "input 'nope': the FMU has no such variable"),
    (dict(inputs={"u0": float("nan")}), "input u0 = nan: not a finite number"),
    (dict(start={"u0": 1.0}), "start value 'u0'"),
    (dict(method="magic"), "method 'magic'"),
])
def test_bad_operating_points_are_one_line(kwargs, words):
    with pytest.raises(LinearizationError, match=words) as info:
        linearize_fmu(_fmu(LINEAR, 2), **kwargs)
    assert "\n" not in str(info.value)


def test_a_black_box_co_simulation_step_is_refused_in_one_line():
    with pytest.raises(LinearizationError, match="declares no sample period") as info:
        linearize_fmu(lag_fmu_path(2), interface="cs")
    assert "\n" not in str(info.value)


# ---- the component's Model Exchange calls, on the Modelica Association's Reference FMUs -------------

_REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"


@pytest.mark.skipif(not _REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {_REFERENCE}")
@pytest.mark.parametrize("version", [2, 3])
def test_the_components_model_exchange_calls_on_the_reference_fmus(version):
    """What the linearizer evaluates, against the models' equations:
    BouncingBall (der(h) = v, der(v) = -g; one event indicator, h) and
    VanDerPol (der(x0) = x1, der(x1) = mu (1 - x0^2) x1 - x0; directional
    derivatives, FMI 3.0's flag read from the XML, fmpy 0.3 misreads it)."""
    from cosim.fmi.fmu import FmuComponent

    with FmuComponent("ball", _REFERENCE / f"fmi{version}" / "BouncingBall.fmu", interface="ModelExchange") as ball:
        ball.start(0.0)
        assert ball.state_names == ["h", "v"] and ball.event_indicator_count == 1
        np.testing.assert_array_equal(ball.continuous_states(), [1.0, 0.0])
        g = ball.get_reals(["g"])["g"]
        ball.set_continuous_states(np.array([0.5, -2.0]))
        np.testing.assert_array_equal(ball.derivatives(), [-2.0, g])
        np.testing.assert_array_equal(ball.event_indicators(), [0.5])
        np.testing.assert_array_equal(ball.nominals(), [1.0, 1.0])
    with FmuComponent("vdp", _REFERENCE / f"fmi{version}" / "VanDerPol.fmu", interface="ModelExchange") as vdp:
        vdp.start(0.0, {"mu": 1.5})
        assert vdp.provides_directional_derivatives
        x0, x1 = 2.0, 0.5
        vdp.set_continuous_states(np.array([x0, x1]))
        J = vdp.directional_derivatives(vdp.derivative_names, vdp.state_names)
        np.testing.assert_allclose(J, [[0.0, 1.0], [-2 * 1.5 * x0 * x1 - 1.0, 1.5 * (1 - x0 ** 2)]], rtol=1e-15)
        lin = linearize_fmu(_REFERENCE / f"fmi{version}" / "VanDerPol.fmu", parameters={"mu": 1.5},
                            start={"x0": x0, "x1": x1})
        assert lin.method == "directional derivatives"
        np.testing.assert_allclose(lin.A, J, rtol=1e-15)
