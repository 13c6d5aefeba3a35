"""The compiled loop for systems of FMUs only (cosim.loop.kernel): the same run as
the Python loop, bit for bit, in both orderings and both FMI versions, FMU
local variables recorded and bounded alike; the same errors, at the same
point, with the same rows kept; its C header lays the structures out as
ctypes does."""
from __future__ import annotations

import numpy as np
import pytest

import ctypes
import os
import shutil
import subprocess
from pathlib import Path

from cosim.loop import kernel
from cosim.errors import DivergenceError, FmuCallError
from cosim.fmi.fmu import FmuComponent
from cosim.loop.master import Master
from cosim.fmi.model_exchange import SolverSettings
from cosim.loop.recorder import read_results
from toy_models import lag_fmu_path, sum_fmu_path

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


class _Chunks:
    """An observer of a run's rows (as a study's metrics): what it was handed, chunk by chunk."""

    def __init__(self):
        self.chunks = []

    def add(self, rows) -> None:
        self.chunks.append((rows.first, rows.data.copy()))


def _observed(monkeypatch, compiled: bool, duration: float, calls: list, bounds=None):
    """A run of ``duration`` s with no CSV and no progress, as a study flies
    it: its result, the chunks its observer got, and (compiled) the kernel
    calls in ``calls``."""
    monkeypatch.setenv("COSIM_PYTHON_LOOP", "" if compiled else "1")
    kernel.load.cache_clear()
    run = kernel.load()
    if run is not None:
        def counted(*args):
            calls.append(1)
            return run(*args)
        monkeypatch.setattr(kernel, "load", lambda: counted)
    seen = _Chunks()
    try:
        with _master(2, "feedthrough", bounds=bounds) as master:
            result = master.run(duration, block_rows=16, keep=0, observers=[seen], raise_on_error=False)
    finally:
        monkeypatch.undo()
        kernel.load.cache_clear()
    return result, seen.chunks


def test_a_run_with_no_csv_and_no_progress_returns_to_python_once_a_chunk(monkeypatch):
    """Nothing waits for a block (no CSV, no progress bar): the compiled loop
    flies a whole chunk of the recorder per call, and the observers get the
    same rows, in the same chunks, as from the Python loop (a study's
    metrics, to the bit)."""
    from cosim.loop.recorder import CHUNK_ROWS

    calls = []
    fast, fast_chunks = _observed(monkeypatch, True, 50.0, calls)
    slow, slow_chunks = _observed(monkeypatch, False, 50.0, [])
    assert fast.status == slow.status == "ok" and fast.rows == slow.rows == 5001
    assert len(calls) == -(-5001 // CHUNK_ROWS) == 2  # per block of 16 rows it was 313 calls
    assert [first for first, _ in fast_chunks] == [first for first, _ in slow_chunks] == [0, 4096]
    for (_, a), (_, b) in zip(fast_chunks, slow_chunks):
        np.testing.assert_array_equal(a, b)


def test_a_master_flown_again_is_a_new_master_bit_for_bit(monkeypatch):
    """A master keeps its compiled loop's structure from run to run
    (Master._kernel_run): a later run of another length and start, and a
    run after its FMUs were freed and instantiated again, equal the run of
    a master built for it."""
    monkeypatch.setenv("COSIM_PYTHON_LOOP", "")
    kernel.load.cache_clear()

    def fresh(duration, t0):
        with _master(2, "feedthrough") as master:
            return master.run(duration, t0=t0)["B.y"]

    with _master(2, "feedthrough") as master:
        master.run(2.0)
        np.testing.assert_array_equal(master.run(0.5, t0=1.0)["B.y"], fresh(0.5, 1.0))
        kept = master._kernel_kept[1]
        for fmu in master.fmus:  # a new instance: the kept structure points into the freed one
            fmu.close()
        np.testing.assert_array_equal(master.run(1.0)["B.y"], fresh(1.0, 0.0))
        assert master._kernel_kept[1] is not kept


def test_a_divergence_mid_chunk_stops_at_the_same_row_in_both_loops(monkeypatch):
    bounds = {"A.y": (-10.0, 0.9)}
    fast, fast_chunks = _observed(monkeypatch, True, 50.0, [], bounds=bounds)
    slow, slow_chunks = _observed(monkeypatch, False, 50.0, [], bounds=bounds)
    assert fast.status == slow.status == "diverged" and fast.error == slow.error and fast.rows == slow.rows
    assert len(fast_chunks) == len(slow_chunks) == 1
    np.testing.assert_array_equal(fast_chunks[0][1], slow_chunks[0][1])


def test_a_profiled_run_and_a_python_component_take_the_python_loop(monkeypatch):
    """Profiling times phases of the Python loop; a Python component needs it;
    the run says why it took that loop (the plan decides, Plan.python_loop_for)."""
    from cosim.loop.plan import NO_COMPILED_LOOP, PROFILED

    with _master(2, "feedthrough") as master:
        profiled = master.run(0.1, profile=True)
        assert set(profiled.phase_times) >= {"fmu", "record", "guard"} and profiled.python_loop == (PROFILED,)
        if kernel.load() is not None:
            assert master.run(0.1).python_loop == ()
        monkeypatch.setenv("COSIM_PYTHON_LOOP", "1")
        kernel.load.cache_clear()
        try:
            assert master.run(0.1).python_loop == (NO_COMPILED_LOOP,)
        finally:
            kernel.load.cache_clear()


def _lag_into_sum(version: int, ordering: str, bounds=None) -> Master:
    """A lag feeding the running sum S, whose sum S.s is an FMU local variable."""
    fmus = [FmuComponent("A", lag_fmu_path(version)), FmuComponent("S", sum_fmu_path(version))]
    return Master(fmus, [], ["A.y -> S.u"], H, ["A.y", "S.s", "S.y"], bounds, {"A": {"y_0": 1.0, "tau": 0.3}},
                  ordering=ordering)


def _both_loops(monkeypatch, make) -> tuple:
    results = []
    for compiled in (True, False):
        monkeypatch.setenv("COSIM_PYTHON_LOOP", "" if compiled else "1")
        kernel.load.cache_clear()
        with make() as master:
            results.append(master.run(2.0, block_rows=16, raise_on_error=False))
    kernel.load.cache_clear()
    return tuple(results)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("ordering", ["feedthrough", "exchange"])
def test_an_fmu_local_variable_records_like_an_output_in_both_loops(monkeypatch, version, ordering):
    """S.s at t_n is the sum of the lag's outputs before t_n, in both
    orderings; S.y is s + u read at t_n (feedthrough: S is evaluated at t_n)
    or held from the step before (exchange; at t0 the initial transfer's)."""
    fast, slow = _both_loops(monkeypatch, lambda: _lag_into_sum(version, ordering))
    assert fast.status == slow.status == "ok"
    np.testing.assert_array_equal(fast.data, slow.data)
    y, s = fast["A.y"], fast["S.s"]
    np.testing.assert_array_equal(s, np.concatenate([[0.0], np.cumsum(y)[:-1]]))
    if ordering == "feedthrough":
        np.testing.assert_array_equal(fast["S.y"], s + y)
    else:
        np.testing.assert_array_equal(fast["S.y"], np.concatenate([[y[0]], s[1:]]))
    assert fast.units[fast.columns.index("S.s")] == "m"


@pytest.mark.parametrize("ordering", ["feedthrough", "exchange"])
def test_an_fmu_local_outside_its_envelope_stops_both_loops_at_the_same_point(monkeypatch, ordering):
    fast, slow = _both_loops(monkeypatch, lambda: _lag_into_sum(2, ordering, bounds={"S.s": (-1.0, 5.0)}))
    first = int(np.argmax(np.concatenate([[0.0], np.cumsum(fast["A.y"])[:-1]]) > 5.0))
    assert fast.status == slow.status == "diverged" and fast.error == slow.error
    assert fast.error.startswith(f"diverged at t = {first * H:.4f} s: S.s = ")
    np.testing.assert_array_equal(fast.data, slow.data)


@pytest.mark.parametrize("library", ["kernel", "me_system"])
def test_the_c_header_lays_the_structures_out_as_ctypes_does(tmp_path, library):
    """The header kernel.c (and me_system.c) is compiled with, generated from
    the ctypes structures: every field at the same offset, every structure of
    the same size."""
    from cosim.fmi import me_system

    module, structures = {"kernel": (kernel, (kernel.KernelFmu, kernel.KernelRun, kernel.KernelStop)),
                          "me_system": (me_system, (me_system.MeMember, me_system.MeConnection,
                                                    me_system.MeSundials, me_system.MeSystem))}[library]
    (tmp_path / "abi.h").write_text(module.header())
    prints = [f'printf("{s.__name__} %zu\\n", sizeof({s.__name__}));' for s in structures]
    prints += [f'printf("{s.__name__}.{name} %zu\\n", offsetof({s.__name__}, {name}));'
               for s in structures for name, _ in s._fields_]
    (tmp_path / "layout.c").write_text("#include <stddef.h>\n#include <stdio.h>\n#include \"abi.h\"\n"
                                       "int main(void) {\n" + "\n".join(prints) + "\nreturn 0;\n}\n")
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    subprocess.run([cc, "-std=c99", f"-I{tmp_path}", "-o", str(tmp_path / "layout"), str(tmp_path / "layout.c")],
                   check=True)
    printed = dict(line.split() for line in subprocess.run([str(tmp_path / "layout")], capture_output=True,
                                                          text=True, check=True).stdout.splitlines())
    expected = {s.__name__: ctypes.sizeof(s) for s in structures}
    expected.update({f"{s.__name__}.{name}": getattr(s, name).offset for s in structures for name, _ in s._fields_})
    assert {k: int(v) for k, v in printed.items()} == expected
    assert "enum { CALL_SET = 0, CALL_GET = 1, CALL_STEP = 2 };" in kernel.header()


REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"


@pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {REFERENCE}")
def test_fmus_the_kernel_cannot_call_are_driven_through_their_python_calls(monkeypatch):
    """Stair as Model Exchange with an Int32 output (it ends the simulation
    at 9 s) and Feedthrough taking an Int32: the compiled loop calls them
    through their Python calls; VanDerPol as Model Exchange (its system's
    calls, cosim/fmi/me_system.c) and Dahlquist in C; the run is the Python
    loop's, bit for bit, ended at the same row."""
    def build() -> Master:
        fmus = [FmuComponent("V", REFERENCE / "fmi3" / "VanDerPol.fmu", interface="ModelExchange",
                             solver=SolverSettings(relative_tolerance=1e-8)),
                FmuComponent("S", REFERENCE / "fmi2" / "Stair.fmu", interface="ModelExchange"),
                FmuComponent("F", REFERENCE / "fmi3" / "Feedthrough.fmu"),
                FmuComponent("D", REFERENCE / "fmi2" / "Dahlquist.fmu")]
        return Master(fmus, [], ["V.x0 -> F.Float64_continuous_input", "S.counter -> F.Int32_input"], 0.05,
                      ["V.x0", "S.counter", "F.Float64_continuous_output", "F.Int32_output", "D.x"])

    runs = []
    for compiled in (True, False):
        monkeypatch.setenv("COSIM_PYTHON_LOOP", "" if compiled else "1")
        kernel.load.cache_clear()
        with build() as master:
            assert master.plan.compiled and set(master.plan.python_calls) == {"S", "F"}
            runs.append(master.run(10.0))
    kernel.load.cache_clear()
    fast, slow = runs
    np.testing.assert_array_equal(fast.data, slow.data)
    assert fast.terminated == slow.terminated and "S (" in fast.terminated
    assert fast.time[-1] == pytest.approx(8.95) and fast["S.counter"][-1] == 9
    np.testing.assert_array_equal(fast["F.Int32_output"], fast["S.counter"])  # through F, at the same instant
    assert np.ptp(fast["V.x0"]) > 3  # the oscillator ran


def test_threads_take_turns_at_python_and_hand_them_over_while_the_compiled_loop_runs(monkeypatch):
    """``kernel.python_turn``: a thread flying a study's run holds its turn
    at Python (the lock) except inside the compiled loop's calls
    (``off_turn``), where another thread's turn may run; the run's numbers
    are those flown without turns; without a turn, ``off_turn`` is nothing."""
    import threading

    turn, seen = threading.Lock(), []
    loop = kernel.load()

    def spied(*args):
        seen.append(turn.locked())
        return loop(*args)

    with _master(2, "feedthrough") as master:
        alone = master.run(2.0, raise_on_error=False)
        monkeypatch.setattr(kernel, "load", lambda: spied)
        with kernel.python_turn(turn):
            assert turn.locked()
            taken = master.run(2.0, raise_on_error=False)
            assert turn.locked()
    assert seen and not any(seen)  # free in every call into the loop
    assert not turn.locked()
    np.testing.assert_array_equal(taken.data, alone.data)
    with kernel.off_turn():  # no turn taken: nothing to hand over
        assert not turn.locked()
