"""The compiled loop for systems of FMUs only (cosim.kernel): the same run as
the Python loop, bit for bit, in both orderings and both FMI versions; the
same errors, at the same point, with the same rows kept."""
from __future__ import annotations

import numpy as np
import pytest

from cosim import kernel
from cosim.errors import DivergenceError, FmuCallError
from cosim.fmu_component import FmuComponent
from cosim.master import Master
from cosim.recorder import read_results
from toy_models import lag_fmu_path

H = 0.01
# A -> B -> C -> A, three lags; the recorded B.rate has feedthrough: in the feedthrough ordering B is evaluated at t_n
CONNECTIONS = ["A.y -> B.u", "B.y -> C.u", "C.y -> A.u"]
RECORD = ["A.y", "B.y", "C.y", "B.rate", "C.rate", "B.u"]


def _master(version: int, ordering: str, bounds=None, parameters=None, record=RECORD) -> Master:
    path = lag_fmu_path(version)
    fmus = [FmuComponent(name, path) for name in "ABC"]
    base = {"A": {"y_0": 1.0, "tau": 0.3}, "B": {"k": -0.5}, "C": {"tau": 0.2, "y_0": -0.4}}
    for name, values in (parameters or {}).items():
        base[name].update(values)
    return Master(fmus, [], CONNECTIONS, H, record, bounds, base, ordering=ordering)


def _run(monkeypatch, compiled: bool, *args, csv=None, **kwargs):
    monkeypatch.setenv("COSIM_PYTHON_LOOP", "" if compiled else "1")
    kernel.load.cache_clear()
    progress = []
    with _master(*args, **kwargs) as master:
        try:
            return master.run(2.0, csv_path=csv, block_rows=16, progress=lambda n, total: progress.append(n),
                              raise_on_error=False), progress
        finally:
            kernel.load.cache_clear()


@pytest.fixture(autouse=True)
def compiler():
    kernel.load.cache_clear()  # another test may have cached the Python loop's None
    if kernel.load() is None:
        pytest.skip("no C compiler: the compiled loop is not available, the Python loop runs")


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("ordering", ["feedthrough", "exchange"])
def test_the_compiled_loop_is_the_python_loop_bit_for_bit(monkeypatch, tmp_path, version, ordering):
    (fast, p_fast), (slow, p_slow) = (_run(monkeypatch, compiled, version, ordering, csv=tmp_path / f"{compiled}.csv")
                                      for compiled in (True, False))
    assert fast.status == slow.status == "ok" and fast.data.shape == (201, len(RECORD) + 1)
    np.testing.assert_array_equal(fast.data, slow.data)
    assert p_fast == p_slow  # progress at the same rows
    np.testing.assert_array_equal(read_results(tmp_path / "True.csv")[1], read_results(tmp_path / "False.csv")[1])


@pytest.mark.parametrize("ordering", ["feedthrough", "exchange"])
def test_a_divergence_stops_both_loops_at_the_same_point(monkeypatch, ordering):
    bounds = {"A.y": (-10.0, 0.9)}
    fast, _ = _run(monkeypatch, True, 2, ordering, bounds=bounds)
    slow, _ = _run(monkeypatch, False, 2, ordering, bounds=bounds)
    assert fast.status == slow.status == "diverged" and fast.error == slow.error
    assert "A.y = " in fast.error and "outside its envelope [-10, 0.9]" in fast.error
    np.testing.assert_array_equal(fast.data, slow.data)


def test_an_fmu_failure_is_the_same_error_with_the_same_rows(monkeypatch):
    """B's state overflows to inf in a step: its doStep fails, naming the time
    (its rate, which would show the overflow first, is not watched here)."""
    huge = {"B": {"k": 1e300, "tau": 1e-3}, "A": {"y_0": 1e300}}
    states = ["A.y", "B.y", "C.y"]
    fast, _ = _run(monkeypatch, True, 2, "feedthrough", parameters=huge, record=states)
    slow, _ = _run(monkeypatch, False, 2, "feedthrough", parameters=huge, record=states)
    assert fast.status == slow.status == "failed"
    assert fast.error == slow.error and "B (" in fast.error and "doStep from t = 0.0" in fast.error
    assert "state y became" in fast.error  # the FMU's own log
    np.testing.assert_array_equal(fast.data, slow.data)
    with _master(2, "feedthrough", parameters=huge, record=states) as master, pytest.raises(FmuCallError):
        master.run(2.0)


def test_a_profiled_run_and_a_python_component_take_the_python_loop(monkeypatch):
    """Profiling times phases of the Python loop; a Python component needs it."""
    with _master(2, "feedthrough") as master:
        assert set(master.run(0.1, profile=True).phase_times) >= {"fmu", "record", "guard"}
