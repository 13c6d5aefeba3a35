"""A foreign FMU beside our plant: a wind source in km/h, built with
PythonFMU (a test extra) into the test's folder, flies in a scenario with the
plant and the controller; its connection to the plant's wind inputs (m/s)
states the unit conversion. PythonFMU declares no units (its variables take
no ``unit``), so the connection is not checked by units: the scenario states
the factor, 1/3.6 (docs/cosim.md, "Units")."""
from __future__ import annotations

import textwrap
import tomllib

import numpy as np
import pytest

from cosim.scenario.definition import parse_scenario
from cosim.scenario.assembly import build_master

pythonfmu = pytest.importorskip("pythonfmu", reason="pythonfmu (a test extra) is not installed")

KMH_TO_MS = 0.2777777777777778  # 1000 / 3600 as a double: km/h -> m/s

WIND_SOURCE = '''
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class KmhWind(Fmi2Slave):
    """A periodic wind in km/h (north and east), none vertically."""

    description = "periodic wind, km/h"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.speed = 18.0  # km/h, the amplitude
        self.period = 2.0  # s
        self.v_north = self.v_east = self.v_down = 0.0
        for name in ("v_north", "v_east", "v_down"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))
        for name in ("speed", "period"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        phase = 2.0 * math.pi * (current_time + step_size) / self.period
        self.v_north = self.speed * math.sin(phase)
        self.v_east = -0.5 * self.speed * math.sin(phase)
        return True
'''


@pytest.fixture(scope="module")
def wind_fmu(tmp_path_factory):
    from pythonfmu.builder import FmuBuilder

    folder = tmp_path_factory.mktemp("pythonfmu")
    script = folder / "kmh_wind.py"
    script.write_text(WIND_SOURCE)
    return FmuBuilder.build_FMU(script, dest=folder)


def _scenario(wind_fmu, connection: str, speed: float):
    text = textwrap.dedent(f"""
        name = "foreign_wind"
        connections = [
            {connection},
            "reference.{{x,y,z,vx,vy,vz}} -> controller.{{x_ref,y_ref,z_ref,vx_ref,vy_ref,vz_ref}}",
            "reference.{{ax,ay,az}} -> controller.{{ax_ref,ay_ref,az_ref}}",
            "Quadrotor.{{x,y,z,u,v,w,phi,theta,psi,p,q,r}} -> controller.{{x,y,z,u,v,w,phi,theta,psi,p,q,r}}",
            "controller.Omega_{{1,2,3,4}} -> Quadrotor.Omega_{{1,2,3,4}}",
        ]

        [simulation]
        duration = 4.0
        step = 0.01

        [fmus.Quadrotor]
        model = "Quadrotor"
        parameters = {{ z_0 = -15.0 }}

        [fmus.Wind]
        path = "{wind_fmu}"
        parameters = {{ speed = {speed!r} }}

        [trajectory]
        kind = "hover"
        x = 0.0
        y = 0.0
        z = -15.0

        [controller]
        variant = "pd+lm"

        [record]
        signals = ["Wind.v_north", "Wind.v_east", "Quadrotor.wind_x", "Quadrotor.wind_y", "Quadrotor.wind_z",
                   "Quadrotor.x", "Quadrotor.y", "Quadrotor.z"]
    """)
    return parse_scenario(tomllib.loads(text))


def _fly(scenario):
    with build_master(scenario) as master:
        return master.run(scenario.duration)


CONVERTED = ('{ connect = "Wind.v_{north,east,down} -> Quadrotor.wind_{x,y,z}", factor = 0.2777777777777778, '
             'offset = 0.0 }')
AS_IT_IS = '"Wind.v_{north,east,down} -> Quadrotor.wind_{x,y,z}"'


def test_a_pythonfmu_wind_in_km_per_h_flies_beside_the_plant_converted(wind_fmu):
    converted = _fly(_scenario(wind_fmu, CONVERTED, 18.0))
    assert converted.status == "ok"
    # the plant's wind inputs are the source's values converted, at every communication point
    np.testing.assert_array_equal(converted["Quadrotor.wind_x"], KMH_TO_MS * converted["Wind.v_north"])
    np.testing.assert_allclose(converted["Quadrotor.wind_y"], converted["Wind.v_east"] / 3.6, rtol=1e-15, atol=0)
    assert np.max(np.abs(converted["Quadrotor.wind_x"])) == pytest.approx(5.0, rel=1e-3)  # 18 km/h = 5 m/s

    # the plant felt the converted wind: the same source in m/s (its amplitude / 3.6) and a plain
    # connection fly the same flight, to round-off
    in_m_per_s = _fly(_scenario(wind_fmu, AS_IT_IS, 18.0 / 3.6))
    for name in ("Quadrotor.x", "Quadrotor.y", "Quadrotor.z"):
        np.testing.assert_allclose(converted[name], in_m_per_s[name], rtol=0, atol=1e-9, err_msg=name)

    # and the conversion matters: the km/h values taken as m/s (3.6 times the wind) push it further off
    unconverted = _fly(_scenario(wind_fmu, AS_IT_IS, 18.0))
    drift = lambda r: np.max(np.hypot(r["Quadrotor.x"], r["Quadrotor.y"]))  # noqa: E731
    assert drift(unconverted) > 2.0 * drift(converted) > 0.0
