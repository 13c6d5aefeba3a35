"""The master's snapshots (cosim.loop.master.Snapshot): every FMU's state and
every signal at chosen communication points, taken without changing the
run, the same in the compiled and the Python loop; a run resumed from one
continues the run it was taken from."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.loop import kernel
from cosim.errors import ConnectionCheckError, FmuCallError
from cosim.fmi.fmu import FmuComponent
from cosim.loop.master import Master
from toy_models import lag_fmu_path, sum_fmu_path

H = 0.01
# three lags in a ring and a running sum fed by A; B.rate and S.y have feedthrough, so
# in the feedthrough ordering B and S are evaluated at t_n, after the snapshot's FMUs stepped there
CONNECTIONS = ["A.y -> B.u", "B.y -> C.u", "C.y -> A.u", "A.y -> S.u"]
RECORD = ["A.y", "B.y", "C.y", "B.rate", "S.y", "B.u"]
TIMES = [0.0, 0.37, 1.0, 2.0]


def _master(version: int = 2, ordering: str = "feedthrough") -> Master:
    fmus = [FmuComponent(name, lag_fmu_path(version)) for name in "ABC"] + [FmuComponent("S", sum_fmu_path(version))]
    base = {"A": {"y_0": 1.0, "tau": 0.3}, "B": {"k": -0.5}, "C": {"tau": 0.2, "y_0": -0.4}, "S": {"dt": H}}
    return Master(fmus, [], CONNECTIONS, H, RECORD, None, base, ordering=ordering)


def _run(monkeypatch, compiled: bool, **kwargs):
    monkeypatch.setenv("COSIM_PYTHON_LOOP", "" if compiled else "1")
    kernel.load.cache_clear()
    try:
        if compiled and kernel.load() is None:  # else both runs would take the Python loop and agree trivially
            pytest.skip("no C compiler: the compiled loop is not available")
        with _master(**kwargs) as master:
            return master.run(2.0, snapshots=TIMES), master.run(2.0)
    finally:
        kernel.load.cache_clear()


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("ordering", ["feedthrough", "exchange"])
def test_snapshots_leave_the_run_as_it_was_and_both_loops_take_the_same(monkeypatch, version, ordering):
    (fast, fast_plain), (slow, slow_plain) = (_run(monkeypatch, compiled, version=version, ordering=ordering)
                                              for compiled in (True, False))
    np.testing.assert_array_equal(fast.data, fast_plain.data)
    np.testing.assert_array_equal(slow.data, slow_plain.data)
    np.testing.assert_array_equal(fast.data, slow.data)
    assert [s.time for s in fast.snapshots] == TIMES and [s.step for s in fast.snapshots] == [0, 37, 100, 200]
    for a, b in zip(fast.snapshots, slow.snapshots):
        assert a.states == b.states and a.outputs == b.outputs and a.inputs == b.inputs
        assert set(a.states) == {"A", "B", "C", "S"}


def test_a_snapshot_holds_every_signal_at_its_time(monkeypatch):
    run, _ = _run(monkeypatch, True)
    for snap in run.snapshots:
        row = run.data[snap.step]
        assert row[0] == snap.time
        for j, name in enumerate(RECORD[:5], start=1):  # the feedthrough outputs B.rate, S.y at t_n too
            assert snap.outputs[name] == row[j], name
        assert snap.inputs_of("B") == {"u": snap.outputs["A.y"]} and snap.inputs["S.u"] == snap.outputs["A.y"]
        assert snap.parameters["A"] == {"y_0": 1.0, "tau": 0.3} and snap.parameters["S"] == {"dt": H}


@pytest.mark.parametrize("compiled", [True, False])
def test_a_run_resumed_from_a_snapshot_continues_the_run(monkeypatch, compiled):
    """Restored FMU states continue the run; the resumed time grid is
    t0 + n h from the snapshot's time, which may differ from the first
    run's n' h in the last bit, so the agreement is to round-off."""
    monkeypatch.setenv("COSIM_PYTHON_LOOP", "" if compiled else "1")
    kernel.load.cache_clear()
    try:
        with _master() as master:
            run = master.run(2.0, snapshots=[0.37])
            snap = run.snapshots[0]
            resumed = master.run(2.0 - 0.37, t0=0.37, restore=snap.states)
            other = master.run(2.0 - 0.37, t0=0.37, restore={k: v for k, v in snap.states.items() if k != "A"},
                               parameters={"A.y_0": snap.outputs["A.y"] + 0.1})
    finally:
        kernel.load.cache_clear()
    tail = run.data[snap.step:]
    assert resumed.data.shape == tail.shape
    np.testing.assert_allclose(resumed.data, tail, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(resumed.data[0], tail[0])
    # A left out of the restore starts from its parameters: here 0.1 above where it was
    assert other.data[0, 1] == pytest.approx(snap.outputs["A.y"] + 0.1, abs=1e-15)
    assert np.max(np.abs(other.data[:, 1:] - tail[:, 1:])) > 1e-3


def test_bad_snapshot_times_and_restores_are_refused_in_one_line():
    with _master() as master:
        with pytest.raises(ValueError, match=r"snapshot at t = 0\.375 s: not a communication point"):
            master.run(1.0, snapshots=[0.375])
        with pytest.raises(ValueError, match=r"snapshot at t = 1\.5 s"):
            master.run(1.0, snapshots=[1.5])
        with pytest.raises(ValueError, match=r"snapshot at t = nan s"):
            master.run(1.0, snapshots=[float("nan")])
        with pytest.raises(ConnectionCheckError, match=r"restore: no FMU named 'D'"):
            master.run(1.0, restore={"D": b""})
        sum_state = master.run(0.1, snapshots=[0.1]).snapshots[0].states["S"]
        with pytest.raises(FmuCallError, match=r"A .*restoring a serialized FMU state failed"):
            master.run(0.1, restore={"A": sum_state})


def test_a_snapshots_state_is_read_and_edited_on_the_live_instance():
    """FmuComponent.state_values reads a variable out of a serialized state;
    state_with sets one (a discrete state, which this project's FMUs accept
    between steps) and serializes again: a run resumed from the edited state
    starts from it. Both work on the master's own instance, which keeps its
    state (no other instance is made)."""
    with _master() as master:
        snap = master.run(1.0, snapshots=[0.5]).snapshots[0]
        live = master.components["S"]
        before = live.serialize_state()
        s = live.state_values(snap.states["S"], ["s"], snap.time)["s"]
        assert s == pytest.approx(snap.outputs["S.y"] - snap.inputs["S.u"], abs=1e-12) and s != 0.0
        edited = live.state_with(snap.states["S"], {"s": 5.0}, snap.time)
        assert live.serialize_state() == before and edited != snap.states["S"]
        resumed = master.run(0.5, t0=0.5, restore=snap.states | {"S": edited})
        assert resumed.data[0, RECORD.index("S.y") + 1] == pytest.approx(5.0 + snap.inputs["S.u"], abs=1e-12)
        with pytest.raises(KeyError, match="has no variable"):
            live.state_with(snap.states["S"], {"nope": 1.0}, snap.time)
