"""The master end to end on a toy loop: a P controller around a first-order lag FMU.

Step semantics (``cosim/loop/master.py``): at ``t_n = t0 + n h`` the FMU outputs
are those at ``t_n``; the Python components are evaluated at ``t_n`` in the
order of their connections (direct feedthrough); then every FMU gets its
inputs taken at ``t_n`` and steps to ``t_{n+1}`` with them held. For the loop

    src.out = R,   ctrl.u = kp (R - y),   dy/dt = (k u - y) / tau

that gives the recurrence ``u_n = kp (R - y_n)``,
``y_{n+1} = k u_n + (y_n - k u_n) exp(-h / tau)`` (exact for u held), which
the FMU's internal RK4 reproduces to round-off.
"""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from cosim.errors import ConnectionCheckError, DivergenceError, FmuCallError
from cosim.fmi.fmu import FmuComponent
from cosim.loop.master import Master
from cosim.loop.recorder import read_results, sidecar_path
from toy_models import (LAG_K, LAG_TAU, Constant, Failing, Gain, PController, Probe, Step, lag_fmu2,  # noqa: F401
                        lag_fmu3, lag_step)

H = 0.1  # s
DURATION = 3.0  # s: 30 steps
N = 30
R = 1.0
KP = 1.5
Y0 = 0.2
TOL = 1e-9
LOOP = ["src.out -> ctrl.r", "lag.y -> ctrl.y", "ctrl.u -> lag.u"]
RECORD = ["lag.y", "ctrl.u", "lag.u", "lag.rate"]


@pytest.fixture
def lag(lag_fmu2):
    fmu = FmuComponent("lag", lag_fmu2)
    yield fmu
    fmu.close()


def closed_loop(fmu, record=RECORD, y0=Y0, kp=KP, **kw):
    # declared controller first: the master must still evaluate the source before it
    comps = [PController("ctrl", kp=kp), Constant("src", value=R)]
    kw.setdefault("fmu_parameters", {fmu.name: {"y_0": y0}})
    return Master([fmu], comps, LOOP, H, record=record, **kw), comps


def expected_loop(n_steps=N, y0=Y0, kp=KP, tau=LAG_TAU, k=LAG_K, r=R):
    """Rows (y_n, u_n, rate_n) of the recurrence. The lag's output ``rate``
    depends directly on its input, so in the feedthrough ordering the master
    evaluates the lag at t_n after the controller: rate_n = (k u_n - y_n)/tau."""
    ys, us, rates = [], [], []
    y = y0
    for _ in range(n_steps + 1):
        u = kp * (r - y)
        ys.append(y)
        us.append(u)
        rates.append((k * u - y) / tau)
        y = lag_step(y, u, H, tau, k)
    return np.array(ys), np.array(us), np.array(rates)


# ---- the closed loop, known answer -----------------------------------------------------------

def test_closed_loop_matches_the_exact_recurrence(lag):
    master, (ctrl, src) = closed_loop(lag)
    result = master.run(DURATION, seed=7)
    assert result.status == "ok" and result.error is None
    assert result.n_steps == N and result.step == H and result.seed == 7
    assert result.data.shape == (N + 1, 5)
    y, u, rate = expected_loop()
    np.testing.assert_allclose(result["lag.y"], y, rtol=0, atol=TOL)
    np.testing.assert_allclose(result["ctrl.u"], u, rtol=0, atol=TOL)
    np.testing.assert_allclose(result["lag.rate"], rate, rtol=0, atol=TOL)
    # by hand: y_1 = k u_0 + (y_0 - k u_0) e^{-h/tau}, u_0 = kp (R - y_0) = 1.2
    assert result["lag.y"][1] == pytest.approx(2.4 - 2.2 * math.exp(-0.2), abs=TOL)
    # the loop settles at the fixed point k kp R / (1 + k kp) = 0.75
    assert result["lag.y"][-1] == pytest.approx(0.75, abs=TOL)
    # every component was started once with (t0, h, n_steps, seed)
    assert ctrl.starts == src.starts == [(0.0, H, N, 7)]


def test_open_loop_follows_the_exact_exponential(lag):
    """Constant input: y(t) = k u + (y_0 - k u) exp(-t / tau) at every t_n."""
    master = Master([lag], [Constant("src", value=0.5)], ["src.out -> lag.u"], H, record=["lag.y"],
                    fmu_parameters={"lag": {"y_0": -1.0}})
    result = master.run(DURATION)
    t = np.arange(N + 1) * H
    np.testing.assert_allclose(result["lag.y"], LAG_K * 0.5 + (-1.0 - LAG_K * 0.5) * np.exp(-t / LAG_TAU),
                               rtol=0, atol=TOL)


def test_inputs_are_held_from_t_n_over_the_step(lag):
    """A step of the input at t = 0.3 s (a communication point) acts from 0.3 s
    on, not before: y stays 0 up to 0.3 s, then y = k (1 - exp(-(t - 0.3) / tau))."""
    master = Master([lag], [Step("src", before=0.0, after=1.0, at=0.3)], ["src.out -> lag.u"], H,
                    record=["lag.y", "lag.u"])
    result = master.run(1.0)
    t = result.time
    expected = np.where(t < 0.3 - 1e-9, 0.0, LAG_K * (1 - np.exp(-np.maximum(t - 0.3, 0.0) / LAG_TAU)))
    np.testing.assert_allclose(result["lag.y"], expected, rtol=0, atol=TOL)
    assert result["lag.y"][3] == 0.0 and result["lag.y"][4] > 0.0
    np.testing.assert_array_equal(result["lag.u"], np.where(t < 0.3 - 1e-9, 0.0, 1.0))


def test_python_components_see_fmu_outputs_at_the_same_time(lag):
    """Direct feedthrough: at t_n a Python component reads the FMU output at
    t_n (not t_{n-1}), and components run in connection order, not declaration order."""
    probe = Probe("probe")
    comps = [probe, Gain("g2", gain=3.0), Gain("g1", gain=2.0), Constant("src", value=1.0)]
    conns = ["src.out -> lag.u", "lag.y -> g1.u", "g1.y -> g2.u", "g2.y -> probe.y"]
    with Master([lag], comps, conns, H, record=["lag.y", "g2.y"]) as master:
        result = master.run(1.0)
    assert [c[0] for c in probe.calls] == list(range(11))
    seen = np.array([c[2][0] for c in probe.calls])
    np.testing.assert_array_equal(seen, 6.0 * result["lag.y"])
    np.testing.assert_array_equal(result["g2.y"], 6.0 * result["lag.y"])
    assert lag._slave is None  # the context manager closed the FMU


def test_two_fmus_are_coupled_by_jacobi_with_held_values(lag_fmu2):
    """lag2 sees lag1.y at t_n held over [t_n, t_{n+1}]: y2_{n+1} = step(y2_n, y1_n)."""
    first, second = FmuComponent("lag1", lag_fmu2), FmuComponent("lag2", lag_fmu2)
    with Master([first, second], [Constant("src", value=1.0)], ["src.out -> lag1.u", "lag1.y -> lag2.u"], H,
                record=["lag1.y", "lag2.y"], fmu_parameters={"lag2": {"k": 0.5, "tau": 0.2}}) as master:
        result = master.run(2.0)
    y1, y2 = [0.0], [0.0]
    for _ in range(20):
        y1, y2 = y1 + [lag_step(y1[-1], 1.0, H)], y2 + [lag_step(y2[-1], y1[-1], H, tau=0.2, k=0.5)]
    np.testing.assert_allclose(result["lag1.y"], y1, rtol=0, atol=TOL)
    np.testing.assert_allclose(result["lag2.y"], y2, rtol=0, atol=TOL)


# ---- time ------------------------------------------------------------------------------------

def test_time_comes_from_the_step_counter(lag):
    """t_n = t0 + n h exactly (no accumulated sum), in the record, in every
    Python call, and for the FMU (which refuses a doStep at the wrong time)."""
    t0 = 0.1
    probe = Probe("probe")
    master = Master([lag], [Constant("src", value=1.0), probe], ["src.out -> lag.u", "lag.y -> probe.y"], H,
                    record=["lag.y"])
    result = master.run(DURATION, t0=t0)
    expected = t0 + np.arange(N + 1) * H
    np.testing.assert_array_equal(result.time, expected)
    np.testing.assert_array_equal([c[1] for c in probe.calls], expected)
    accumulated = np.concatenate([[t0], t0 + np.cumsum(np.full(N, H))])
    assert not np.array_equal(accumulated, expected)  # the test can tell the two apart
    # the FMU was initialized at t0: the solution is the one started at t0
    np.testing.assert_allclose(result["lag.y"], LAG_K * (1 - np.exp(-(expected - t0) / LAG_TAU)), rtol=0, atol=TOL)


def test_progress_is_reported_per_block_and_at_the_end(lag):
    calls = []
    master, _ = closed_loop(lag)
    master.run(DURATION, block_rows=10, progress=lambda n, total: calls.append((n, total)))
    assert calls == [(9, N), (19, N), (29, N), (N, N)]


# ---- recording -------------------------------------------------------------------------------

def test_recorded_columns_units_and_inputs(lag):
    master, _ = closed_loop(lag)
    result = master.run(1.0)
    assert result.columns == ("time", "lag.y", "ctrl.u", "lag.u", "lag.rate")
    assert result.units == ("s", "m", "m", "m", "m/s")
    # an input is recorded as the value its source gives it
    np.testing.assert_array_equal(result["lag.u"], result["ctrl.u"])
    with pytest.raises(KeyError, match="signal 'lag.k' was not recorded; recorded: time, lag.y"):
        result["lag.k"]


@pytest.mark.parametrize("record, message", [
    (["lag.nope"], "signal 'lag.nope': lag has no output or input 'nope'; it has: y, rate, u"),
    (["nope.y"], "signal 'nope.y': unknown component 'nope'"),
    (["lag.u"], "signal 'lag.u' is an input that nothing feeds; record its source"),
])
def test_bad_record_signals_are_refused(lag, record, message):
    with pytest.raises(ConnectionCheckError, match=re.escape(message)):
        Master([lag], [Constant("src")], [], H, record=record)


def test_record_none_records_every_output_of_every_component(lag):
    """What a scenario without record.signals records: the FMUs' outputs,
    then the Python components' (docs/cosim.md, "Recording")."""
    master = Master([lag], [Constant("src")], ["src.out -> lag.u"], H, record=None)
    assert list(master.record_columns) == ["time"] + [f"lag.{p.name}" for p in lag.outputs] + ["src.out"]


def test_record_signal_without_a_variable_is_refused_as_malformed(lag):
    with pytest.raises(ConnectionCheckError) as info:
        Master([lag], [Constant("src")], ["src.out -> lag.u"], H, record=["lag"])
    assert "unknown component" not in str(info.value)
    assert "component.variable" in str(info.value)


def test_results_csv_holds_the_run_and_its_sidecar(lag, tmp_path):
    path = tmp_path / "run" / "results.csv"
    master, _ = closed_loop(lag, record=["lag.y", "ctrl.u"])
    result = master.run(DURATION, seed=3, csv_path=path, block_rows=7)
    assert result.csv_path == path
    columns, data = read_results(path)
    assert columns == ["time", "lag.y", "ctrl.u"]
    assert data.shape == (N + 1, 3)
    np.testing.assert_allclose(data, result.data, rtol=1e-9, atol=1e-12)  # 10 significant digits
    info = json.loads(sidecar_path(path).read_text())
    assert info["status"] == "ok" and info["error"] is None
    assert info["columns"] == ["time", "lag.y", "ctrl.u"] and info["units"] == ["s", "m", "m"]
    assert info["rows"] == N + 1 and info["step"] == H and info["t0"] == 0.0 and info["seed"] == 3


def test_results_are_streamed_in_blocks_while_the_run_goes(lag, tmp_path):
    """At t_25, with blocks of 10 rows, rows 0..19 are on disk and the sidecar says running."""
    path = tmp_path / "results.csv"
    seen = {}

    def look(n, t, u):
        if n == 25:
            seen["rows"] = len(read_results(path)[1])
            seen["status"] = json.loads(sidecar_path(path).read_text())["status"]

    probe = Probe("probe", hook=look)
    master = Master([lag], [Constant("src"), probe], ["src.out -> lag.u", "lag.y -> probe.y"], H, record=["lag.y"])
    master.run(DURATION, csv_path=path, block_rows=10)
    assert seen == {"rows": 20, "status": "running"}
    assert len(read_results(path)[1]) == N + 1


def test_rows_before_an_exception_are_kept_and_readable(lag, tmp_path):
    """A component raising at t = 1.3 s (n = 13): rows 0..12 are in the CSV,
    the sidecar says failed with the exception, the exception propagates."""
    path = tmp_path / "results.csv"
    master = Master([lag], [Failing("fail", at=1.25)], ["fail.out -> lag.u"], H, record=["lag.y"])
    with pytest.raises(RuntimeError, match="toy failure at n = 13"):
        master.run(DURATION, csv_path=path, block_rows=100, raise_on_error=False)
    columns, data = read_results(path)
    assert data.shape == (13, 2)
    t = np.arange(13) * H
    np.testing.assert_allclose(data[:, 1], LAG_K * (1 - np.exp(-t / LAG_TAU)), rtol=1e-9, atol=1e-12)
    info = json.loads(sidecar_path(path).read_text())
    assert info["status"] == "failed" and info["error"] == "RuntimeError: toy failure at n = 13"
    assert info["rows"] == 13


def test_internal_signals_are_recorded_and_bounded_but_not_connected(lag):
    """ctrl publishes error = R - y: recorded like an output, read only when asked for."""
    master, (ctrl, _) = closed_loop(lag, record=["lag.y", "ctrl.error"])
    result = master.run(DURATION)
    np.testing.assert_allclose(result["ctrl.error"], R - expected_loop()[0], rtol=0, atol=TOL)
    assert result.units[2] == "m"
    assert ctrl.internal_reads == N + 1
    unread, (ctrl, _) = closed_loop(lag, record=["lag.y"])
    unread.run(DURATION)
    assert ctrl.internal_reads == 0
    with pytest.raises(ConnectionCheckError, match=re.escape("source ctrl.error does not exist")):
        Master([lag], [PController("ctrl"), Constant("src")], LOOP[:2] + ["ctrl.error -> lag.u"], H)


def test_an_internal_signal_outside_its_envelope_stops_the_run(lag):
    """error = R - y falls from 0.8 to 0.25: below 0.3 first at the step the recurrence says."""
    first = int(np.argmax(R - expected_loop()[0] < 0.3))
    master, _ = closed_loop(lag, record=["lag.y"], bounds={"ctrl.error": (0.3, 2.0)})
    result = master.run(DURATION, raise_on_error=False)
    assert result.status == "diverged" and len(result.time) == first + 1
    assert result.error.startswith(f"diverged at t = {first * H:.4f} s: ctrl.error = ")
    assert result.error.endswith("is outside its envelope [0.3, 2]")


def test_profiled_runs_name_their_phases(lag):
    master, _ = closed_loop(lag)
    assert master.run(1.0).phase_times == {}
    # the lag's recorded output 'rate' has feedthrough, so it is evaluated at t_n too ("fmu:lag")
    assert set(master.run(1.0, profile=True).phase_times) == {"fmu", "record", "guard", "python:src",
                                                               "python:ctrl", "fmu:lag"}


# ---- divergence guard ------------------------------------------------------------------------

def _open_loop(fmu, **kw):
    return Master([fmu], [Constant("src", value=1.0)], ["src.out -> lag.u"], H, record=["lag.y"], **kw)


def test_envelope_violation_names_time_signal_and_value(lag, tmp_path):
    """y = 2 (1 - exp(-2 t)) first exceeds 1.5 at t = 0.7 s (it crosses at ln(4)/2 = 0.693 s)."""
    path = tmp_path / "results.csv"
    master = _open_loop(lag, bounds={"lag.y": (-1.0, 1.5)})
    with pytest.raises(DivergenceError) as info:
        master.run(DURATION, csv_path=path)
    exc = info.value
    value = 2 * (1 - math.exp(-1.4))
    assert exc.time == pytest.approx(0.7, abs=1e-12) and exc.signal == "lag.y"
    assert exc.value == pytest.approx(value, abs=TOL) and exc.bounds == (-1.0, 1.5)
    assert str(exc).startswith("diverged at t = 0.7000 s: lag.y = 1.50")
    assert str(exc).endswith("is outside its envelope [-1, 1.5]")
    # the partial result, with the violating row, rides on the exception and is on disk
    assert exc.result.status == "diverged" and exc.result.error == str(exc)
    assert exc.result.data.shape == (8, 2) and exc.result["lag.y"][-1] == exc.value
    assert read_results(path)[1].shape == (8, 2)
    info = json.loads(sidecar_path(path).read_text())
    assert info["status"] == "diverged" and info["error"] == str(exc)


def test_divergence_is_returned_without_raise_on_error(lag):
    result = _open_loop(lag, bounds={"lag.y": (-1.0, 1.5)}).run(DURATION, raise_on_error=False)
    assert result.status == "diverged" and "lag.y" in result.error and len(result.time) == 8


@pytest.mark.parametrize("mode, shown", [("nan", "nan"), ("inf", "inf")])
def test_non_finite_python_output_is_caught_before_the_fmu_sees_it(lag, mode, shown):
    master = Master([lag], [Failing("fail", mode=mode, at=0.3)], ["fail.out -> lag.u"], H, record=["lag.y"])
    result = master.run(1.0, raise_on_error=False)
    # diverged (the guard), not failed (the FMU would refuse a non-finite input)
    assert result.status == "diverged"
    assert result.error == f"diverged at t = 0.3000 s: fail.out = {shown} is not a finite number"
    assert len(result.time) == 4


def test_envelope_on_an_unknown_signal_is_refused(lag):
    with pytest.raises(ConnectionCheckError, match="unknown component 'nope'"):
        _open_loop(lag, bounds={"nope.y": (0.0, 1.0)})


# ---- checks before the first step ------------------------------------------------------------

def test_algebraic_loop_among_python_components_is_refused(lag):
    comps = [Gain("a"), Gain("b"), Constant("src")]
    with pytest.raises(ConnectionCheckError, match="algebraic loop: a -> b -> a; each block needs the one before it"):
        Master([lag], comps, ["a.y -> b.u", "b.y -> a.u", "src.out -> lag.u"], H)
    with pytest.raises(ConnectionCheckError, match="algebraic loop: a -> a;"):
        Master([lag], [Gain("a"), Constant("src")], ["a.y -> a.u", "src.out -> lag.u"], H)


def test_loop_closed_through_an_fmu_is_accepted(lag):
    master, _ = closed_loop(lag)  # ctrl -> lag -> ctrl: the FMU breaks the loop
    assert [b.name for b in master.plan.at_tn] == ["src", "ctrl", "lag"]  # lag.rate has feedthrough


@pytest.mark.parametrize("build, error, message", [
    (lambda f: Master([f], [Constant("lag")], [], H), ConnectionCheckError, "component names must be unique"),
    (lambda f: Master([f], [], [], 0.0), ValueError, "step = 0.0 s must be positive"),
    (lambda f: Master([f], [PController("ctrl"), Constant("src")], ["src.out -> ctrl.r"], H),
     ConnectionCheckError, "inputs of ctrl not connected: y"),
    (lambda f: Master([f], [], [], H, fmu_parameters={"other": {"k": 1.0}}), ConnectionCheckError,
     "parameters given for unknown FMU 'other'"),
    (lambda f: Master([f], [Constant("src")], ["src.out -> lag.tau"], H), ConnectionCheckError,
     "destination lag.tau is a parameter, not an input"),
])
def test_bad_setups_are_refused(lag, build, error, message):
    with pytest.raises(error, match=message):
        build(lag)


def test_duration_must_be_a_whole_number_of_steps(lag):
    master, _ = closed_loop(lag)
    for duration in (0.25, 0.0, -1.0):
        with pytest.raises(ValueError, match="not a positive whole number of steps of 0.1 s"):
            master.run(duration)


# ---- runs: parameters, reset, FMI versions ---------------------------------------------------

def test_run_level_parameters_apply_to_that_run_only(lag):
    master, (ctrl, _) = closed_loop(lag)
    base = master.run(DURATION)
    override = {"lag.tau": 0.25, "lag.k": 1.0, "lag.y_0": 0.7, "ctrl.kp": 3.0}
    other = master.run(DURATION, parameters=override)
    assert other.parameters == override
    y, u, _ = expected_loop(y0=0.7, kp=3.0, tau=0.25, k=1.0)
    np.testing.assert_allclose(other["lag.y"], y, rtol=0, atol=TOL)
    np.testing.assert_allclose(other["ctrl.u"], u, rtol=0, atol=TOL)
    # the next run without overrides is back on the base values (fmu_parameters y_0 = 0.2)
    again = master.run(DURATION)
    np.testing.assert_array_equal(again.data, base.data)
    np.testing.assert_allclose(again["lag.y"], expected_loop()[0], rtol=0, atol=TOL)


def test_reset_between_runs_gives_identical_results(lag):
    master, _ = closed_loop(lag)
    first = master.run(DURATION)
    for _ in range(2):
        np.testing.assert_array_equal(master.run(DURATION).data, first.data)


@pytest.mark.parametrize("parameters, error, message", [
    ({"nope.x": 1.0}, ConnectionCheckError, "parameter 'nope.x': expected 'component.name'"),
    ({"lag": 1.0}, ConnectionCheckError, "parameter 'lag': expected 'component.name'"),
    ({"ctrl.ki": 1.0}, KeyError, "component 'ctrl' has no parameter"),
    ({"lag.nope": 1.0}, FmuCallError, "'nope' is no variable of the FMU"),
    ({"lag.y": 1.0}, FmuCallError, "'y' is an output with initial = calculated: the standard lets an importer set only inputs"),
    ({"lag.tau": 0.0}, FmuCallError, "setting parameter tau = 0.0 failed"),
])
def test_refused_run_parameters_raise_and_the_next_run_works(lag, tmp_path, parameters, error, message):
    master, _ = closed_loop(lag)
    path = tmp_path / "results.csv"
    with pytest.raises(error, match=message) as info:
        master.run(DURATION, parameters=parameters, csv_path=path, raise_on_error=False)
    if error is FmuCallError and "tau" in parameters:
        assert info.value.variable == "tau" and "tau = 0 refused: outside its range" in info.value.log
    if error is ConnectionCheckError:  # refused before anything is written
        assert not path.exists()
    else:  # refused at start: the sidecar says so
        status = json.loads(sidecar_path(path).read_text())
        assert status["status"] == "failed" and status["error"].startswith("could not start: ")
    np.testing.assert_allclose(master.run(DURATION)["lag.y"], expected_loop()[0], rtol=0, atol=TOL)


def test_fmi2_and_fmi3_toy_fmus_give_identical_results(lag_fmu2, lag_fmu3):
    results = []
    for path in (lag_fmu2, lag_fmu3):
        fmu = FmuComponent("lag", path)
        with closed_loop(fmu)[0] as master:
            results.append(master.run(DURATION, parameters={"lag.tau": 0.3}))
    assert [FmuComponent("x", p).fmi_version for p in (lag_fmu2, lag_fmu3)] == [2, 3]
    np.testing.assert_array_equal(results[0].data, results[1].data)
    np.testing.assert_allclose(results[1]["lag.y"], expected_loop(tau=0.3)[0], rtol=0, atol=TOL)


def test_internal_step_is_a_parameter_like_any_other(lag):
    """One RK4 step per communication step (internal_step = h): the classical
    RK4 amplification of dy/dt = -y/tau, exactly, instead of exp(-h/tau)."""
    master = Master([lag], [Constant("src", value=0.0)], ["src.out -> lag.u"], H, record=["lag.y"],
                    fmu_parameters={"lag": {"y_0": 1.0, "internal_step": H}})
    result = master.run(1.0)
    z = -H / LAG_TAU
    g = 1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24
    np.testing.assert_allclose(result["lag.y"], g ** np.arange(11), rtol=1e-13, atol=0)
    assert abs(result["lag.y"][-1] - math.exp(-1.0 / LAG_TAU)) > 1e-6  # not the exact answer


def test_an_unconnected_input_with_a_start_value_holds_it(lag):
    """Port.start: an input left unconnected holds its start value (as an
    FMU's input does); connected, it reads its source; without a start value
    it must be connected."""
    from cosim.component import Port

    class Held(Probe):
        inputs = (Port("y", "m"), Port("bias", "m", start=0.25))

    held = Held("probe")
    with Master([lag], [held, Constant("src", value=1.0)], ["src.out -> lag.u", "lag.y -> probe.y"], H) as master:
        master.run(0.1)
    assert len(held.calls) > 1 and all(c[2][1] == 0.25 for c in held.calls)
    fed = Held("probe")
    with Master([lag], [fed, Constant("src", value=1.0)],
                ["src.out -> lag.u", "lag.y -> probe.y", "src.out -> probe.bias"], H) as master:
        master.run(0.1)
    assert len(fed.calls) > 1 and all(c[2][1] == 1.0 for c in fed.calls)
    with pytest.raises(ConnectionCheckError, match="inputs of probe not connected: y"):
        Master([lag], [Held("probe"), Constant("src", value=1.0)], ["src.out -> lag.u"], H)
