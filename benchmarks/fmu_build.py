"""Where a first build of every shipped FMU spends its CPU: what
``make test``'s session build (tests/conftest.py) and a user's first
``fnn-cosim build-fmu`` do, from an empty cache.

Builds every registered model in FMI 2.0 and 3.0 with
:func:`cosim.scenario.registry.build_fmu_models` into a fresh, empty FMU cache
(``FNN_COSIM_CACHE`` and ``XDG_CACHE_HOME`` pointed at a temporary folder)
and prints: the wall time, the CPU time of this process and of its
children (the compilers), the number of compiler calls and their CPU by
what they compiled (each model's generated C, the generic core and FMI
layers, the links), the Python phases (staging: CasADi's code generation,
the sources and modelDescription written; zipping), and the largest
compiler calls. Then each scenario of ``--export`` exported as an SSP
archive (``fnn-cosim export-ssp``: an FMU of each model with the
scenario's values as its start values, what the tests of the archives do
many times): its compiler calls and CPU. The machine may be shared: the CPU seconds are the
figures to compare, the wall time says how well the cores were used.

    .venv/bin/python benchmarks/fmu_build.py [--versions 2 3] [--top 10] [--export circles circles_estimated]
"""
from __future__ import annotations

import argparse
import atexit
import collections
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path


def _cpu() -> tuple[float, float]:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


class _Calls:
    """Every compiler call of the build: its command and its own CPU (``wait4``)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.calls: list[tuple[list[str], float]] = []
        self.spans: list[tuple[float, float]] = []  # each call's start and end (perf_counter)
        self.phases: dict[str, float] = collections.defaultdict(float)
        self.roots: dict[str, str] = {}  # a staged tree -> "<model> FMI <version>"

    def run(self, cmd, **kwargs):
        start = time.perf_counter()
        with tempfile.TemporaryFile() as out:
            process = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT)
            _, status, usage = os.wait4(process.pid, 0)
            out.seek(0)
            text = out.read().decode(errors="replace")
        with self.lock:
            self.calls.append((list(cmd), usage.ru_utime + usage.ru_stime))
            self.spans.append((start, time.perf_counter()))
        code = os.waitstatus_to_exitcode(status)
        return subprocess.CompletedProcess(cmd, code, text, text)

    def stage(self, stage):
        def wrapper(model, fmi_version, root):
            self.roots[str(root)] = f"{model.identifier} FMI {fmi_version}"
            return stage(model, fmi_version, root)
        return wrapper

    def model(self, cmd: list[str]) -> str:
        for part in cmd:
            for root, name in self.roots.items():
                if part.startswith(("-I" + root, root)):
                    return name
        return "?"

    def timed(self, phase: str, function):
        def wrapper(*args, **kwargs):
            t = time.thread_time()
            try:
                return function(*args, **kwargs)
            finally:
                with self.lock:
                    self.phases[phase] += time.thread_time() - t
        return wrapper


def _running(spans: list[tuple[float, float]], start: float, end: float) -> dict[int, float]:
    """Seconds of [start, end] with n compilers running, by n."""
    events = sorted([(a, 1) for a, _ in spans] + [(b, -1) for _, b in spans] + [(end, 0)])
    out: dict[int, float] = collections.defaultdict(float)
    n, t = 0, start
    for when, change in events:
        out[n] += when - t
        n, t = n + change, when
    return dict(out)


def _what(cmd: list[str]) -> str:
    """The kind of a compiler call: a link, or the C file it compiles."""
    if "-c" not in cmd:
        return "link"
    return Path(cmd[cmd.index("-c") + 1]).name


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--versions", type=int, nargs="+", default=[2, 3])
    parser.add_argument("--top", type=int, default=10, help="how many of the largest compiler calls to list")
    parser.add_argument("--export", nargs="*", default=["circles", "circles_estimated"],
                        help="shipped scenarios exported as SSP archives after the build")
    args = parser.parse_args()
    empty = tempfile.mkdtemp(prefix="fmu-build-")
    atexit.register(shutil.rmtree, empty, ignore_errors=True)  # the FMUs built: a few hundred MB
    os.environ["FNN_COSIM_CACHE"] = str(Path(empty, "fmu-cache"))
    os.environ["XDG_CACHE_HOME"] = str(Path(empty, "xdg"))

    wall0, (own0, kids0) = time.perf_counter(), _cpu()
    import quadrotor_paper  # noqa: F401  (registers the shipped models)
    from cosim.scenario import registry
    from fmu_models.export import build, codegen

    calls = _Calls()
    build.subprocess = type("Shim", (), {"run": staticmethod(calls.run), "PIPE": subprocess.PIPE,
                                         "STDOUT": subprocess.STDOUT,
                                         "CompletedProcess": subprocess.CompletedProcess})
    build._stage = calls.timed("staging (CasADi C, sources, modelDescription)", calls.stage(build._stage))
    build._zip = calls.timed("zipping", build._zip)
    codegen._generated = calls.timed("  of which CasADi code generation", codegen._generated)
    imported = time.perf_counter() - wall0

    t = time.perf_counter()
    built = registry.build_fmu_models(args.versions)
    wall = time.perf_counter() - t
    own, kids = _cpu()

    print(f"{len(built)} FMUs ({len({n for n, _, _ in built})} models, FMI {' and '.join(map(str, args.versions))}) "
          f"from an empty cache, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}")
    print(f"  wall {wall:6.1f} s  (imports before it {imported:.1f} s)")
    print(f"  CPU  {own - own0 + kids - kids0:6.1f} s: this process {own - own0:.1f} s (Python, imports included), "
          f"compilers {kids - kids0:.1f} s")
    for phase, seconds in calls.phases.items():
        print(f"    {phase:<48} {seconds:6.1f} s")
    by_kind = collections.defaultdict(lambda: [0, 0.0])
    for cmd, seconds in calls.calls:
        by_kind[_what(cmd)][0] += 1
        by_kind[_what(cmd)][1] += seconds
    print(f"  compiler calls {len(calls.calls)}, {sum(s for _, s in calls.calls):.1f} CPU-s:")
    for kind, (n, seconds) in sorted(by_kind.items(), key=lambda kv: -kv[1][1]):
        print(f"    {kind:<24} {n:4d} calls {seconds:6.1f} s")
    running = _running(calls.spans, t, t + wall)
    print("  compilers running: " + ", ".join(f"{n} for {running[n]:.1f} s" for n in sorted(running)))
    last = max(calls.spans, key=lambda s: s[1])
    print(f"  the last compiler call ended {t + wall - last[1]:.1f} s before the build's end")
    print(f"  the {args.top} largest:")
    for cmd, seconds in sorted(calls.calls, key=lambda c: -c[1])[:args.top]:
        span = calls.spans[calls.calls.index((cmd, seconds))]
        print(f"    {seconds:6.2f} s  {_what(cmd):<20} {calls.model(cmd):<32} {span[0] - t:6.1f} -> {span[1] - t:6.1f} s")
    for name in args.export:
        from cosim.scenario.definition import load_scenario
        from cosim.ssp.export import export_ssp
        from quadrotor_paper.portable import all_fmu

        calls.calls.clear()
        own0, kids0 = _cpu()
        t = time.perf_counter()
        export_ssp(all_fmu(load_scenario(name)), Path(empty, f"{name}.ssp"))  # as fnn-cosim export-ssp
        own, kids = _cpu()
        by_kind = collections.Counter(_what(cmd) for cmd, _ in calls.calls)
        print(f"export-ssp {name} after it: wall {time.perf_counter() - t:.1f} s, CPU {own - own0 + kids - kids0:.1f} s "
              f"(compilers {kids - kids0:.1f} s), compiler calls: "
              + (", ".join(f"{kind} {n}" for kind, n in sorted(by_kind.items())) or "none"))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
