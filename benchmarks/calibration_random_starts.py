"""``fnn-cosim calibrate`` from random bounds and first guesses: no exit
other than 0 (converged), 1 (did not converge) or 2 (bad input, one line),
and never an internal error (issue 42, item 5).

Two problems, each run many times in this process through the command's
``main`` (its exit status and stderr captured):

* VanDerPol (the Reference FMU, FMI 2.0) on its published output: ``mu``
  guessed uniformly in [-10, 10], sometimes with random bounds;
* the plant (our Quadrotor FMU) on a short synthetic flight log
  (:mod:`quadrotor_paper.synthetic_log`) with noise: ``b, d, Ix, Iy, Iz,
  k_drag_lin, tau_m`` guessed log-uniformly from 1/30 to 30 times the truth
  (and some of them 0 or negative), sometimes unbounded below by a random
  bound, segments of random length.

Printed: the histogram of exit statuses, the longest run's CPU seconds, the
count of internal errors, and each run that ended otherwise than 0, 1 or 2 or with an internal error, with
its command line and stderr. Never asserted.

    .venv/bin/python benchmarks/calibration_random_starts.py [--runs 40] [--seed 0] [--duration 4]
"""
from __future__ import annotations

import argparse
import collections
import contextlib
import io
import tempfile
import time
from pathlib import Path

import numpy as np

PLANT = ("b", "d", "Ix", "Iy", "Iz", "k_drag_lin", "tau_m")


def command(argv: list[str]) -> tuple[int, str]:
    """The command's exit status and stderr, in this process."""
    from quadrotor_paper.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 2
        except BaseException as exc:  # noqa: BLE001  what this benchmark looks for
            code = f"raised {type(exc).__name__}: {exc}"
    return code, err.getvalue()


def vanderpol_args(rng, out: Path) -> list[str]:
    shared = Path(__file__).resolve().parents[2] / "shared" / "reference-fmus"
    args = ["calibrate", str(shared / "results" / "VanDerPol_out.csv"), "--fmu", str(shared / "fmi2" / "VanDerPol.fmu"),
            "--fit", "mu", "--guess", f"mu={rng.uniform(-10, 10):.6g}", "--no-plots", "--quiet", "--out", str(out),
            "--segment", str(rng.choice([2.0, 5.0, 20.0]))]
    if rng.random() < 0.3:
        args += ["--settings", str(_bounds(out, {"mu": sorted(map(float, rng.uniform(-10, 10, 2)))}))]
    return args


def plant_args(rng, log: Path, out: Path, truth: dict) -> list[str]:
    fit = [n for n in PLANT if rng.random() < 0.6] or ["b"]
    args = ["calibrate", str(log), "--fmu", "Quadrotor", "--fit", ",".join(fit), "--no-plots", "--quiet",
            "--out", str(out), "--segment", str(rng.choice([0.5, 1.0, 2.0]))]
    bounds = {}
    for n in fit:
        v = truth[n] * 10 ** rng.uniform(-1.5, 1.5)
        if rng.random() < 0.05:  # outside the FMU's range: refused (exit 2)
            v = 0.0 if rng.random() < 0.5 else -v
        args += ["--guess", f"{n}={v:.6g}"]
        if rng.random() < 0.2:
            bounds[n] = [0.0, truth[n] * 10 ** rng.uniform(0, 2)]
    if rng.random() < 0.3:
        args[args.index("--out"):args.index("--out")] = ["--interface", "ModelExchange"]
    if bounds:
        args += ["--settings", str(_bounds(out, bounds))]
    return args


def _bounds(out: Path, bounds: dict) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    path = out / "bounds.toml"
    path.write_text("[bounds]\n" + "".join(f"{k} = [{lo!r}, {hi!r}]\n" for k, (lo, hi) in bounds.items()))
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=40, help="runs of each problem (default 40)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=4.0, help="the plant's log, s (default 4)")
    ap.add_argument("--verbose", action="store_true", help="print every run's status and stderr")
    args = ap.parse_args()
    from calibration_speed import noisy  # this folder's
    from quadrotor_paper.synthetic_log import HIDDEN, fly_synthetic_log

    rng = np.random.default_rng(args.seed)
    truth = {"d": 2.66e-2 * 6.55e-6, "Iz": 2.1e-2, **HIDDEN}  # the log's: Table 1's, HIDDEN's changed
    histogram: dict[str, collections.Counter] = {"VanDerPol": collections.Counter(), "Quadrotor": collections.Counter()}
    bad = []
    longest = dict.fromkeys(histogram, 0.0)  # CPU-s of the longest run of each problem
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        log = noisy(fly_synthetic_log(tmp / "flight", duration=args.duration), 0.01, rng)
        t0 = time.perf_counter()
        for k in range(args.runs):
            for name in histogram:
                out = tmp / f"{name}{k}"
                argv = vanderpol_args(rng, out) if name == "VanDerPol" else plant_args(rng, log, out, truth)
                cpu = time.process_time()
                code, err = command(argv)
                cpu = time.process_time() - cpu
                internal = "internal error" in err
                histogram[name]["internal error" if internal else str(code)] += 1
                longest[name] = max(longest[name], cpu)
                if args.verbose:
                    print(f"{name}: exit {code}, {cpu:.1f} CPU-s: {' '.join(argv[3:])}\n    {err.strip()[-300:]}",
                          flush=True)
                if internal or code not in (0, 1, 2):
                    settings = out / "bounds.toml"
                    bad.append((name, code, " ".join(argv) + (f"  ({settings.name}: {settings.read_text()!r})" if
                                                              settings.exists() else ""), err.strip()))
        wall = time.perf_counter() - t0
    print(f"{args.runs} random starts of each problem, seed {args.seed}, {wall:.0f} s")
    for name, counts in histogram.items():
        print(f"{name:10s} exit statuses: " + ", ".join(f"{k}: {v}" for k, v in sorted(counts.items()))
              + f"; longest run {longest[name]:.1f} CPU-s")
    print(f"runs that ended otherwise than 0, 1 or 2, or in an internal error: {len(bad)}")
    for name, code, argv, err in bad:
        print(f"  {name}: exit {code}: fnn-cosim {argv}\n    {err}")


if __name__ == "__main__":
    main()
