"""The co-simulation master: end to end with two FMUs and the controller, every
refusal with its message, divergence, partial results of failed and killed runs."""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from cosim.component import Port, PythonComponent, ports
from cosim.errors import ConnectionCheckError, DivergenceError, FmuCallError
from cosim.fmi.fmu import FmuComponent
from cosim.loop.master import Master
from cosim.loop.recorder import read_results, sidecar_path
from cosim.scenario.definition import load_scenario
from cosim.scenario.assembly import build_master
from fmu_models.export.build import cached_fmu
from fmu_models.catalog import MODELS
from fmu_models.models.quadrotor import hover_rotor_speed
from tests.catalog_fmus import catalog_fmu

WIND_TO_PLANT = "WindGust.v_wind_{x,y,z} -> Quadrotor.wind_{x,y,z}"
ROTORS_TO_PLANT = "standin.Omega_{1,2,3,4} -> Quadrotor.Omega_{1,2,3,4}"


class ConstantRotors(PythonComponent):
    """Stand-in controller: fixed rotor speeds (hover by default), reads z."""

    inputs = ports(("z", "m"))
    outputs = ports(*[(f"Omega_{i}", "rad/s") for i in range(1, 5)])

    def __init__(self, name="standin", speeds=None):
        super().__init__(name)
        self.y = np.array(speeds if speeds is not None else [hover_rotor_speed()] * 4, dtype=float)

    def step(self, n, t, u):
        return self.y


class Failing(ConstantRotors):
    """Raises (or outputs NaN) from a given time on."""

    def __init__(self, name="standin", at=0.5, mode="raise"):
        super().__init__(name)
        self.at, self.mode = at, mode

    def step(self, n, t, u):
        if t >= self.at:
            if self.mode == "raise":
                raise RuntimeError(f"stand-in failure at t = {t}")
            return np.full(4, np.nan)
        return self.y


@pytest.fixture(scope="module")
def fmu_paths():
    return {name: catalog_fmu(model, 2) for name, model in MODELS.items()}


@pytest.fixture
def fmus(fmu_paths):
    made = [FmuComponent("Quadrotor", fmu_paths["Quadrotor"]), FmuComponent("WindGust", fmu_paths["WindGust"])]
    yield made
    for f in made:
        f.close()


def _master(fmus, standin=None, connections=(WIND_TO_PLANT, ROTORS_TO_PLANT, "Quadrotor.z -> standin.z"), **kw):
    kw.setdefault("record", ["Quadrotor.x", "Quadrotor.z", "Quadrotor.phi", "Quadrotor.wind_x"])
    kw.setdefault("fmu_parameters", {"Quadrotor": {"z_0": -15.0}})
    return Master(fmus, [standin or ConstantRotors()], list(connections), 0.01, **kw)


# ---- end to end -------------------------------------------------------------------

def test_end_to_end_two_fmus_and_controller(tmp_path):
    """The shipped mission, shortened to 3 s: WindGust + Quadrotor + reference + PD+LM."""
    scenario = load_scenario("circles", {"simulation.duration": 3.0, "wind.speed": 3.0})
    with build_master(scenario) as master:
        result = master.run(scenario.duration, seed=3, csv_path=tmp_path / "r.csv")
    assert result.status == "ok" and result.data.shape[0] == 301
    np.testing.assert_array_equal(result.time, 0.01 * np.arange(301))
    # the gust reaches the plant: 3 m/s along [-1, -1, 0] / sqrt(2)
    np.testing.assert_allclose(result["Quadrotor.wind_x"], -3 / math.sqrt(2))
    # the controller flies the reference: within 1.5 m of it after 3 s, and it moved
    err = np.linalg.norm(np.column_stack([result[f"Quadrotor.{a}"] - result[f"reference.{a}"] for a in "xyz"]), axis=1)
    assert err.max() < 1.5
    assert abs(result["Quadrotor.x"][-1]) > 3.0
    columns, data = read_results(tmp_path / "r.csv")
    assert columns == list(result.columns)
    np.testing.assert_allclose(data, result.data, rtol=1e-9, atol=1e-12)


def test_runs_are_reproducible_after_reset(fmus):
    master = _master(fmus)
    a = master.run(1.0, parameters={"WindGust.v_w": 5.0})
    master.run(0.5, parameters={"WindGust.v_w": 1.0})
    b = master.run(1.0, parameters={"WindGust.v_w": 5.0})
    np.testing.assert_array_equal(a.data, b.data)
    assert a["Quadrotor.x"][-1] < -0.01  # pushed downwind (north component of the wind is negative)


def test_fmu_outputs_reach_python_components_at_the_same_time(fmus):
    """Gauss-Seidel within a communication point: the stand-in sees z(t_n)."""
    seen = []

    class Spy(ConstantRotors):
        def step(self, n, t, u):
            seen.append(u[0])
            return self.y

    master = _master(fmus, Spy(), record=["Quadrotor.z"])
    result = master.run(0.2)
    np.testing.assert_array_equal(np.array(seen), result["Quadrotor.z"])


# ---- refusals ---------------------------------------------------------------------

@pytest.mark.parametrize("connection, message", [
    ("WindGust.v_wind_q -> Quadrotor.wind_x", "source WindGust.v_wind_q does not exist"),
    ("WindGust.v_wind_x -> Quadrotor.nope", "destination Quadrotor.nope does not exist"),
    ("Wind.v_wind_x -> Quadrotor.wind_x", "unknown component 'Wind'"),
    ("Quadrotor.wind_x -> Quadrotor.wind_y", "source Quadrotor.wind_x is an input, not an output"),
    ("WindGust.v_wind_x -> Quadrotor.x", "destination Quadrotor.x is an output, not an input"),
    ("WindGust.v_wind_x -> Quadrotor.m", "destination Quadrotor.m is a parameter, not an input"),
    ("WindGust.v_wind_x -> Quadrotor.Omega_1", "unit mismatch, WindGust.v_wind_x is in m/s (SI m.s-1) but "
                                               "Quadrotor.Omega_1 is in rad/s (SI s-1.rad), not one quantity"),
    ("WindGust.v_wind_x", "must be a string 'A.out -> B.in'"),
])
def test_bad_connection_is_refused_naming_it(fmus, connection, message):
    with pytest.raises(ConnectionCheckError) as info:
        _master(fmus, connections=[WIND_TO_PLANT.replace("{x,y,z}", "{y,z}").replace("wind_{y,z}", "wind_{y,z}"),
                                   ROTORS_TO_PLANT, "Quadrotor.z -> standin.z", connection])
    assert message in str(info.value)
    if "->" in connection:
        assert connection.strip() in str(info.value)


def test_type_mismatch_is_refused(fmus):
    class Counter(ConstantRotors):
        outputs = (Port("count", None, "Int32"),) + ConstantRotors.outputs

    with pytest.raises(ConnectionCheckError, match=r"standin.count -> Quadrotor.wind_x: type mismatch, "
                                                   r"standin.count is Int32 but Quadrotor.wind_x is Float64"):
        _master(fmus, Counter(), connections=[ROTORS_TO_PLANT, "Quadrotor.z -> standin.z",
                                              "standin.count -> Quadrotor.wind_x"])


def test_input_fed_twice_is_refused(fmus):
    with pytest.raises(ConnectionCheckError, match="Quadrotor.wind_x is already fed by WindGust.v_wind_x"):
        _master(fmus, connections=[WIND_TO_PLANT, ROTORS_TO_PLANT, "Quadrotor.z -> standin.z",
                                   "WindGust.v_wind_y -> Quadrotor.wind_x"])


def test_unconnected_python_input_and_unknown_record_signal_are_refused(fmus):
    with pytest.raises(ConnectionCheckError, match="inputs of standin not connected: z"):
        _master(fmus, connections=[WIND_TO_PLANT, ROTORS_TO_PLANT])
    with pytest.raises(ConnectionCheckError, match="signal 'Quadrotor.altitude'.*has no output or input 'altitude'"):
        _master(fmus, record=["Quadrotor.altitude"])


def test_algebraic_loop_among_python_components_is_refused(fmus):
    class Echo(PythonComponent):
        inputs = ports(("a", "m"))
        outputs = ports(("b", "m"))

        def step(self, n, t, u):
            return u

    with pytest.raises(ConnectionCheckError, match="algebraic loop: e1 -> e2 -> e1;"):
        Master(fmus, [Echo("e1"), Echo("e2")], ["e1.b -> e2.a", "e2.b -> e1.a"], 0.01)


# ---- divergence, failures, partial results ------------------------------------------

def test_flip_stops_the_run_naming_time_signal_and_value(fmus, tmp_path):
    w = hover_rotor_speed()
    master = _master(fmus, ConstantRotors(speeds=[w, w * 0.9, w, w * 1.1]),
                     bounds={"Quadrotor.phi": (-1.2, 1.2), "Quadrotor.theta": (-1.2, 1.2)})
    csv = tmp_path / "flip.csv"
    with pytest.raises(DivergenceError) as info:
        master.run(10.0, csv_path=csv)
    err = info.value
    assert err.signal == "Quadrotor.phi" and abs(err.value) > 1.2 and 0.1 < err.time < 10.0
    assert f"diverged at t = {err.time:.4f} s: Quadrotor.phi = " in str(err)
    assert "outside its envelope [-1.2, 1.2]" in str(err)
    # the partial result: every row up to and including the violation, in memory and on disk
    partial = err.result
    assert partial.status == "diverged" and partial.time[-1] == pytest.approx(err.time)
    columns, data = read_results(csv)
    np.testing.assert_allclose(data[:, 0], partial.time)
    assert '"status": "diverged"' in sidecar_path(csv).read_text()


def test_nan_stops_the_run(fmus):
    master = _master(fmus, Failing(at=0.25, mode="nan"))
    with pytest.raises(DivergenceError, match=r"t = 0.2500 s: standin.Omega_1 = nan is not a finite number"):
        master.run(1.0)


def test_envelope_violation(fmus):
    master = _master(fmus, ConstantRotors(speeds=[0.0] * 4), bounds={"Quadrotor.z": (-100.0, -14.0)})
    with pytest.raises(DivergenceError, match=r"Quadrotor.z = -13.9.* is outside its envelope \[-100, -14\]") as info:
        master.run(5.0)
    # free fall: z(t) = -15 + g t^2 / 2 crosses -14 at t = sqrt(2 / g) (minus drag, a bit later)
    assert info.value.time == pytest.approx(math.sqrt(2 / 9.81), abs=0.03)


def test_exception_mid_run_keeps_the_rows_before_it(fmus, tmp_path):
    master = _master(fmus, Failing(at=0.5))
    csv = tmp_path / "partial.csv"
    with pytest.raises(RuntimeError, match="stand-in failure"):
        master.run(5.0, csv_path=csv, block_rows=7)
    columns, data = read_results(csv)
    np.testing.assert_allclose(data[:, 0], 0.01 * np.arange(50))  # t = 0 .. 0.49
    assert '"status": "failed"' in sidecar_path(csv).read_text()


def test_fmu_error_is_reported_with_the_fmu_log(fmus):
    master = _master(fmus)
    with pytest.raises(FmuCallError, match=r"Quadrotor \(.*Quadrotor.fmu\): setting parameter m = -1.0 failed "
                                           r".*FMU log: \[ERROR\] m = -1 refused") as refused:
        master.run(0.1, parameters={"Quadrotor.m": -1.0})
    assert (refused.value.variable, refused.value.value) == ("m", -1.0)
    assert refused.value.log.startswith("[ERROR] m = -1 refused")
    assert master.run(0.1).status == "ok"  # the instance is still usable


def test_a_refused_start_raises_even_where_run_failures_are_returned(fmus, tmp_path):
    """Nothing ran, so there is no result to return: the refusal is raised, and
    the results file that was opened says why."""
    master = _master(fmus)
    csv = tmp_path / "refused.csv"
    with pytest.raises(FmuCallError, match="m = -1 refused"):
        master.run(0.1, parameters={"Quadrotor.m": -1.0}, csv_path=csv, raise_on_error=False)
    sidecar = sidecar_path(csv).read_text()
    assert '"status": "failed"' in sidecar and "could not start" in sidecar and "m = -1 refused" in sidecar
    assert read_results(csv)[1].shape[0] == 0


def test_killed_run_leaves_a_readable_partial_result(tmp_path, fmu_paths):
    """SIGKILL mid-run: the CSV holds every flushed block and reads back.

    The child's stand-in controller, once four blocks of 10 rows are flushed
    (step 45), says so on stdout and waits on stdin; it is killed right then,
    so the test races no clock."""
    csv = tmp_path / "killed.csv"
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_master_with_the_plant import ConstantRotors, _master
        from cosim.fmi.fmu import FmuComponent

        class WaitsToBeKilled(ConstantRotors):
            def step(self, n, t, u):
                if n == 45:
                    print("flushed", flush=True)
                    sys.stdin.readline()
                return self.y

        fmus = [FmuComponent("Quadrotor", {str(fmu_paths['Quadrotor'])!r}),
                FmuComponent("WindGust", {str(fmu_paths['WindGust'])!r})]
        _master(fmus, WaitsToBeKilled()).run(100.0, csv_path={str(csv)!r}, block_rows=10)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=Path(__file__).parents[2],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        said = proc.stdout.readline()  # blocks until step 45, or returns "" if the child ended
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdin.close()
        proc.stdout.close()
    assert said == "flushed\n", "the run ended before it could be killed"
    columns, data = read_results(csv)
    assert columns[0] == "time" and len(data) == 40  # rows 0..39, four blocks of 10; row 40.. unflushed
    np.testing.assert_allclose(data[:, 0], 0.01 * np.arange(len(data)))
    assert '"status": "running"' in sidecar_path(csv).read_text()


def test_duration_must_be_whole_steps(fmus):
    with pytest.raises(ValueError, match="not a positive whole number of steps"):
        _master(fmus).run(0.015)


def test_fmi3_fmu_runs_like_fmi2():
    """Both FMI versions through the same master: one core, one result. An
    FMI 3.0 build that fails (FmuBuildError) fails this test."""
    results = []
    for version in (2, 3):
        fmus = [FmuComponent(name, cached_fmu(MODELS[name], version)) for name in ("Quadrotor", "WindGust")]
        assert [f.fmi_version for f in fmus] == [version, version]
        with _master(fmus) as master:
            results.append(master.run(1.0, parameters={"WindGust.v_w": 3.0}).data)
    np.testing.assert_array_equal(results[0], results[1])
