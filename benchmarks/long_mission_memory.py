"""A long mission in constant memory (issue 28), measured in one run.

Flies ``fnn-cosim run circles`` twice, each in its own process, as a user
runs it (results CSV of every row, plots, summary): the shipped 50 s
mission, the reference, and a long one (``--duration``, default 10^6 s:
10^8 steps at 10 ms; its CSV about 45 GB, said before it starts). Prints
each one's wall time and peak resident memory (the process's own, from
``wait4``) and their ratio (target: the long one within 1.2x of the 50 s
one), then recomputes the long run's metrics from its results CSV
(:func:`quadrotor_paper.run_metrics.from_results`) and prints whether they
equal its summary's, to the bit. For a shorter ``--duration`` it also prints
what 10^6 s would take at the same cost per step. Printed, never asserted.

    .venv/bin/python benchmarks/long_mission_memory.py [--duration 1e6] [--keep DIR]
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

from processes import cli, measured

REFERENCE_S = 50.0
TARGET = 1.2


def _fly(duration: float, out: Path) -> dict:
    wall, cpu, peak = measured(cli("run", "circles", "--set", f"simulation.duration={duration!r}", "--out", str(out),
                                   "--quiet"))
    summary = json.loads((out / "summary.json").read_text())
    return {"duration_s": duration, "rows": summary["rows"], "wall_s": wall, "cpu_s": cpu, "peak_rss_bytes": peak,
            "csv_bytes": (out / "results.csv").stat().st_size, "summary": summary}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=1e6, help="the long mission (s; default 1e6: 10^8 steps)")
    p.add_argument("--keep", type=Path, help="keep the runs' folders here (default: a temporary folder, removed)")
    p.add_argument("--json", type=Path, help="also write the figures here")
    args = p.parse_args(argv)
    root = Path(tempfile.mkdtemp(prefix="long-mission-")) if args.keep is None else args.keep
    try:
        short = _fly(REFERENCE_S, root / "reference")
        print(f"{'mission':>12} {'rows':>11} {'wall (s)':>9} {'peak RSS (MB)':>14} {'CSV (GB)':>9}", flush=True)
        print(f"{REFERENCE_S:>10g} s {short['rows']:>11} {short['wall_s']:>9.1f} {short['peak_rss_bytes'] / 1e6:>14.1f} "
              f"{short['csv_bytes'] / 1e9:>9.4f}", flush=True)
        long = _fly(args.duration, root / "long")
        ratio = long["peak_rss_bytes"] / short["peak_rss_bytes"]
        print(f"{args.duration:>10g} s {long['rows']:>11} {long['wall_s']:>9.1f} {long['peak_rss_bytes'] / 1e6:>14.1f} "
              f"{long['csv_bytes'] / 1e9:>9.3f}")
        print(f"peak resident memory, long / {REFERENCE_S:g} s: {ratio:.3f} (target <= {TARGET})")

        from cosim.scenario.definition import load_scenario
        from quadrotor_paper.run_metrics import from_results

        scenario = load_scenario("circles", {"simulation.duration": args.duration})
        t = time.perf_counter()
        recomputed = from_results(scenario, root / "long" / "results.csv")
        read = time.perf_counter() - t
        streamed = {k: long["summary"].get(k) for k in recomputed}
        same = streamed == recomputed
        print(f"summary == recomputed from its CSV ({read:.0f} s to read): {'yes' if same else 'NO'} {streamed}"
              + ("" if same else f" != {recomputed}"))
        per_step = (long["wall_s"] - short["wall_s"]) / (long["rows"] - short["rows"])  # start-up and plots apart
        if args.duration < 1e6:
            steps = round(1e6 / scenario.step)
            print(f"10^6 s at the same cost per step ({per_step * 1e6:.1f} us): {steps * per_step / 3600:.1f} h, "
                  f"CSV {long['csv_bytes'] / long['rows'] * (steps + 1) / 1e9:.0f} GB; memory: what grows with "
                  f"the duration is bounded (docs/security.md), so as measured")
        if args.json:
            args.json.write_text(json.dumps({"reference": short, "long": long, "ratio": ratio, "same": same},
                                            indent=1, default=str))
        return 0 if same else 1
    finally:
        if args.keep is None:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
