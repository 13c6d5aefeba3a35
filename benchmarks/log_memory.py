"""A calibration log's memory against its file's size (issue 42 item 5).

Writes a CSV of ``--rows`` rows (default 3 million, about 48 MB, as the
issue's) and ``--columns`` columns besides the time, then, each in a fresh
process, reads it as ``fnn-cosim calibrate`` does (``read_log``, then
``Log.check`` of two of its columns: what a fit of one input and one output
uses), and the same with every column, and prints each process's peak
resident memory beside the file's size, less that of a process that only
imports the reader (the interpreter, numpy, pyarrow). Before 2026-11-29 the
reader parsed the whole file into Python rows: the signal table's reader of
the same file peaked at 972 MB, about 20x.

    .venv/bin/python benchmarks/log_memory.py [--rows 3000000] [--columns 2]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

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


def _peak(path: Path, used: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(path), used], capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(out.stderr)
    return json.loads(out.stdout)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=3_000_000)
    parser.add_argument("--columns", type=int, default=2, help="columns besides the time")
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


if __name__ == "__main__":
    main()
