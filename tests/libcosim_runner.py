"""An SSP archive flown by libcosim (the Open Simulation Platform's C++
master, through ``libcosimpy``): the independent importer the tests and the
benchmarks compare our master with (``docs/ssp.md``). Not part of the
product: it lives where its users are.
"""
from __future__ import annotations

import tempfile
import time as _time
from pathlib import Path
from typing import Sequence

from cosim.errors import CosimError, ScenarioError
from cosim.ssp.archive import load_ssp

__all__ = ["run_libcosim"]


def run_libcosim(path: str | Path, signals: Sequence[str], *, step: float | None = None,
                 duration: float | None = None):
    """Run an SSP archive (or its extracted folder) in libcosim and record
    ``signals`` (``Component.variable``) at every communication point, t0
    (after libcosim's initialization) included; return a
    :class:`~cosim.loop.master.RunResult` like the master's (``data[:, 0]`` is time).

    Needs ``libcosimpy``. The step is the archive's (its OSP annotation)
    unless ``step`` is given; the duration the default experiment's unless
    ``duration`` is given. libcosim runs FMI 1.0 and 2.0 co-simulation FMUs
    only (an FMI 3.0 FMU crashes the process), so an archive holding an FMI
    3.0 FMU is refused before libcosim sees it; so is a parameter value that
    names no parameter or input of its FMU (libcosim would log a warning and
    run without it). Sets libcosim's log level (process-wide) to errors only.
    """
    from ctypes import POINTER, c_double, c_int, c_int64, c_size_t, c_uint32

    import numpy as np
    try:
        from libcosimpy import CosimLogging
        from libcosimpy._internal import get_last_error_message, libcosimc, wrap_function
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimObserver import CosimObserver
    except ImportError as exc:
        raise ImportError(f"running an SSP archive in libcosim needs libcosimpy ({exc})") from None
    from fmpy import read_model_description

    from cosim.loop.master import RunResult

    overrides = {k: v for k, v in (("simulation.step", step), ("simulation.duration", duration)) if v is not None}
    with tempfile.TemporaryDirectory(prefix="ssp-libcosim-") as tmp:
        scenario = load_ssp(path, step=step, duration=duration, overrides=overrides, extract_to=tmp)
        units: dict[str, str | None] = {}
        for name, spec in scenario.fmus.items():
            md = read_model_description(str(spec["path"]), validate=False)
            units.update({f"{name}.{v.name}": v.unit or None for v in md.modelVariables})
            if not md.fmiVersion.startswith(("1.", "2.")):
                raise ScenarioError(f"{path}: ssd:Component {name!r} is an FMI {md.fmiVersion} FMU; libcosim runs "
                                    f"FMI 1.0 and 2.0 co-simulation FMUs only")
            variables = {v.name: v for v in md.modelVariables}
            for key in spec["parameters"]:
                if key not in variables or variables[key].causality not in ("parameter", "input"):
                    raise ScenarioError(f"{path}: ssd:Component {name!r}: ssv:Parameter {key!r} is no parameter "
                                        f"or input of its FMU")
        h, n = scenario.step, scenario.n_steps
        CosimLogging.log_output_level(CosimLogging.CosimLogLevel.ERROR)
        try:  # libcosimpy asserts; libcosim says why in its last error message
            execution = CosimExecution.from_ssp_file(str(scenario.source.parent),
                                                     step_size=round(h * 1e9) if step is not None else None)
        except AssertionError:
            raise CosimError(f"{path}: libcosim cannot load the archive: {get_last_error_message()}") from None
        slaves = {info.name.decode(): info.index for info in execution.slave_infos()}  # not the SSD's order
        targets = []
        for signal in signals:
            comp, _, var = signal.partition(".")
            if comp not in slaves:
                raise ScenarioError(f"signal {signal!r}: no component {comp!r}; components are: {', '.join(slaves)}")
            refs = {v.name.decode(): v.reference for v in execution.slave_variables(slaves[comp])}
            if var not in refs:
                raise ScenarioError(f"signal {signal!r}: {comp} has no variable {var!r}")
            targets.append((slaves[comp], refs[var]))
        observer = CosimObserver.create_time_series(n + 1)
        execution.add_observer(observer)
        for slave, ref in targets:
            observer.start_time_series(slave, ref, CosimVariableType.REAL)
        wall0 = _time.perf_counter()
        if not execution.step(n):
            raise CosimError(f"{path}: libcosim failed: {get_last_error_message()}")
        wall = _time.perf_counter() - wall0
        # libcosimpy 0.0.6 drops the last sample when step 0 is among those read (it
        # counts zero step numbers as missing ones): read them through libcosimc itself.
        read = wrap_function(lib=libcosimc(), funcname="cosim_observer_slave_get_real_samples", restype=c_int64,
                             argtypes=[POINTER(CosimObserver), c_int, c_uint32, c_int64, c_size_t,
                                       POINTER(c_double), POINTER(c_int64), POINTER(c_int64)])
        columns = ("time",) + tuple(signals)
        data = np.empty((n + 1, len(columns)))
        data[:, 0] = scenario.start_time + np.arange(n + 1) * h  # from the step counter, as the master's
        values, numbers, times = np.empty(n + 1), np.empty(n + 1, np.int64), np.empty(n + 1, np.int64)
        for j, (slave, ref) in enumerate(targets, 1):
            got = read(observer.ptr(), slave, ref, 0, n + 1, values.ctypes.data_as(POINTER(c_double)),
                       numbers.ctypes.data_as(POINTER(c_int64)), times.ctypes.data_as(POINTER(c_int64)))
            if got != n + 1 or not np.array_equal(numbers, np.arange(n + 1)):
                raise CosimError(f"libcosim returned {got} samples of {columns[j]} for steps 0..{n}")
            data[:, j] = values
        del observer, execution
    return RunResult(columns, ("s",) + tuple(units.get(s) for s in signals), data, "ok", None, wall, n, h,
                     seed=scenario.seed)
