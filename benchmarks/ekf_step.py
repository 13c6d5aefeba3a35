"""Cost of one step of each EKF FMU (Estimator, EstimatorMag, EstimatorMocap,
EstimatorGM), and the compiler's CPU for its generated C.

For each model: its FMU (FMI 2.0) as built from this tree (``cached_fmu``,
the shared cache), instantiated as a run does (``cosim.fmi.fmu``) and
stepped ``--steps`` times on a straight line with noisy IMU samples and a
fresh fix every tenth step; the time of ``do_step`` (``fmi2DoStep``) alone per
step, best of ``--repeats`` runs (the Python call is about a microsecond of it).
Then the model's ``model_generated.c``
compiled alone with the build's flags, its compiler CPU (``wait4``).
``--against TREE`` runs the same in another checkout (``PYTHONPATH=TREE``)
and prints both side by side, measured in the same minutes: the machine may
be shared, so compare the ratios.

    .venv/bin/python benchmarks/ekf_step.py [--steps 3000] [--repeats 5] [--against ../other-checkout]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

MODELS = ("Estimator", "EstimatorMag", "EstimatorMocap", "EstimatorGM")


def _compile_seconds(model) -> float:
    """Compiler CPU of the model's generated C alone, with the build's flags."""
    from fmu_models.export.build import CFLAGS, _compiler
    from fmu_models.export.codegen import generate_sources

    with tempfile.TemporaryDirectory() as folder:
        generate_sources(model, Path(folder))
        flags = [f for f in CFLAGS if f != "-shared"]
        process = subprocess.Popen([_compiler(), *flags, "-c", str(Path(folder, "model_generated.c")),
                                    "-o", str(Path(folder, "model_generated.o"))])
        _, status, usage = os.wait4(process.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError(f"compiling {model.identifier}'s generated C failed")
    return usage.ru_utime + usage.ru_stime


def _step_seconds(model, steps: int, repeats: int) -> float:
    """Best time of one step (``FmuComponent.do_step``: fmi2DoStep) over ``repeats`` runs of ``steps`` steps."""
    import numpy as np

    from cosim.fmi.fmu import FmuComponent
    from fmu_models.export.build import cached_fmu

    names = [v.name for v in model.inputs]
    dt = model.variable("dt").start
    rng = np.random.default_rng(1)
    t = np.arange(steps) * dt
    inputs = np.tile(np.array(model.input_values(), float), (steps, 1))
    column = {n: k for k, n in enumerate(names)}
    inputs[:, column["x_m"]] = 1.0 * t + rng.normal(0, 0.02, steps)
    inputs[:, column["u_m"]] = 1.0 + rng.normal(0, 0.05, steps)
    for axis in "xyz":
        inputs[:, column[f"gyro_{axis}"]] = rng.normal(0, 0.01, steps)
        inputs[:, column[f"acc_{axis}"]] += rng.normal(0, 0.05, steps)
    inputs[:, column["fresh"]] = np.arange(steps) % 10 == 0
    inputs[:, column["t_imu"]] = inputs[:, column["t_fix"]] = t
    best = float("inf")
    with FmuComponent("ekf", cached_fmu(model, 2)) as fmu:
        fmu.instantiate()
        for _ in range(repeats):
            fmu.start(0.0)
            spent = 0.0
            for n in range(steps):
                fmu.set_inputs(dict(zip(names, inputs[n])), n * dt)
                start = time.perf_counter()
                fmu.do_step(n * dt, dt)
                spent += time.perf_counter() - start
            best = min(best, spent / steps)
    return best


def measure(steps: int, repeats: int) -> dict[str, tuple[float, float]]:
    """Per model: (seconds per step, compiler CPU-s of its generated C)."""
    import fmu_models.models.estimator as estimator

    models = {m.identifier: m for m in (estimator.ESTIMATOR, estimator.ESTIMATOR_MAG, estimator.ESTIMATOR_MOCAP,
                                        estimator.ESTIMATOR_GM)}
    return {name: (_step_seconds(models[name], steps, repeats), _compile_seconds(models[name])) for name in MODELS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--against", type=Path, help="another checkout, measured the same way in the same run")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # one tree's figures, for --against
    args = parser.parse_args()
    if args.json:
        print(json.dumps(measure(args.steps, args.repeats)))
        return
    trees = {"this tree": None} if args.against is None else {"this tree": None, str(args.against): args.against}
    figures = {}
    for label, tree in trees.items():
        env = dict(os.environ, PYTHONPATH=str(tree.resolve() if tree else Path(__file__).resolve().parents[1]))
        out = subprocess.run([sys.executable, __file__, "--json", "--steps", str(args.steps), "--repeats",
                              str(args.repeats)], env=env, check=True, capture_output=True, text=True).stdout
        figures[label] = json.loads(out.strip().splitlines()[-1])
    print(f"EKF step (fmi2DoStep, best of {args.repeats} x {args.steps} steps) and compiler CPU of its generated C; "
          f"load {os.getloadavg()[0]:.2f}")
    for name in MODELS:
        line = f"  {name:16s}"
        for label, values in figures.items():
            step, cc = values[name]
            line += f"  {label}: {step * 1e6:6.1f} us, {cc:5.1f} CPU-s"
        if len(figures) == 2:
            (a, ca), (b, cb) = (values[name] for values in figures.values())
            line += f"  (ratio step {a / b:.2f}, compile {ca / cb:.2f})"
        print(line)
    for label, values in figures.items():
        print(f"  {label}: the four compile in {sum(cc for _, cc in values.values()):.1f} CPU-s")


if __name__ == "__main__":
    main()
