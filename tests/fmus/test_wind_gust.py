"""The WindGust FMU: the paper's gust of Fig. 5, ramps, turbulence, and the FMU itself."""
from __future__ import annotations

import math

import numpy as np
import pytest
from tests.catalog_fmus import simulated
from tests.fmu_validation import validate_fmu

from fmu_models.export.build import cached_fmu
from fmu_models.models.wind_gust import WIND_GUST, gust_speed_factor


@pytest.fixture(scope="module")
def wind_fmu():
    return cached_fmu(WIND_GUST, 2)


def _simulate(path, stop=50.0, **start_values):
    return simulated(path, stop_time=stop, output_interval=0.01, start_values=start_values,
                             validate=False, output=["v_wind_x", "v_wind_y", "v_wind_z"])


def test_paper_gust_profile(wind_fmu):
    """v_w along [-1, -1, 0]/sqrt(2) before 17 s, opposite until 34 s, back after (section 5.3)."""
    r = _simulate(wind_fmu, v_w=3.0)
    t = r["time"]
    expected = -3.0 / math.sqrt(2) * np.where((t >= 17.0 - 1e-9) & (t < 34.0 - 1e-9), -1.0, 1.0)
    np.testing.assert_allclose(r["v_wind_x"], expected, atol=1e-12)
    np.testing.assert_allclose(r["v_wind_y"], expected, atol=1e-12)
    np.testing.assert_array_equal(r["v_wind_z"], 0.0)
    # the switch happens exactly at the 1700th step (t = 17.00 s) whichever way n*h rounds
    i = int(np.argmin(np.abs(t - 17.0)))
    assert r["v_wind_x"][i - 1] < 0 < r["v_wind_x"][i]


def test_direction_is_normalized_and_speed_scales(wind_fmu):
    r = _simulate(wind_fmu, stop=1.0, v_w=2.0, dir_x=1.0, dir_y=-1.0, dir_z=0.0)
    np.testing.assert_allclose(r["v_wind_x"], math.sqrt(2))
    np.testing.assert_allclose(r["v_wind_y"], -math.sqrt(2))
    r = _simulate(wind_fmu, stop=1.0, v_w=5.0, dir_x=0.0, dir_y=0.0, dir_z=-7.0)
    np.testing.assert_allclose(r["v_wind_z"], -5.0)


def test_ramp_reversal_is_linear():
    for t, s in [(16.9, 1.0), (17.0, 1.0), (17.5, 0.0), (17.75, -0.5), (18.0, -1.0), (34.5, 0.0), (40.0, 1.0)]:
        assert float(gust_speed_factor(t, 17.0, 34.0, 1.0)) == pytest.approx(s)


def test_turbulence_rms_determinism_and_seed(wind_fmu):
    a = _simulate(wind_fmu, stop=400.0, v_w=0.0, turbulence=0.5, turbulence_seed=3)
    b = _simulate(wind_fmu, stop=400.0, v_w=0.0, turbulence=0.5, turbulence_seed=3)
    c = _simulate(wind_fmu, stop=400.0, v_w=0.0, turbulence=0.5, turbulence_seed=4)
    for axis in ("v_wind_x", "v_wind_y", "v_wind_z"):
        np.testing.assert_array_equal(a[axis], b[axis])
        assert np.sqrt(np.mean(a[axis] ** 2)) == pytest.approx(0.5, rel=0.15)
        assert abs(np.mean(a[axis])) < 0.1
        assert not np.allclose(a[axis], c[axis])


def test_zero_state_model_builds_and_runs_in_both_interfaces(wind_fmu):
    assert WIND_GUST.states == ()
    for kind in ("CoSimulation", "ModelExchange"):
        r = simulated(wind_fmu, stop_time=20.0, output_interval=0.5, fmi_type=kind, validate=False,
                              start_values={"v_w": 1.0})
        assert r["v_wind_x"][0] == pytest.approx(-1 / math.sqrt(2))
        assert r["v_wind_x"][-1] == pytest.approx(1 / math.sqrt(2))


@pytest.mark.parametrize("version", [2, 3])
def test_validates(version):
    """The stateless model passes fmpy's validation in every FMI version built."""
    from fmu_models.export.build import FMI_VERSIONS

    if version not in FMI_VERSIONS:
        pytest.skip(f"FMI {version} export not available")
    assert validate_fmu(str(cached_fmu(WIND_GUST, version))) == []
