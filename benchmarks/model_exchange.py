"""Model Exchange against Co-Simulation, measured: the loop and the whole process.

Two cases, each flown with the same FMUs in Co-Simulation and in Model
Exchange (``cosim.fmi.me_system``: one CVODE over the stacked states of the
connected Model Exchange FMUs, its calls in C):

1. the DC motor as three FMUs (``tests/industrial_fmus.py``: a voltage
   source with a step, the motor's electrical part, its mechanical part),
   0.5 s at a 1 ms step: Co-Simulation (each FMU's own RK4 inside), Model
   Exchange tightly coupled (the default), Model Exchange loosely coupled
   (each FMU alone, its inputs held over a step), all in the compiled loop,
   and fmpy's ``simulate_fmu`` of one FMU (the mechanical part in Model
   Exchange, its input held: fmpy cannot couple Model Exchange FMUs); the
   speed's largest difference from the monolithic solution (scipy's
   ``solve_ivp`` over the stacked states, rtol 1e-10) is printed beside each;
2. our plant on the 50 s circles mission (PD+LM-FNN, 3 m/s gust, 5000 steps
   of 10 ms): Co-Simulation (RK4 in the FMU) and Model Exchange at each
   --tolerances value, with the position RMSE against the Co-Simulation run.

For each: the loop (``Master.run``'s wall time, median of --repeats after a
warm-up) and the whole process (``fnn-cosim run`` of the scenario in a fresh
interpreter, median of --repeats), and their ratios to Co-Simulation. Printed,
never asserted.

    .venv/bin/python benchmarks/model_exchange.py [--repeats 3] [--tolerances 1e-8] [--fmi-version 2]
"""
from __future__ import annotations

import argparse
import json
import statistics
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim.scenario.assembly import build_master
from cosim.scenario.definition import load_scenario

ROOT = Path(__file__).resolve().parents[1]
POSITION = ("Quadrotor.x", "Quadrotor.y", "Quadrotor.z")


def loop(scenario, repeats: int, signals) -> tuple[float, np.ndarray]:
    """The median wall time of ``Master.run`` and the recorded ``signals`` of the last run."""
    with build_master(scenario) as master:
        master.run(scenario.duration, seed=scenario.seed)  # warm-up
        times, result = [], None
        for _ in range(repeats):
            result = master.run(scenario.duration, seed=scenario.seed)
            times.append(result.wall_time)
    return statistics.median(times), np.column_stack([result[s] for s in signals])


def process(scenario_arguments: list[str], repeats: int) -> tuple[float, float]:
    """The median wall and CPU time of ``fnn-cosim run`` in a fresh interpreter
    (imports, build, run, results written): the wall time is what a user
    waits, the CPU time is less moved by other work on the machine."""
    walls, cpus = [], []
    with tempfile.TemporaryDirectory() as folder:
        for k in range(repeats):
            command = [sys.executable, "-m", "quadrotor_paper.cli", "run", *scenario_arguments, "--no-plots",
                       "--quiet", "--out", str(Path(folder) / str(k))]
            before, start = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
            subprocess.run(command, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            walls.append(time.perf_counter() - start)
            cpus.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return statistics.median(walls), statistics.median(cpus)


def row(name: str, loop_s: float, process_s: tuple[float, float], base, error: str) -> None:
    (wall, cpu), (base_loop, (base_wall, base_cpu)) = process_s, base
    print(f"{name:<44} {loop_s:9.3f} {loop_s / base_loop:6.1f} {wall:9.3f} {wall / base_wall:6.2f} {cpu:8.3f} "
          f"{cpu / base_cpu:6.2f} {error:>14}")


HEADER = (f"{'':<44} {'loop (s)':>9} {'x CS':>6} {'wall (s)':>9} {'x CS':>6} {'CPU (s)':>8} {'x CS':>6} "
          f"{'error':>14}\n{'':<44} {'(Master.run)':>16} {'(fnn-cosim run, whole process)':>32}")


def dc_motor(repeats: int, folder: Path) -> None:
    """Case 1: the DC motor's three FMUs (tests/industrial_fmus.py)."""
    sys.path.insert(0, str(ROOT))
    from fmpy import simulate_fmu

    from tests.industrial_fmus import DC_MOTOR_CONNECTIONS, build, dc_motor_exact, dc_motor_specs

    duration, step = 0.5, 1e-3
    fmus = {n: build(folder, s) for n, s in dc_motor_specs(interfaces=("ModelExchange", "CoSimulation")).items()}
    times = np.linspace(0.0, duration, int(round(duration / step)) + 1)
    speed = dc_motor_exact(times)[:, 2]
    connections = [f'"{a}.{x} -> {b}.{y}"' for (a, x), (b, y) in DC_MOTOR_CONNECTIONS]
    print(f"DC motor as three FMUs (source, electrical, mechanical), {duration} s at a {step * 1e3:g} ms step, "
          f"median of {repeats}; error: the speed's largest difference from the monolithic solution")
    print(HEADER)
    base = None
    for name, interface, coupling in (("Co-Simulation (Euler at 0.1 ms in each FMU)", "CoSimulation", "tight"),
                                      ("Model Exchange, tight (one CVODE, rtol 1e-8)", "ModelExchange", "tight"),
                                      ("Model Exchange, loose (each FMU alone)", "ModelExchange", "loose")):
        lines = [f"connections = [{', '.join(connections)}]", "[simulation]", f"duration = {duration}",
                 f"step = {step}", f'coupling = "{coupling}"']
        for fmu, path in fmus.items():
            lines += [f"[fmus.{fmu}]", f"path = {json.dumps(str(path))}", f'interface = "{interface}"']
            if interface == "ModelExchange":
                lines.append("solver = { relative_tolerance = 1e-8 }")
        lines += ["[record]", 'signals = ["DCMotor_Mechanical.w"]']
        path = folder / f"dc_{interface}_{coupling}.toml"
        path.write_text("\n".join(lines) + "\n")
        scenario = load_scenario(str(path))
        loop_s, rows = loop(scenario, repeats, ["DCMotor_Mechanical.w"])
        process_s = process([str(path)], repeats)
        base = base or (loop_s, process_s)
        row(name, loop_s, process_s, base, f"{np.max(np.abs(rows[:, 0] - speed)):.2e} rad/s")
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        simulate_fmu(str(fmus["DCMotor_Mechanical"]), fmi_type="ModelExchange", stop_time=duration,
                     output_interval=step, relative_tolerance=1e-8)
        times.append(time.perf_counter() - start)
    print(f"{'fmpy simulate_fmu, the mechanical part alone':<44} {statistics.median(times):9.3f} "
          f"{statistics.median(times) / base[0]:6.1f}")


def plant(repeats: int, tolerances: list[float], version: int) -> None:
    overrides = {"fmus.Quadrotor.fmi_version": version}
    cs = load_scenario("circles", overrides)
    arguments = ["circles", "--set", f"fmus.Quadrotor.fmi_version={version}"]
    cs_loop, cs_xyz = loop(cs, repeats, POSITION)
    base = (cs_loop, process(arguments, repeats))
    print(f"\nour plant on circles, 50 s, {cs.n_steps} steps, Quadrotor FMI {version}.0, median of {repeats}")
    print(HEADER)
    row("Co-Simulation (RK4 in the FMU)", base[0], base[1], base, "0")
    for tolerance in tolerances:
        me = {"fmus.Quadrotor.interface": "ModelExchange", "fmus.Quadrotor.solver.relative_tolerance": tolerance}
        me_loop, me_xyz = loop(load_scenario("circles", {**overrides, **me}), repeats, POSITION)
        me_process = process(arguments + [a for k, v in me.items() for a in ("--set", f"{k}={v}")], repeats)
        rmse = float(np.sqrt(np.mean(np.sum((me_xyz - cs_xyz) ** 2, axis=1))))
        row(f"Model Exchange, CVODE rtol {tolerance:g}", me_loop, me_process, base, f"{rmse:.2e} m")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--tolerances", default="1e-8", help="CVODE relative tolerances for the plant, comma-separated")
    parser.add_argument("--fmi-version", type=int, default=2, choices=(2, 3))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        dc_motor(args.repeats, Path(folder))
    plant(args.repeats, [float(t) for t in args.tolerances.split(",")], args.fmi_version)


if __name__ == "__main__":
    main()
