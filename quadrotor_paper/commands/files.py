"""``fnn-cosim export-ssp``, ``schema``, ``scenarios`` and ``build-fmu``:
what the tool writes and lists besides runs (an SSP archive, the JSON
Schemas of its files, the shipped scenarios, the FMUs)."""
from __future__ import annotations

import argparse

from .options import overrides
from . import Commands

__all__ = ["add_commands"]


def add_commands(commands: Commands) -> None:
    commands.add("export-ssp", _export_ssp_arguments, _export_ssp,
                 help="write a scenario as an SSP 1.0 archive, every component an FMU")
    commands.add("schema", _schema_arguments, _schema,
                 help="print the JSON Schema of a scenario, study or calibration file (for editors)")
    commands.add("scenarios", None, _scenarios, help="list the shipped scenarios")
    commands.add("build-fmu", _build_fmu_arguments, _build_fmu,
                 help="build every model as FMI 2.0 (and 3.0) FMUs")


def _export_ssp_arguments(e: argparse.ArgumentParser) -> None:
    e.add_argument("scenario", help="TOML file or shipped scenario name (see fnn-cosim scenarios)")
    e.add_argument("--out", required=True, help="the .ssp file to write")
    e.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scenario value")


def _export_ssp(args) -> int:
    """Write the scenario, every component as an FMU, as an SSP archive."""
    from cosim.files import output_file
    from cosim.scenario.definition import load_scenario
    from cosim.ssp.export import export_ssp

    from ..portable import all_fmu

    out = output_file(args.out, "--out")
    print(export_ssp(all_fmu(load_scenario(args.scenario, overrides(args.set))), out))
    return 0


def _schema_arguments(js: argparse.ArgumentParser) -> None:
    js.add_argument("kind", choices=("scenario", "study", "settings", "column-map"),
                    help="settings, column-map: fnn-cosim calibrate's --settings and --columns files")
    js.add_argument("--out", help="write it to this file instead")


def _schema(args) -> int:
    """Print the JSON Schema of a scenario, a study or a calibration file (for editors: docs/cosim.md)."""
    import json

    if args.kind == "scenario":
        from cosim.scenario.definition import scenario_json_schema as schema
    elif args.kind == "study":
        from cosim.study.definition import study_json_schema as schema
    else:  # fnn-cosim calibrate's files: --settings, --columns
        from cosim.calibration.columns import calibration_schema

        schema = lambda: calibration_schema()[args.kind.replace("-", "_")]  # noqa: E731
    text = json.dumps(schema(), indent=1)
    if args.out:
        from cosim.files import output_file

        output_file(args.out, "--out").write_text(text + "\n")
        print(args.out)
    else:
        print(text)
    return 0


def _scenarios(args) -> int:
    from cosim.scenario.definition import load_scenario, shipped_scenarios

    shipped = sorted(shipped_scenarios().items())
    width = max(len(name) for name, _ in shipped)
    for name, path in shipped:
        print(f"{name:{width}s}  {load_scenario(path).description}  ({path})")
    return 0


def _build_fmu_arguments(b: argparse.ArgumentParser) -> None:
    b.add_argument("--out", default="build/fmus", help="output directory (default build/fmus)")


def _build_fmu(args) -> int:
    """Build every registered model (the plant, the wind, the references, the
    controller of every variant) in every FMI version the exporter supports,
    side by side (:func:`cosim.scenario.registry.write_fmu_models`); print the path
    of each FMU written, one per line."""
    from cosim.files import output_folder
    from cosim.scenario.registry import write_fmu_models
    from fmu_models.export.build import FMI_VERSIONS

    for path in write_fmu_models(output_folder(args.out), sorted(FMI_VERSIONS)):
        print(path)
    return 0
