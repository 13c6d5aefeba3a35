"""``fnn-cosim calibrate``'s speed against a plain loop of scipy's
``least_squares`` over fmpy's ``simulate_fmu`` (what fmpy's parameter
example does), on the same log and the same parameters.

The log: the plant flown by the project (quadrotor_paper.synthetic_log) with
hidden parameters, ``--duration`` s at 100 Hz (default 50 s: 5000 rows), its
12 states, commanded and measured rotor speeds. Seven names fitted (issue
42's "seven-name fit on a 50 s log": every hidden parameter and the wind)
from the same first guesses (b, Ix, Iy, k_drag_lin, tau_m 20-30 % off; the
constant wind from 0): ``b, Ix, Iy, k_drag_lin, tau_m, wind_x, wind_y``.

1. ours, the CasADi way: :func:`cosim.calibration.calibrate` (2 s shooting
   segments from the logged states) on the plant's own CasADi definition
   (``jacobian = "casadi"``, :mod:`cosim.calibration.symbolic`: the segments
   and their exact forward sensitivities compiled, 2 threads), the wall time
   of the whole fit (target: 10x faster than 3.); the
   C it compiles once per machine is timed apart (0 when cached);
2. ours, the generic way for any FMU (``jacobian = "derivatives"``: forward
   sensitivities from the FMU's directional derivatives, 2 worker
   processes);
3. the plain loop: ``least_squares`` (its own 2-point differences) over
   ``simulate_fmu`` of the same FMU on the whole log from its first state,
   the logged rotor commands as its input signal, the wind as two constant
   input columns; ``--baseline-evaluations`` simulations at most.

1. and 2. fit the exact log with ``initial_states = "recorded"`` (its
logged states start the segments, as the plain loop starts from its first
state). Issue 42's other two figures, each beside its target:

4. a log of ``--estimated-duration`` s (default 60) with Gaussian noise
   (0.01 on every state; the rotor commands and speeds exact) fitted with
   the default ``initial_states = "estimated"`` the CasADi way: wall time
   against the target of the log's duration (60 s in under 60 s), and the
   solver's iterations (:mod:`cosim.calibration.marquardt`);
5. the VanDerPol fit without plots as a whole process (``fnn-cosim
   calibrate VanDerPol_out.csv --fmu VanDerPol.fmu --fit mu --no-plots``)
   against the baseline's whole process (``least_squares`` over
   ``simulate_fmu`` in ``python -c``), the median of ``--repeat`` runs each.

Printed: each wall time, the number of simulations, each estimate's relative
error against the hidden value, and the ratio of the times. Never asserted.

    .venv/bin/python benchmarks/calibration_speed.py [--duration 50] [--estimated-duration 60]
        [--baseline-evaluations 400] [--skip-baseline]
"""
from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

FIT = ("b", "Ix", "Iy", "k_drag_lin", "tau_m", "wind_x", "wind_y")
GUESS = {"b": 5.0e-6, "Ix": 0.025, "Iy": 0.035, "k_drag_lin": 0.18, "tau_m": 0.022, "wind_x": 0.0, "wind_y": 0.0}


def truth() -> dict[str, float]:
    from quadrotor_paper.synthetic_log import HIDDEN

    wind = -3.0 / 2 ** 0.5
    return {**HIDDEN, "wind_x": wind, "wind_y": wind}


def cpu() -> float:
    """CPU seconds of this process, its finished children, and the worker
    processes its children started and reaped: the workers (cosim.executor)
    start from a forkserver, whose children they are, not ours; psutil reads
    the server's count of them."""
    import psutil

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    alive = [child.cpu_times() for child in psutil.Process().children()]
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime + sum(
        t.user + t.system + t.children_user + t.children_system for t in alive)


def ours(log: Path, fmu: Path, fixed: dict, workers: int, jacobian: str, initial_states: str = "recorded"):
    """Wall and CPU seconds, the estimates, the simulations, the compiler's seconds, converged."""
    from cosim.calibration import CalibrationSettings, calibrate

    t, c = time.perf_counter(), cpu()
    cal = calibrate(log, fmu, CalibrationSettings(fit=list(FIT), guess=GUESS, fix=fixed, segment=2.0, holdout=0.0,
                                                  workers=workers, jacobian=jacobian, initial_states=initial_states))
    wall = time.perf_counter() - t
    return (wall, cpu() - c, dict(zip(cal.problem.fit, map(float, cal.fit.theta))), cal.fit.evaluations,
            cal.fit.compile_seconds, cal.converged)


VDP_BASELINE = """
import sys
import numpy as np
from fmpy import simulate_fmu
from scipy.optimize import least_squares
log = np.genfromtxt(sys.argv[1], delimiter=",", names=True)
def residuals(mu):
    r = simulate_fmu(sys.argv[2], stop_time=float(log["time"][-1]), output_interval=0.01, start_values={"mu": mu[0]},
                     output=["x0", "x1"])
    return np.concatenate([r["x0"] - log["x0"], r["x1"] - log["x1"]])
print(least_squares(residuals, [1.5]).x[0])
"""


def whole_process(argv: list[str], repeat: int) -> float:
    """The median wall time of ``repeat`` runs of ``argv`` as a process (exit 0 asked)."""
    import statistics
    import subprocess

    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def van_der_pol(repeat: int) -> None:
    import sys

    shared = Path(__file__).resolve().parents[2] / "shared" / "reference-fmus"
    log, fmu = shared / "results" / "VanDerPol_out.csv", shared / "fmi2" / "VanDerPol.fmu"
    if not fmu.exists():
        print(f"VanDerPol: the Reference FMUs are not at {shared}: skipped")
        return
    cli = Path(sys.executable).with_name("fnn-cosim")
    with tempfile.TemporaryDirectory() as tmp:
        for interface in ("CoSimulation", "auto"):
            ours_s = whole_process([str(cli), "calibrate", str(log), "--fmu", str(fmu), "--fit", "mu", "--guess",
                                    "mu=1.5", "--interface", interface, "--no-plots", "--quiet", "--out", tmp], repeat)
            print(f"VanDerPol, fnn-cosim calibrate --no-plots --interface {interface}, whole process: {ours_s:.2f} s "
                  f"(median of {repeat})")
        base = whole_process([sys.executable, "-c", VDP_BASELINE, str(log), str(fmu)], repeat)
    print(f"VanDerPol, least_squares over simulate_fmu, whole process: {base:.2f} s; target: ours <= it "
          f"(ratio {ours_s / base:.2f})")


def baseline(log: Path, fmu: Path, fixed: dict, max_evaluations: int) -> tuple[float, float, dict, int, str]:
    from fmpy import simulate_fmu
    from scipy.optimize import least_squares

    data = np.genfromtxt(log, delimiter=",", names=True)
    states = ["x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r"]
    col = lambda n: data[n.replace(".", "")]  # noqa: E731
    measured = np.column_stack([col(f"Quadrotor.{s}") for s in states])
    scale = np.maximum(measured.std(axis=0), 1e-3)
    t = data["time"]
    start = {f"{s}_0": float(col(f"Quadrotor.{s}")[0]) for s in states}
    start |= {f"Omega_r_{i}_0": float(col(f"Quadrotor.Omega_r_{i}")[0]) for i in range(1, 5)}
    evaluations = [0]
    x0 = np.array([GUESS[n] for n in FIT])

    def residuals(theta):
        evaluations[0] += 1
        values = dict(zip(FIT, theta))
        signal = np.zeros(t.size, dtype=[("time", float)] + [(f"Omega_{i}", float) for i in range(1, 5)] +
                          [("wind_x", float), ("wind_y", float), ("wind_z", float)])
        signal["time"] = t
        for i in range(1, 5):
            signal[f"Omega_{i}"] = col(f"Quadrotor.Omega_{i}")
        signal["wind_x"], signal["wind_y"] = values.pop("wind_x"), values.pop("wind_y")
        try:
            r = simulate_fmu(str(fmu), stop_time=float(t[-1]), output_interval=float(t[1] - t[0]), input=signal,
                             start_values={**fixed, **start, **values}, output=states)
            sim = np.column_stack([r[s] for s in states])[:t.size]
        except Exception:  # a step the FMU refuses: the plain loop has no way on
            return np.full(measured.size, 1e6)
        if sim.shape != measured.shape or not np.isfinite(sim).all():
            return np.full(measured.size, 1e6)
        return ((sim - measured) / scale).ravel()

    lower = np.array([1e-12, 1e-9, 1e-9, 0.0, 0.0, -np.inf, -np.inf])
    w, c = time.perf_counter(), cpu()
    res = least_squares(residuals, x0, bounds=(lower, np.inf), x_scale=np.where(x0 != 0, np.abs(x0), 1.0),
                        max_nfev=max_evaluations)
    wall = time.perf_counter() - w
    return wall, cpu() - c, dict(zip(FIT, map(float, res.x))), evaluations[0], res.message


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=50.0, help="the exact log of 1.-3., s (default 50)")
    ap.add_argument("--estimated-duration", type=float, default=60.0, help="the noisy log of 4., s (default 60)")
    ap.add_argument("--baseline-evaluations", type=int, default=400)
    ap.add_argument("--workers", type=int, default=2, help="our fit's processes (default 2)")
    ap.add_argument("--skip-baseline", action="store_true", help="without 2. and 3. (the slow ones)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each VanDerPol process (default 3)")
    args = ap.parse_args()
    from fmu_models.built import built_fmu
    from fmu_models.catalog import model
    from quadrotor_paper.synthetic_log import HIDDEN, fly_synthetic_log

    fmu = built_fmu("Quadrotor", 2, lambda: model("Quadrotor"))
    fixed = {k: v for k, v in HIDDEN.items() if k not in FIT}
    true = truth()
    with tempfile.TemporaryDirectory() as tmp:
        log = fly_synthetic_log(Path(tmp), duration=args.duration)
        rows = sum(1 for _ in open(log)) - 1
        print(f"log: {args.duration:g} s at 100 Hz ({rows} rows), {len(FIT)} names fitted: {', '.join(FIT)}")
        print(f"load average before: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (wall times grow with it; "
              f"CPU times much less)")
        ways = {}
        for jacobian, label in (("casadi", "the CasADi way (threads)"), ("derivatives", "the generic FMU way "
                                                                                      "(processes)")):
            if jacobian == "derivatives" and args.skip_baseline:
                continue
            wall, cpu_s, est, n_ours, compiled, _ = ours(log, fmu, fixed, args.workers, jacobian)
            ways[jacobian] = (wall, cpu_s, est)
            print(f"fnn-cosim calibrate, {label}, {args.workers} workers: {wall:.2f} s wall, {cpu_s:.2f} s CPU, "
                  f"{n_ours} simulations of the log" + (f" (of which {compiled:.1f} s compiling its C, once per "
                                                         f"machine)" if compiled else ""))
            for n in FIT:
                print(f"    {n:11s} = {est[n]:+.15g}  relative error {abs(est[n] / true[n] - 1):.1e}")
        if not args.skip_baseline:
            worst = max(abs(ways["casadi"][2][n] / ways["derivatives"][2][n] - 1) for n in FIT)
            print(f"the two ways' estimates differ by at most {worst:.1e} relative")
            t_base, c_base, est_b, n_base, message = baseline(log, fmu, fixed, args.baseline_evaluations)
            print(f"least_squares over fmpy simulate_fmu: {t_base:.1f} s wall, {c_base:.1f} s CPU, {n_base} "
                  f"simulations ({message})")
            for n in FIT:
                print(f"    {n:11s} = {est_b[n]:+.10g}  relative error {abs(est_b[n] / true[n] - 1):.1e}")
            for jacobian, (wall, cpu_s, _) in ways.items():
                print(f"ratio, {jacobian}: the plain loop took {t_base / wall:.1f}x its wall time, "
                      f"{c_base / cpu_s:.1f}x its CPU time (target >= 10x)")
        if args.estimated_duration != args.duration:
            (Path(tmp) / "noisy").mkdir()
            log = fly_synthetic_log(Path(tmp) / "noisy", duration=args.estimated_duration)
        noisy_log = noisy(log, 0.01, np.random.default_rng(0))
        print(f"load average before: {os.getloadavg()[0]:.1f}")
        wall, cpu_s, est, n_ours, _, converged = ours(noisy_log, fmu, fixed, args.workers, "casadi", "estimated")
        print(f"a {args.estimated_duration:g} s log with noise 0.01, initial_states = 'estimated' (the default), "
              f"the CasADi way: {wall:.1f} s wall, {cpu_s:.1f} s CPU, {n_ours} simulations, "
              f"{'converged' if converged else 'NOT converged'}; target: under {args.estimated_duration:g} s "
              f"({'met' if wall < args.estimated_duration else 'NOT met'} at load {os.getloadavg()[0]:.1f})")
        for n in FIT:
            print(f"    {n:11s} = {est[n]:+.10g}  relative error {abs(est[n] / true[n] - 1):.1e}")
    van_der_pol(args.repeat)


def noisy(log: Path, sigma: float, rng) -> Path:
    """The log with Gaussian noise ``sigma`` on every state (the rotor commands and speeds exact), beside it."""
    head = log.read_text().splitlines()[0]
    data = np.loadtxt(log, delimiter=",", skiprows=1)
    for j, n in enumerate(head.split(",")):
        if n != "time" and not n.startswith("Quadrotor.Omega_"):
            data[:, j] += sigma * rng.standard_normal(data.shape[0])
    out = log.with_name("noisy.csv")
    np.savetxt(out, data, delimiter=",", header=head, comments="", fmt="%.17g")
    sidecar = log.with_name(log.name + ".json")
    if sidecar.exists():
        out.with_name(out.name + ".json").write_text(sidecar.read_text())
    return out


if __name__ == "__main__":
    main()
