"""Cost of one controller step, against a reference measured in the same run.

For each registered variant it times, on the same inputs:

* the fast path: ``QuadrotorController.step``, one
  ``casadi.Function.buffer()`` evaluation of the controller's one step
  function (the parametric step the co-simulation component and the
  controller FMU run, its parameter vector filled once) on preallocated
  arrays;
* the reference: one plain call of the very same CasADi function with numpy
  arguments (``f(p_ref, p_ref_dot, x, psi_ref, state, p, p_ref_ddot)``), what
  a user gets without the fast path;

and prints both per step (best of --repeats batches of --steps calls) and
their ratio. Target: the fast path at least 10x cheaper than the plain call.
Nothing here fails on a slow machine; it prints.

    .venv/bin/python benchmarks/controller_speed.py [--steps 5000] [--repeats 5]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def _best_per_call(call, steps: int, repeats: int) -> float:
    for _ in range(min(200, steps)):  # warm-up
        call()
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(steps):
            call()
        best = min(best, (time.perf_counter() - t) / steps)
    return best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=5000)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args(argv)

    from fnn_controller import QuadrotorController
    from fnn_controller.variants import variant_names

    p_ref, p_ref_dot, p_ref_ddot = np.array([1.0, 0.0, -15.0]), np.array([0.5, 0.0, 0.0]), np.zeros(3)
    x = np.zeros(12)
    x[2] = -15.0
    print(f"controller step, best of {args.repeats} x {args.steps} calls:")
    print(f"  {'variant':10s} {'fast path':>12s} {'plain call':>12s} {'ratio':>8s}")
    for variant in variant_names():
        ctrl = QuadrotorController(variant)
        ctrl.reset(0)
        fast = _best_per_call(lambda: ctrl.step(p_ref, p_ref_dot, x), args.steps, args.repeats)
        f, state, p = ctrl.function, ctrl.state, ctrl.inputs["p"].copy()
        plain = _best_per_call(lambda: f(p_ref, p_ref_dot, x, 0.0, state, p, p_ref_ddot), max(args.steps // 10, 1),
                               args.repeats)
        print(f"  {variant:10s} {fast * 1e6:9.2f} us {plain * 1e6:9.2f} us {plain / fast:7.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
