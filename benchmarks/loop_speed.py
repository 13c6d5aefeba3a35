"""Speed of the master's loop against libcosim and a compiled loop, measured in one run.

Prints, for the 50 s circles mission (PD+LM-FNN, 3 m/s gust; 5000 steps of
10 ms), the wall time (median of --repeats runs, after one warm-up run) and
the time per step of:

1. libcosim (libcosimpy) flying the all-FMU SSP archive (``fnn-cosim
   export-ssp circles``: plant, wind, reference and controller FMUs), its
   Jacobi fixed-step algorithm; only ``simulate_until`` is timed (it includes
   libcosim's initialization of the FMUs), not the loading of the archive. A
   time-series observer records Quadrotor.x/y/z, as ``run_libcosim`` does.
   libcosim steps its FMUs on a thread pool; it runs once as it comes, and
   once with the process pinned to one CPU (its threads then never wait for
   each other across cores, which on a small machine can be several times
   faster);
2. our master flying the same archive in the 'exchange' ordering
   (libcosim's algorithm), and in the default 'feedthrough' ordering;
3. the shipped circles mission as ``fnn-cosim run circles`` runs it:
   ``Master.run`` on the shipped TOML scenario, whose trajectory and
   controller are their FMUs, so the master runs it in its compiled loop
   (``cosim/loop/kernel.c``);
4. the same with the controller in its Python form (``controller.form =
   "python"``: the CasADi step called in process), which the master runs in
   its Python loop;
5. the compiled-loop limit: ``benchmarks/compiled_loop.c`` (built here with
   ``gcc -O2``) dlopen()s the four FMUs' binaries from the archive and runs
   the master's feedthrough loop in plain C, with no recording and no guard.

A master's wall time is ``Master.run`` (it includes starting the FMUs:
reset, parameters, initialization; recording the scenario's signals in
memory and the divergence guard); the compiled loop times its 5000 steps
only. Then the ratios, the final position of every engine against the
compiled loop (or, for libcosim, against our exchange ordering), and where
the Python path's time goes per step (``run(..., profile=True)``).

Targets, as ratios measured in this run: ``fnn-cosim run circles``'s loop
(3.) within 1.5x the compiled-loop limit (5.), and our master no slower than
libcosim on the same loop (master, exchange ordering, archive / libcosim <=
1). Printed, never asserted.

    .venv/bin/python benchmarks/loop_speed.py [--repeats 5] [--json out.json]
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
POSITION = ("Quadrotor.x", "Quadrotor.y", "Quadrotor.z")
STATES = ("x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")
# the compiled loop's layout of each FMU's inputs and outputs (the circles mission's connections)
LAYOUT = {
    "Quadrotor": ([f"Omega_{i}" for i in range(1, 5)] + ["wind_x", "wind_y", "wind_z"], list(STATES)),
    "WindGust": ([], ["v_wind_x", "v_wind_y", "v_wind_z"]),
    "reference": ([], ["x", "y", "z", "vx", "vy", "vz"]),
    "controller": (["x_ref", "y_ref", "z_ref", "vx_ref", "vy_ref", "vz_ref"] + list(STATES),
                   [f"Omega_{i}" for i in range(1, 5)]),
}


@contextlib.contextmanager
def _quiet_stdout():
    """Silence file descriptor 1 (libcosim logs a harmless FMI Library error
    per FMU load on stdout, docs/ssp.md)."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


@contextlib.contextmanager
def _pinned(cpus: set[int] | None):
    """Pin the calling thread (and the threads it creates) to ``cpus``."""
    if not cpus:
        yield
        return
    saved = os.sched_getaffinity(0)
    os.sched_setaffinity(0, cpus)
    try:
        yield
    finally:
        os.sched_setaffinity(0, saved)


def _time_master(scenario, repeats: int, profile: bool = False):
    """Median-able wall times of ``Master.run`` (after one warm-up run), the
    last result, the profiled runs' phase times per step (us), the ordering
    and which of the master's loops ran."""
    from cosim.loop import kernel
    from cosim.scenario.assembly import build_master

    times, phases = [], {}
    with build_master(scenario) as master:
        loop = "compiled" if master.plan.compiled and kernel.load() is not None else "Python"
        run = lambda **kw: master.run(scenario.duration, seed=scenario.seed, t0=scenario.start_time, **kw)  # noqa: E731
        run()  # warm-up
        for _ in range(repeats):
            t = time.perf_counter()
            result = run()
            times.append(time.perf_counter() - t)
        if profile:
            for _ in range(repeats):
                r = run(profile=True)
                for k, v in r.phase_times.items():
                    phases.setdefault(k, []).append(v / r.n_steps * 1e6)
                phases.setdefault("total (profiled run)", []).append(r.wall_time / r.n_steps * 1e6)
    final = [float(result[s][-1]) for s in POSITION]
    return times, final, {k: statistics.median(v) for k, v in phases.items()}, master.ordering, loop


def _time_libcosim(folder: Path, n_steps: int, step: float, repeats: int, cpus: set[int] | None = None):
    """libcosim on the extracted archive: wall times of ``simulate_until`` and
    the final position, or the reason it cannot run. With ``cpus``, the
    calling thread is pinned to them while each execution is created and run,
    so libcosim's worker threads (created with the execution) inherit it."""
    try:
        from libcosimpy import CosimLogging
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimObserver import CosimObserver
    except ImportError as exc:
        return None, None, f"libcosimpy is not installed ({exc})"
    CosimLogging.log_output_level(CosimLogging.CosimLogLevel.ERROR)
    times, final = [], None
    for i in range(repeats + 1):  # run 0 is the warm-up
        with _quiet_stdout(), _pinned(cpus):
            execution = CosimExecution.from_ssp_file(str(folder))
        plant = execution.slave_index_from_instance_name("Quadrotor")
        refs = {v.name.decode(): v.reference for v in execution.slave_variables(plant)}
        observer = CosimObserver.create_time_series(16)
        execution.add_observer(observer)
        for var in ("x", "y", "z"):
            observer.start_time_series(plant, refs[var], CosimVariableType.REAL)
        with _pinned(cpus):
            t = time.perf_counter()
            ok = execution.simulate_until(round(n_steps * step * 1e9))
            wall = time.perf_counter() - t
        if not ok:
            return None, None, "libcosim failed to simulate the archive"
        if i:
            times.append(wall)
        final = []
        for var in ("x", "y", "z"):
            _, steps, values = observer.time_series_real_samples(plant, refs[var], from_step=n_steps, sample_count=1)
            if list(steps) != [n_steps]:
                return None, None, f"libcosim stopped at step {list(steps)}, not {n_steps}"
            final.append(values[0])
        del observer, execution
    return times, final, None


def _compiled_command(exe: Path, archive: Path, portable, folder: Path, repeats: int) -> list[str]:
    """The compiled loop's command line: each FMU's binary, GUID, resources,
    input and output value references in LAYOUT's order, and its parameters
    (the all-FMU scenario's, plus the run's seed)."""
    from fmpy import read_model_description

    n_steps = int(round(portable.duration / portable.step))
    cmd = [str(exe), str(n_steps), repr(portable.step), str(repeats)]
    with zipfile.ZipFile(archive) as z:
        for name, (inputs, outputs) in LAYOUT.items():
            fmu_dir = folder / name
            with zipfile.ZipFile(z.open(f"resources/{name}.fmu")) as fmu:
                fmu.extractall(fmu_dir)
            md = read_model_description(str(fmu_dir), validate=False)
            vr = {v.name: v.valueReference for v in md.modelVariables}
            spec = portable.fmus[name]
            params = dict(spec["parameters"])
            if spec.get("seed_parameter"):
                params[spec["seed_parameter"]] = float(portable.seed)
            library = fmu_dir / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
            cmd += [str(library), md.guid, (fmu_dir / "resources").as_uri(),
                    ",".join(str(vr[v]) for v in inputs) or "-",
                    ",".join(str(vr[v]) for v in outputs) or "-",
                    ",".join(f"{vr[k]}={float(v)!r}" for k, v in params.items()) or "-"]
    return cmd


def _time_compiled(portable, archive: Path, tmp: Path, repeats: int):
    gcc = shutil.which("gcc")
    if gcc is None:
        return None, None, "gcc not found"
    exe = tmp / "compiled_loop"
    subprocess.run([gcc, "-O2", "-o", str(exe), str(HERE / "compiled_loop.c"), "-ldl"], check=True)
    out = subprocess.run(_compiled_command(exe, archive, portable, tmp / "fmus", repeats),
                         capture_output=True, text=True)
    if out.returncode:
        return None, None, f"compiled_loop exited with status {out.returncode}: {out.stderr.strip()}"
    if out.stderr.strip():
        print(out.stderr.strip(), file=sys.stderr)
    lines = [line.split() for line in out.stdout.splitlines()]
    times = [float(w[1]) for w in lines if w[0] == "run"]
    final = [float(x) for w in lines if w[0] == "final" for x in w[1:]]
    return times, final, None


def _dist(a, b) -> float:
    return max(abs(x - y) for x, y in zip(a, b))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", help="also write the figures to this JSON file")
    args = p.parse_args(argv)
    wall0 = time.perf_counter()

    import quadrotor_paper  # noqa: F401  (registers the paper's scenarios)
    from cosim.scenario.definition import load_scenario
    from cosim.ssp.archive import load_ssp
    from cosim.ssp.export import export_ssp
    from quadrotor_paper.portable import all_fmu

    portable = all_fmu(load_scenario("circles"))
    n_steps = int(round(portable.duration / portable.step))
    rows: dict[str, dict] = {}
    notes: list[str] = []

    with tempfile.TemporaryDirectory(prefix="loop-speed-") as tmp_name:
        tmp = Path(tmp_name)
        archive = export_ssp(portable, tmp / "circles.ssp")
        exchange = load_ssp(archive, overrides={"simulation.ordering": "exchange"}, extract_to=tmp / "ssp")
        feedthrough = load_ssp(archive, extract_to=tmp / "ssp-feedthrough")

        one_cpu = {min(os.sched_getaffinity(0))} if hasattr(os, "sched_setaffinity") else None
        for key, label, cpus in (("libcosim", "libcosim, archive, simulate_until", None),
                                 ("libcosim_1cpu", "libcosim, same, pinned to one CPU", one_cpu)):
            if key == "libcosim_1cpu" and (one_cpu is None or len(os.sched_getaffinity(0)) < 2):
                continue
            times, final, why = _time_libcosim(tmp / "ssp", n_steps, portable.step, args.repeats, cpus)
            if why:
                notes.append(f"{label} skipped: {why}")
                break
            rows[key] = {"label": label, "times": times, "final": final}
        for key, label, scenario, profile in (
                ("exchange", "our master, archive, 'exchange' ordering", exchange, False),
                ("feedthrough", "our master, archive, 'feedthrough' ordering", feedthrough, False),
                ("shipped", "fnn-cosim run circles (Master.run, shipped TOML)", load_scenario("circles"), False),
                ("python", "same, controller.form = \"python\"", load_scenario("circles", {"controller.form": "python"}),
                 True)):
            times, final, phases, ordering, loop = _time_master(scenario, args.repeats, profile)
            rows[key] = {"label": f"{label}, {loop} loop", "times": times, "final": final, "phases": phases,
                         "ordering": ordering, "loop": loop}
        times, final, why = _time_compiled(portable, archive, tmp, args.repeats)
        if why:
            notes.append(f"compiled loop skipped: {why}")
        else:
            rows["compiled"] = {"label": "compiled C loop, 4 FMUs (feedthrough)", "times": times, "final": final}

    for row in rows.values():
        row["median_s"] = statistics.median(row["times"])
        row["best_s"] = min(row["times"])
        row["per_step_us"] = row["median_s"] / n_steps * 1e6

    print(f"50 s circles mission (PD+LM-FNN, 3 m/s gust), {n_steps} steps of {portable.step} s; "
          f"median of {args.repeats} runs after a warm-up; {os.cpu_count()} cores")
    for note in notes:
        print(f"  {note}")
    print(f"  {'':68s} {'median':>9s} {'best':>9s} {'per step':>10s}")
    for row in rows.values():
        print(f"  {row['label']:68s} {row['median_s'] * 1e3:6.1f} ms {row['best_s'] * 1e3:6.1f} ms "
              f"{row['per_step_us']:7.2f} us")

    ratios = {}

    def ratio(name: str, num: str, den: str, target: str) -> None:
        if num in rows and den in rows:
            ratios[name] = rows[num]["median_s"] / rows[den]["median_s"]
            print(f"  {name:58s} {ratios[name]:6.2f}   (target {target})")

    print("ratios of medians:")
    ratio("fnn-cosim run circles (Master.run) / compiled C loop", "shipped", "compiled", "<= 1.5")
    ratio("master (exchange, archive) / libcosim", "exchange", "libcosim", "<= 1")
    ratio("master (exchange, archive) / libcosim pinned to one CPU", "exchange", "libcosim_1cpu", "<= 1")
    ratio("master (feedthrough, archive) / compiled", "feedthrough", "compiled", "none, for reference")
    ratio("master (controller.form = \"python\") / compiled", "python", "compiled", "none, for reference")
    ratio("libcosim / compiled", "libcosim", "compiled", "none, for reference")
    ratio("libcosim pinned to one CPU / compiled", "libcosim_1cpu", "compiled", "none, for reference")

    print("final position, max |dx|,|dy|,|dz| (m):")
    pairs = [("libcosim", "exchange", "libcosim vs our master, same archive, exchange ordering"),
             ("libcosim_1cpu", "exchange", "libcosim pinned to one CPU vs the same"),
             ("compiled", "feedthrough", "compiled loop vs our master, archive, feedthrough"),
             ("compiled", "shipped", "compiled loop vs fnn-cosim run circles"),
             ("compiled", "python", "compiled loop vs our master, controller.form = \"python\""),
             ("compiled", "exchange", "compiled loop (feedthrough) vs master exchange (1-step delay)")]
    differences = {}
    for a, b, text in pairs:
        if a in rows and b in rows:
            differences[f"{a}-{b}"] = _dist(rows[a]["final"], rows[b]["final"])
            print(f"  {text:62s} {differences[f'{a}-{b}']:.3g}")
    if "compiled" in rows:
        x, y, z = rows["compiled"]["final"]
        print(f"  (compiled loop's final position: x = {x:.12g}, y = {y:.12g}, z = {z:.12g})")

    names = {"fmu": "FMU exchange (set, doStep, get)", "python:controller": "controller (adapter + CasADi)",
             "record": "recording", "guard": "divergence guard"}
    for key in ("python",):
        if key not in rows:
            continue
        row = rows[key]
        phases = dict(row["phases"])
        total = phases.pop("total (profiled run)")
        print(f"where the time goes per step, {row['label']} (median of {args.repeats} profiled runs; "
              f"the timers add their own cost):")
        for k, v in phases.items():
            print(f"    {names.get(k, k):44s} {v:6.2f} us")
        print(f"    {'loop and run() outside the phases':44s} {total - sum(phases.values()):6.2f} us")
        print(f"    {'total, profiled run':44s} {total:6.2f} us   (unprofiled: {row['per_step_us']:.2f} us)")
        if "compiled" in rows:
            print(f"    compiled loop, the 4 FMUs' work in C: {rows['compiled']['per_step_us']:.2f} us; "
                  f"Python-side overhead ~ {row['per_step_us'] - rows['compiled']['per_step_us']:.2f} us a step")
    print(f"benchmark wall time: {time.perf_counter() - wall0:.1f} s")

    if args.json:
        figures = {"steps": n_steps, "cores": os.cpu_count(), "repeats": args.repeats, "notes": notes,
                   "rows": rows, "ratios": ratios, "final_position_differences_m": differences}
        Path(args.json).write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
