"""The reference trajectory FMUs (ReferenceHover, ReferenceTwoCircles,
ReferenceFigureEight): validation, the same numbers as the Python path of the
same CasADi definition over whole missions, and their parameter ranges."""
from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy import read_model_description
from tests.catalog_fmus import simulated
from tests.fmu_validation import validate_fmu

from cosim.errors import FmuCallError
from cosim.fmi.fmu import FmuComponent
from fmu_models.catalog import MODELS
from fmu_models.export.build import FMI_VERSIONS, cached_fmu
from fmu_models.models.reference import (OUTPUT_NAMES, REFERENCE_FIGURE_EIGHT, REFERENCE_HOVER, REFERENCE_MODELS,
                                         REFERENCE_TWO_CIRCLES, check_parameter, evaluate, evaluate_outputs)

VERSIONS = sorted(FMI_VERSIONS)
IDENTIFIERS = sorted(REFERENCE_MODELS)

# (model, parameters, mission duration in s): the paper's missions and variations of them
CASES = [
    (REFERENCE_TWO_CIRCLES, {}, 50.0),
    (REFERENCE_TWO_CIRCLES, {"speed": 1.0, "radius": 4.0}, 50.0),
    (REFERENCE_TWO_CIRCLES, {"radius": 3.0, "speed": 1.7, "climb": -2.0, "x0": 1.0, "y0": -2.0, "z0": -7.0}, 50.0),
    (REFERENCE_TWO_CIRCLES, {"radius": 2.0, "speed": 4.0, "climb": 10.0}, 20.0),  # path done at 6.5 s, then holds
    (REFERENCE_FIGURE_EIGHT, {}, 60.0),
    (REFERENCE_FIGURE_EIGHT, {"max_speed": 1.3, "half_length": 3.1, "half_width": 0.7, "z0": -2.0}, 60.0),
    (REFERENCE_FIGURE_EIGHT, {"max_speed": 0.4, "half_length": 1.0, "half_width": 2.5, "x0": -1.0}, 60.0),
    (REFERENCE_HOVER, {}, 10.0),
    (REFERENCE_HOVER, {"x0": 1.5, "y0": -2.0, "z0": -3.0}, 10.0),
]


def _case_id(case):
    model, params, _ = case
    return model.identifier + "".join(f"-{k}={v:g}" for k, v in params.items())


def test_in_the_catalog():
    for identifier, model in REFERENCE_MODELS.items():
        assert MODELS[identifier] is model
        assert model.states == () and model.inputs == ()
        assert tuple(v.name for v in model.outputs) == OUTPUT_NAMES


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("identifier", IDENTIFIERS)
def test_validates(identifier, version):
    assert validate_fmu(str(cached_fmu(REFERENCE_MODELS[identifier], version))) == []


@pytest.mark.parametrize("identifier", IDENTIFIERS)
def test_model_description_declares_units_descriptions_and_ranges(identifier):
    model = REFERENCE_MODELS[identifier]
    md = read_model_description(str(cached_fmu(model, 2)))
    declared = {v.name: v for v in md.modelVariables}
    for name in OUTPUT_NAMES:
        v = declared[name]
        assert v.causality == "output" and v.unit == {"x": "m", "v": "m/s", "a": "m/s2"}[name[0] if len(name) > 1 else "x"] and v.description
    for p in model.parameters:
        v = declared[p.name]
        assert v.causality == "parameter" and v.unit == p.unit and v.description == p.description
        assert float(v.start) == p.start
        assert (float(v.min) if v.min is not None else -math.inf) == p.min
        assert (float(v.max) if v.max is not None else math.inf) == p.max
        if p.name != "internal_step":
            assert math.isfinite(p.min) and math.isfinite(p.max)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_fmu_outputs_equal_the_python_path_over_the_mission(case, version):
    """Co-simulation over the whole mission at 0.01 s: every communication
    point equals the Python evaluation of the same CasADi definition."""
    model, params, duration = case
    r = simulated(cached_fmu(model, version), stop_time=duration, output_interval=0.01,
                          start_values=params, validate=False, output=list(OUTPUT_NAMES))
    assert len(r) == round(duration / 0.01) + 1
    fmu = np.column_stack([r[name] for name in OUTPUT_NAMES])
    np.testing.assert_allclose(fmu, evaluate_outputs(model, r["time"], params), rtol=0, atol=1e-12)


@pytest.mark.parametrize("identifier", IDENTIFIERS)
def test_model_exchange_gives_the_same_outputs(identifier):
    model = REFERENCE_MODELS[identifier]
    r = simulated(cached_fmu(model, 2), stop_time=30.0, output_interval=0.25,
                          fmi_type="ModelExchange", validate=False, output=list(OUTPUT_NAMES))
    np.testing.assert_allclose(np.column_stack([r[n] for n in OUTPUT_NAMES]), evaluate_outputs(model, r["time"], {}),
                               rtol=0, atol=1e-12)


def test_two_circles_known_points():
    """Start point, the quarter of the first circle (east of the start by R,
    north by R), the crossing back at the tangent point, and the hold."""
    model = REFERENCE_TWO_CIRCLES
    vh = 2.5 / math.sqrt(1 + (5.0 / (20 * math.pi)) ** 2)
    circle = 20 * math.pi
    p, v = evaluate(model, np.array([0.0, circle / 4 / vh, circle / vh, 2 * circle / vh + 1.0]), {})
    np.testing.assert_allclose(p[0], [0.0, 0.0, -15.0], atol=1e-12)
    np.testing.assert_allclose(p[1], [10.0, 10.0, -16.25], atol=1e-12)
    np.testing.assert_allclose(p[2], [0.0, 0.0, -20.0], atol=1e-12)
    np.testing.assert_allclose(p[3], [0.0, 0.0, -15.0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(v[:3], axis=1), 2.5, rtol=1e-14)
    np.testing.assert_array_equal(v[3], 0.0)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model, name, value", [
    (REFERENCE_TWO_CIRCLES, "radius", -10.0), (REFERENCE_TWO_CIRCLES, "radius", 0.0),
    (REFERENCE_TWO_CIRCLES, "speed", 341.0), (REFERENCE_TWO_CIRCLES, "climb", 2e4),
    (REFERENCE_FIGURE_EIGHT, "half_width", 1e-4), (REFERENCE_FIGURE_EIGHT, "max_speed", -1.0),
    (REFERENCE_HOVER, "z0", -2e4), (REFERENCE_HOVER, "x0", math.inf),
], ids=lambda x: getattr(x, "identifier", str(x)))
def test_out_of_range_parameters_are_refused(model, name, value, version):
    """The FMU refuses the value with a message naming it, and Python refuses
    the same value from the same declaration."""
    variable = model.variable(name)
    with pytest.raises(ValueError, match=f"^{name} = "):
        check_parameter(variable, value)
    with pytest.raises(ValueError):
        model.parameter_values(**{name: value})
    with FmuComponent(model.identifier, cached_fmu(model, version)) as fmu:
        with pytest.raises(FmuCallError) as info:
            fmu.start(0.0, {name: value})
    assert info.value.variable == name
    assert f"{name} = " in info.value.log and "refused" in info.value.log


@pytest.mark.parametrize("model, name", [(m, v.name) for m in REFERENCE_MODELS.values() for v in m.parameters
                                         if v.name != "internal_step"],
                         ids=lambda x: getattr(x, "identifier", str(x)))
def test_the_bounds_themselves_are_admitted_and_fly(model, name):
    """Each parameter at either end of its range (the others at their start
    values): accepted, and the whole first 20 s give finite outputs."""
    variable = model.variable(name)
    for bound in (variable.min, variable.max):
        check_parameter(variable, bound)
        r = simulated(cached_fmu(model, 2), stop_time=20.0, output_interval=0.1,
                              start_values={name: bound}, validate=False, output=list(OUTPUT_NAMES))
        fmu = np.column_stack([r[n] for n in OUTPUT_NAMES])
        assert np.all(np.isfinite(fmu))
        np.testing.assert_allclose(fmu, evaluate_outputs(model, r["time"], {name: bound}), rtol=0,
                                   atol=1e-12 * max(1.0, abs(bound)))


@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_the_acceleration_is_the_derivative_of_the_velocity(case):
    """a* (the symbolic derivative) equals the central difference of v*
    wherever the path is smooth over the difference's 2 ms (not at the jumps
    of the curvature: the start, the tangent point, the end)."""
    model, params, duration = case
    h = 1e-3
    t = np.linspace(0.0, duration, 4001)
    y = evaluate_outputs(model, t, params)
    ahead, behind = evaluate_outputs(model, t + h, params), evaluate_outputs(model, t - h, params)
    difference = (ahead[:, 3:6] - behind[:, 3:6]) / (2 * h)
    curvature_same = np.all(np.abs(ahead[:, 6:9] - behind[:, 6:9]) < 0.05, axis=1)  # no jump in between
    assert curvature_same.mean() > 0.95
    np.testing.assert_allclose(y[curvature_same, 6:9], difference[curvature_same], rtol=0, atol=1e-5)
    if model is REFERENCE_TWO_CIRCLES:  # centripetal: v_h^2 / R while the circles are flown
        from fmu_models.models.reference import two_circles_timing

        radius = params.get("radius", 10.0)
        _, vh, path_time = two_circles_timing(radius, params.get("speed", 2.5), params.get("climb", 5.0))
        flying = curvature_same & (t > 0) & (t < path_time)
        np.testing.assert_allclose(np.hypot(y[flying, 6], y[flying, 7]), vh ** 2 / radius, rtol=1e-9)
