"""How the importers a Python user can install fly the archives of
``fnn-cosim export-ssp``: a markdown table for ``docs/ssp.md``.

Exports ``circles``, ``circles_sensors``, ``circles_estimated``, ``figure8_lab`` and
``figure8_lab_estimated`` (every component an FMU,
``quadrotor_paper.portable.all_fmu``) and flies each archive with

* our master (the scenario file, and the archive read back by ``load_ssp``),
  in its default ``feedthrough`` ordering, and the archive in the
  ``exchange`` ordering (libcosim's);
* libcosim (``libcosimpy``, :func:`cosim.ssp.archive.run_libcosim`);
* fmpy's ``simulate_ssp`` as a user calls it (``stop_time`` = the duration,
  ``step_size`` = the step), on the archive as exported (its FMUs start from
  the scenario's values) and on the same archive with the stock FMUs (their
  own defaults, the values bound in the SSD only: what fmpy flew before the
  archives were self-contained);
* fmpy's ``simulate_fmu`` on each FMU alone (no connection at all: every
  input stays at its start value).

For each: what it honours (parameter bindings, an initial transfer of the
connections before the first step, its ordering), the Euclidean position
RMSE over the recorded rows as our summary computes it
(:func:`quadrotor_paper.metrics.rmse`, the scenario's ``[metrics]`` signals)
and the position at t = duration. fmpy's ``simulate_ssp`` stamps a row t
with the values after the step from t, and its time is a running sum, so it
records one row more than the duration: the position at t = duration is its
row stamped duration - h; its RMSE is over all its rows.

A second table prints issue 29's bars for the estimated scenarios, importer
by importer (:func:`_bars`): ``circles_estimated`` over our master's run, and
``figure8_lab_estimated`` over ``figure8_lab`` in the same importer against
that ratio in our master, each within 3 %.

    .venv/bin/python benchmarks/ssp_importers.py [--scenarios circles circles_estimated ...]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from cosim.scenario.definition import load_scenario
from cosim.scenario.assembly import build_master, fmu_file
from cosim.ssp.archive import load_ssp
from cosim.ssp.export import export_ssp
from quadrotor_paper.metrics import rmse
from quadrotor_paper.portable import all_fmu

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the libcosim runner lives with its users
from libcosim_runner import run_libcosim  # noqa: E402

_FMPY = "Jacobi, transfer after the step"
HONOURS = {  # importer -> (parameter bindings, initial transfer, ordering)
    "our master (scenario)": ("yes", "yes", "feedthrough: Gauss-Seidel along direct feedthrough"),
    "our master (archive, `load_ssp`)": ("yes", "yes", "feedthrough: Gauss-Seidel along direct feedthrough"),
    "our master (archive, `exchange` ordering)": ("yes", "yes", "Jacobi (libcosim's)"),
    "libcosim 0.11 (`libcosimpy`)": ("yes", "yes", "Jacobi (our `exchange`)"),
    "fmpy `simulate_ssp`, archive as exported": ("no", "no: connectors start at 0.0", _FMPY),
    "fmpy `simulate_ssp`, stock FMUs (before)": ("no", "no: connectors start at 0.0", _FMPY),
    "fmpy `simulate_fmu`, each FMU alone": ("no (SSD not read)", "none: no connection", "none"),
}


def _row(result, position, reference, final_index=-1) -> tuple[float, np.ndarray]:
    return rmse(result, position, reference), np.array([result[p][final_index] for p in position])


def fly(name: str, folder: Path) -> dict[str, tuple[float, np.ndarray]]:
    """Every importer's (RMSE, final position) on scenario ``name``."""
    from fmpy import simulate_fmu
    from fmpy.ssp.simulation import simulate_ssp

    scenario = all_fmu(load_scenario(name))
    metrics = scenario.raw["metrics"]
    position, reference = metrics["position"], metrics["reference"]
    signals = list(dict.fromkeys(position + reference))
    archive = export_ssp(scenario, folder / f"{name}.ssp")
    stock = export_ssp(scenario, folder / f"{name}-stock.ssp",
                       fmu_files={c: fmu_file(spec) for c, spec in scenario.fmus.items()})
    n, h, duration = scenario.n_steps, scenario.step, scenario.duration
    out = {}
    with build_master(load_scenario(name)) as master:
        out["our master (scenario)"] = _row(master.run(duration), position, reference)
    loaded = load_ssp(archive)
    with build_master(loaded) as master:
        out["our master (archive, `load_ssp`)"] = _row(master.run(duration), position, reference)
    with build_master(load_ssp(archive, overrides={"simulation.ordering": "exchange"})) as master:
        out["our master (archive, `exchange` ordering)"] = _row(master.run(duration), position, reference)
    out["libcosim 0.11 (`libcosimpy`)"] = _row(run_libcosim(archive, signals), position, reference)
    for label, path in (("archive as exported", archive), ("stock FMUs (before)", stock)):
        rows = simulate_ssp(str(path), stop_time=duration, step_size=h)
        out[f"fmpy `simulate_ssp`, {label}"] = _row(rows, position, reference, final_index=n - 1)
    alone = {}  # each FMU on its own, every input at its start value
    for component in {s.partition(".")[0] for s in signals}:
        fmu = folder / "x" / component
        alone[component] = simulate_fmu(str(_member(archive, f"resources/{component}.fmu", fmu)),
                                        stop_time=duration, output_interval=h, fmi_type="CoSimulation",
                                        output=[s.partition(".")[2] for s in signals if s.startswith(component + ".")])
    joined = {s: alone[s.partition(".")[0]][s.partition(".")[2]] for s in signals}
    out["fmpy `simulate_fmu`, each FMU alone"] = _row(joined, position, reference)
    return out


def _member(archive: Path, member: str, target: Path) -> Path:
    import zipfile

    target.parent.mkdir(parents=True, exist_ok=True)
    target.with_suffix(".fmu").write_bytes(zipfile.ZipFile(archive).read(member))
    return target.with_suffix(".fmu")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenarios", nargs="+",
                   default=["circles", "circles_sensors", "circles_estimated", "figure8_lab", "figure8_lab_estimated"])
    args = p.parse_args(argv)
    results = {}
    with tempfile.TemporaryDirectory(prefix="ssp-importers-") as tmp:
        for name in args.scenarios:
            results[name] = fly(name, Path(tmp) / name)
    head = " | ".join(f"{name}: RMSE (m) | {name}: position at the end (m)" for name in args.scenarios)
    print(f"| importer | parameter bindings | initial transfer | ordering | {head} |")
    print("|" + "---|" * (4 + 2 * len(args.scenarios)))
    for importer, honours in HONOURS.items():
        cells = []
        for name in args.scenarios:
            error, final = results[name][importer]
            cells += [f"{error:.4g}", "(" + ", ".join(f"{v:.4g}" for v in final) + ")"]
        print(f"| {importer} | " + " | ".join(honours + tuple(cells)) + " |")
    print()
    _bars(results)
    return 0


def _bars(results) -> None:
    """Issue 29's bars, importer by importer: ``circles_estimated``'s RMSE over
    our master's (feedthrough, the scenario), and the filter's own cost on the
    lab, ``figure8_lab_estimated``'s RMSE over ``figure8_lab``'s in the same
    importer, against that ratio in our master; each within 3 %."""
    ours = "our master (scenario)"
    importers = [i for i in HONOURS if i != ours and not i.startswith("fmpy `simulate_fmu`")
                 and "stock FMUs" not in i]
    columns = []
    if "circles_estimated" in results:
        base = results["circles_estimated"][ours][0]
        columns.append(("circles_estimated over our master's", lambda i: results["circles_estimated"][i][0] / base))
    if "figure8_lab" in results and "figure8_lab_estimated" in results:
        def lab(i):
            return results["figure8_lab_estimated"][i][0] / results["figure8_lab"][i][0]
        columns.append(("figure8_lab_estimated / figure8_lab, over our master's ratio",
                        lambda i: lab(i) / lab(ours)))
    if not columns:
        return
    print("| importer | " + " | ".join(label for label, _ in columns) + " |")
    print("|---|" + "---|" * len(columns))
    for importer in importers:
        cells = [f"{value(importer):.4f} ({'within' if abs(value(importer) - 1) <= 0.03 else 'outside'} 3 %)"
                 for _, value in columns]
        print(f"| {importer} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    raise SystemExit(main())
