"""A log's and a signal table's memory against their file's size (issue 42 item 5).

The log: writes a CSV of ``--rows`` rows (default 3 million) and
``--columns`` columns besides the time, then, each in a fresh process, reads
it as ``fnn-cosim calibrate`` does (``read_log``, then ``Log.check`` of two
of its columns: what a fit of one input and one output uses), and the same
with every column, and prints each process's peak resident memory beside
the file's size, less that of a process that only imports the reader (the
interpreter, numpy, pyarrow).

The table (the issue's case): a CSV of the same rows and one column (about
48 MB) played as a signal table into the plant's ``wind_x`` by ``fnn-cosim
run`` for 1 s, in its default form (the table FMU, the compiled loop) and
as the Python component, each process's peak printed beside the file's
size, a process that runs the plant alone, and the same run with the reader
before 2026-11-29 (``cosim/scenario/signal_table.py`` at commit :data:`BEFORE`, taken from
git: it parsed the whole file into Python rows; the issue measured 972 MB).

    .venv/bin/python benchmarks/log_memory.py [--rows 3000000] [--columns 2] [--no-before]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

BEFORE = "f3f8343"  # the last commit whose signal table read a CSV whole (cosim/scenario/signal_table.py)

CHILD = r"""
import json, sys
import numpy, pyarrow, pyarrow.csv
from cosim.calibration.log import read_log
path, used = sys.argv[1], sys.argv[2]
def peak():  # this process's own high-water mark (ru_maxrss would carry the parent's over the fork)
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))
if used != "none":
    log = read_log(path)
    names = list(log.columns) if used == "all" else list(log.columns)[:int(used)]
    log.check(names)
    print(json.dumps({"rows": int(log.times.size), "names": names,
                      "peak": peak()}))
else:
    print(json.dumps({"peak": peak()}))
"""


RUN = r"""
import json, sys
scenario, out, before = sys.argv[1], sys.argv[2], sys.argv[3]
def peak():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))
if before != "-":  # the reader of commit BEFORE in place of cosim.scenario.signal_table, before anything imports it
    import importlib.util, cosim, cosim.limits
    cosim.limits.MAX_TABLE_BYTES = 256 * 2 ** 20  # its bound, since removed
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader("cosim.scenario.signal_table", loader=None))
    module.__package__ = "cosim"
    sys.modules["cosim.scenario.signal_table"] = cosim.scenario.signal_table = module
    exec(compile(open(before).read(), "cosim/scenario/signal_table.py@before", "exec"), module.__dict__)
from quadrotor_paper.cli import main
code = main(["run", scenario, "--out", out, "--no-plots", "--quiet"])
print(json.dumps({"code": code, "peak": peak()}))
"""

SCENARIO = """connections = [{connections}]
[simulation]
duration = 1.0
step = 0.01
[fmus.Quadrotor]
model = "Quadrotor"
[record]
signals = ["Quadrotor.x"]
"""


def _peak(path: Path, used: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(path), used], capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(out.stderr)
    return json.loads(out.stdout)


def _run(scenario: Path, before: Path | None = None) -> int:
    """The peak of ``fnn-cosim run scenario`` in a fresh process (exit 0 asserted)."""
    out = subprocess.run([sys.executable, "-c", RUN, str(scenario), str(scenario.with_suffix("")),
                          str(before) if before else "-"], capture_output=True, text=True)
    if out.returncode or json.loads(out.stdout.splitlines()[-1])["code"] != 0:
        raise SystemExit(out.stderr + out.stdout)
    return json.loads(out.stdout.splitlines()[-1])["peak"]


def tables(tmp: Path, rows: int, before: bool) -> None:
    """The issue's case: the table of ``rows`` rows and one column played for 1 s (module docstring)."""
    path = tmp / "table.csv"
    t = np.arange(rows) * 1e-3
    np.savetxt(path, np.column_stack([t, np.sin(t)]), delimiter=",", header="time,x0", comments="",
               fmt=["%.7g", "%.4g"])
    del t
    size = path.stat().st_size
    table = '\n[components.log]\nkind = "signal_table"\nfile = "table.csv"\n'
    plant = tmp / "plant.toml"
    plant.write_text(SCENARIO.format(connections=""), encoding="utf-8")
    played = SCENARIO.format(connections='"log.x0 -> Quadrotor.wind_x"') + table
    (tmp / "fmu.toml").write_text(played, encoding="utf-8")
    (tmp / "python.toml").write_text(played + 'form = "python"\n', encoding="utf-8")
    base = _run(plant)
    print(f"\ntable: {rows} rows, 2 columns, {size / 2**20:.1f} MiB, played for 1 s into the plant by fnn-cosim run")
    print(f"  the plant alone: peak {base / 2**20:.1f} MiB")
    runs = [("the table FMU (the default form)", tmp / "fmu.toml", None),
            ("the Python component", tmp / "python.toml", None)]
    if before:
        old = tmp / "table_before.py"
        got = subprocess.run(["git", "show", f"{BEFORE}:cosim/scenario/signal_table.py"], capture_output=True, text=True,
                             cwd=Path(__file__).parent)
        if got.returncode:
            print(f"  the reader before (commit {BEFORE}): not in this checkout's history")
        else:
            old.write_text(got.stdout, encoding="utf-8")
            runs.append((f"the reader before (commit {BEFORE}), the table FMU", tmp / "fmu.toml", old))
    for what, scenario, old in runs:
        peak = _run(scenario, old)
        print(f"  {what}: peak {peak / 2**20:.1f} MiB, {(peak - base) / 2**20:.1f} MiB above the plant alone = "
              f"{(peak - base) / size:.2f}x the file (the time and x0 as floats: {16 * rows / 2**20:.1f} MiB)")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=3_000_000)
    parser.add_argument("--columns", type=int, default=2, help="columns besides the time")
    parser.add_argument("--no-before", action="store_true", help="leave out the reader before (its run takes ~1 min)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.csv"
        t = np.arange(args.rows) * 1e-3
        data = np.column_stack([t] + [np.sin(t * (k + 1)) for k in range(args.columns)])
        header = ",".join(["time"] + [f"x{k}" for k in range(args.columns)])
        np.savetxt(path, data, delimiter=",", header=header, comments="", fmt=["%.7g"] + ["%.4g"] * args.columns)
        del data, t
        size = path.stat().st_size
        base = _peak(path, "none")["peak"]
        print(f"file: {args.rows} rows, {args.columns + 1} columns, {size / 2**20:.1f} MiB")
        print(f"a process that imports the reader: peak {base / 2**20:.1f} MiB")
        for used in ("1", "all"):
            r = _peak(path, used)
            extra = r["peak"] - base
            print(f"read for time + {', '.join(r['names'])}: peak {r['peak'] / 2**20:.1f} MiB, "
                  f"{extra / 2**20:.1f} MiB above the imports = {extra / size:.2f}x the file "
                  f"(the columns' floats alone: {8 * r['rows'] * (len(r['names']) + 1) / 2**20:.1f} MiB)")
        tables(Path(tmp), args.rows, not args.no_before)


if __name__ == "__main__":
    main()
