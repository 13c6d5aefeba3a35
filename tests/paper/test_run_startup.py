"""A run of the shipped mission, its FMUs built and its scenario validated
before, starts only what it needs (issue 26): no CasADi, Dask, matplotlib or
python-control, no pydantic (the scenario served from the cache, the
controller built from its validated values) and no lxml (the FMUs' model
descriptions served from the cache, cosim.fmi.description_cache), and writes
what a validated run writes. What is imported is checked here, in a fresh interpreter
(``sys.modules``); the time it takes, by ``benchmarks/cli_startup.py``."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

NOT_FOR_A_RUN = ("casadi", "dask", "distributed", "matplotlib", "control", "scipy", "pydantic", "pydantic_core",
                 "importlib.metadata", "fnn_controller.fast", "fmu_models.export.build", "cosim.scenario.tables",
                 "quadrotor_paper.section_tables", "lxml",
                 # nor what only another path uses: TOML parsed (the document kept), an archive opened, a log shown
                 "tomllib", "zipfile", "logging", "cosim.fmi.log",
                 # the cases (a study's), a Model Exchange solver (the shipped FMUs are Co-Simulation), a results reader
                 "quadrotor_paper.options", "cosim.fmi.model_exchange", "cosim.fmi.me_system", "csv")

_RUN = """
import json, sys
from quadrotor_paper.cli import main
code = main(["run", "circles", "--no-plots", "--quiet", "--out", sys.argv[1]])
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""


def _run(out: Path, cwd: Path) -> tuple[int, set[str]]:
    proc = subprocess.run([sys.executable, "-c", _RUN, str(out)], capture_output=True, text=True, cwd=cwd)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    return report["code"], set(report["modules"])


def test_a_run_of_the_shipped_mission_imports_no_casadi_dask_matplotlib_pydantic_or_lxml(tmp_path):
    first_code, _ = _run(tmp_path / "first", tmp_path)  # builds or finds the FMUs, keeps the validated scenario
    code, modules = _run(tmp_path / "again", tmp_path)
    assert first_code == code == 0
    assert {"fmpy", "cosim.loop.master", "quadrotor_paper.controller_component"} <= modules  # the run is seen
    loaded = sorted(m for m in modules if any(m == name or m.startswith(name + ".") for name in NOT_FOR_A_RUN))
    assert loaded == []
    # the two runs write the same, to the bit
    assert (tmp_path / "again" / "results.csv").read_bytes() == (tmp_path / "first" / "results.csv").read_bytes()
    first, again = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("first", "again"))
    for summary in (first, again):
        for key in ("wall_time_s", "real_time_factor", "results"):
            summary.pop(key, None)
    assert {**first, "results_csv": None} == {**again, "results_csv": None} and first["status"] == "ok"


def test_the_shipped_mission_served_from_the_cache_is_the_validated_one(tmp_path):
    """What the run above reads instead of validating: the kept scenario and
    the controller built from its values as they are (cosim.scenario.parameters.Given)."""
    from cosim.scenario.definition import Scenario, load_scenario, parse_scenario
    from quadrotor_paper.controller_component import ControllerComponent

    for overrides in ({}, {"controller.position.kd": 2.5, "controller.position.nu": [0.5, 0.5, 0.1],
                           "controller.position.init.alpha": 2e-3, "controller.nominal.m": 1.3,
                           "controller.geometric.dt": 0.01, "controller.variant": "pd+smc", "wind.speed": 4.0}):
        load_scenario("circles", overrides)  # validated and kept, or already kept
        kept = load_scenario("circles", overrides)
        validated = parse_scenario(kept.raw, source=kept.source)
        assert all(getattr(kept, k) == getattr(validated, k) for k in Scenario.__slots__ if k != "__weakref__")
        parameters = kept.components["controller"]["parameters"]
        given = ControllerComponent.from_parameters("controller", parameters, validated=True)
        checked = ControllerComponent.from_parameters("controller", parameters)
        assert (given.variant, given.psi_ref, given.position, given.geometric) == \
            (checked.variant, checked.psi_ref, checked.position, checked.geometric)
        assert given.fmu_entry() == checked.fmu_entry()


_COLLECTOR = """
import atexit, gc, json, sys
from quadrotor_paper.cli import main
numpy_before_main = "numpy" in sys.modules  # the registrations load none: its import falls in main's start-up
out = sys.argv[1]
called = main(["run", "circles", "--no-plots", "--quiet", "--out", out + "/called"])  # a caller's main([...])
after_call = [gc.isenabled(), gc.get_freeze_count()]
report = {"called": called, "after_call": after_call, "numpy_before_main": numpy_before_main}
# what the command's process is left with, told by Python's exit handlers, which the command's own end runs
atexit.register(lambda: print(json.dumps({**report, "after_command": [gc.isenabled(), gc.get_freeze_count()]})))
sys.argv = ["fnn-cosim", "run", "circles", "--no-plots", "--quiet", "--out", out + "/command"]
main()  # the entry point's call: ends the process with the command's status
print("main() returned")
"""


def test_the_command_collects_cycles_again_once_started(tmp_path):
    """fnn-cosim's own process runs its start-up with the cycle collector off
    and turns it on again once started, start-up's objects set aside
    (gc.freeze); a caller's main([...]) leaves the collector as it is. Both
    write the same results. Importing the command line (the application's
    registrations with it) loads no numpy: its import is part of the start-up
    the collector is off for. The command's main() ends the process with
    the command's status, its output flushed and Python's exit handlers run
    (cli._end)."""
    proc = subprocess.run([sys.executable, "-c", _COLLECTOR, str(tmp_path)], capture_output=True, text=True,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "main() returned" not in proc.stdout
    *printed, told = proc.stdout.splitlines()
    assert printed[-1] == f"results: {tmp_path / 'command'}"  # the command's output, then the exit handler's
    report = json.loads(told)
    assert report["called"] == 0 and report["numpy_before_main"] is False
    assert report["after_call"] == [True, 0]
    enabled, frozen = report["after_command"]
    assert enabled and frozen > 0
    assert (tmp_path / "called" / "results.csv").read_bytes() == (tmp_path / "command" / "results.csv").read_bytes()


_FAILING = """
import atexit, sys
from quadrotor_paper.cli import main
atexit.register(lambda: print("exit handler ran"))
sys.stdout.write("buffered, ")  # a pipe: held in the buffer until flushed
sys.argv = ["fnn-cosim", "run", "circles", "--no-plots", "--quiet", "--set", "wind.speed=-1",
            "--out", sys.argv[1]]
main()
"""


def test_the_command_ends_with_its_status_its_output_and_its_exit_handlers(tmp_path):
    """A refused input ends the command's process with status 2, its one
    line on stderr, what was written to stdout before flushed and the exit
    handlers run, as Python's own exit does."""
    proc = subprocess.run([sys.executable, "-c", _FAILING, str(tmp_path / "out")], capture_output=True,
                          text=True, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stdout == "buffered, exit handler ran\n"
    assert proc.stderr.startswith("fnn-cosim: error: ") and "wind.speed" in proc.stderr
    assert proc.stderr.count("\n") == 1


def test_a_run_makes_only_its_own_parser(capsys):
    """``fnn-cosim run ...`` makes the run's parser alone, with its arguments
    (quadrotor_paper.commands.Commands): it parses what the parser of every
    command parses; another command or options first make every command's
    parser (the listing of --help, the refusal of an unknown command) and
    add the arguments of the one given."""
    from quadrotor_paper.cli import _parser
    from quadrotor_paper.commands import declared
    from quadrotor_paper.commands.run import add_commands

    argv = ["run", "circles", "--no-plots", "--seed", "3"]
    parser, full = _parser(argv), _parser()
    args = parser.parse_args(argv)
    assert (args.scenario, args.no_plots, args.seed) == ("circles", True, 3)
    assert args.func.__module__ == add_commands.__module__ and vars(args) == vars(full.parse_args(argv))
    names = ("run", "table2", "table3", "reproduce", "sweep", "export-ssp", "schema", "scenarios", "build-fmu",
             "linearize", "stability", "calibrate")
    for name in names[1:]:  # not made for a run; with every command, each one's help from its own arguments
        for tree, status in ((parser, 2), (full, 0), (_parser(["--debug", name, "--help"]), 0)):
            with pytest.raises(SystemExit) as ended:
                tree.parse_args(["--debug", name, "--help"])
            assert ended.value.code == status, (name, status)
    capsys.readouterr()
    with pytest.raises(SystemExit) as ended:
        _parser(["--help"])
    assert ended.value.code == 0 and capsys.readouterr().out == full.format_help()
    assert "{" + ",".join(names) + "}" in full.format_help() and tuple(declared()) == names


_ARGPARSE_END = """
import sys
from quadrotor_paper.cli import main
sys.argv = ["fnn-cosim", *sys.argv[1:]]
main()
print("main() returned")
"""


def test_the_command_ends_as_argparse_ends_it():
    """--help and arguments argparse refuses end the command's process the
    same way, with argparse's status and text."""
    helped = subprocess.run([sys.executable, "-c", _ARGPARSE_END, "--help"], capture_output=True, text=True)
    assert helped.returncode == 0 and helped.stdout.startswith("usage: fnn-cosim") and "returned" not in helped.stdout
    refused = subprocess.run([sys.executable, "-c", _ARGPARSE_END, "run", "circles", "--record-every", "0"],
                             capture_output=True, text=True)
    assert refused.returncode == 2 and refused.stdout == ""
    assert refused.stderr.startswith("fnn-cosim: error: run: argument --record-every: ") and \
        refused.stderr.count("\n") == 1
