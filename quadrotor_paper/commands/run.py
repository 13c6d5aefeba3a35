"""``fnn-cosim run``: one scenario (a shipped name, a TOML file or an SSP
archive) flown once into its files (:func:`quadrotor_paper.experiments.run_with_files`)."""
from __future__ import annotations

import argparse
import sys

from .options import overrides
from . import DEFAULT_OUT, EXIT_RUN_FAILED, Commands, output_options

__all__ = ["add_commands"]


def add_commands(commands: Commands) -> None:
    commands.add("run", _arguments, _run, help="run one scenario: results CSV, plots, summary")


def _record_every(text: str) -> int:
    """The ``type`` of ``--record-every``: a whole number from 1."""
    from cosim.errors import shown_text

    try:
        k = int(text)
    except ValueError:  # not a whole number, or beyond Python's digits
        k = 0
    if k < 1:
        raise argparse.ArgumentTypeError(f"{shown_text(repr(text))}: expected a whole number from 1 (every K-th "
                                         f"row written)")
    return k


def _arguments(r: argparse.ArgumentParser) -> None:
    from fnn_controller.variants import variant_names

    r.add_argument("scenario", help="TOML file, shipped scenario name (see fnn-cosim scenarios), or SSP archive "
                                    "(.ssp)")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario value, e.g. --set wind.speed=5 (repeatable)")
    r.add_argument("--seed", type=int, help="the run's seed (simulation.seed): every seeded component and FMU "
                   "draws from it (the FNN's initial weights, sensor noise, wind)")
    r.add_argument("--variant", choices=variant_names(), help="controller variant")
    r.add_argument("--no-plots", action="store_true")
    r.add_argument("--record-every", type=_record_every, default=1, metavar="K",
                   help="write every K-th row to results.csv (rows 0, K, 2K, ...): a long mission in less disk; "
                        "the metrics still take every row (default 1)")
    r.add_argument("--profile", action="store_true",
                   help="time each phase of the loop (summary.json: cost_per_step_us; python_loop: why the "
                        "compiled loop cannot run the plan)")
    r.add_argument("--save-learned", metavar="FILE", help="write the controller's learned state after the run")
    r.add_argument("--load-learned", metavar="FILE",
                   help="start the controller from a saved learned state (resume learning)")
    output_options(r)


def _scenario(args):
    """The scenario of ``args.scenario`` with the command line's changes:
    ``--set``, ``--seed``, and for a TOML scenario ``--variant`` and
    ``--load-learned`` (an SSP archive's controller is an FMU it holds)."""
    from cosim.errors import ScenarioError
    from cosim.files import is_ssp

    changes = overrides(args.set)
    if args.seed is not None:
        changes["simulation.seed"] = args.seed
    if is_ssp(args.scenario):
        for flag, value in (("--variant", args.variant), ("--load-learned", args.load_learned)):
            if value:
                raise ScenarioError(f"{flag} {value}: an SSP archive's controller is an FMU it holds, with its "
                                    f"own model and state; give it to a TOML scenario's [controller]")
        from cosim.ssp.archive import load_ssp

        return load_ssp(args.scenario, overrides=changes)
    if args.variant:
        changes["controller.variant"] = args.variant
    if args.load_learned:
        changes["controller.learned"] = str(args.load_learned)
    from cosim.scenario.definition import load_scenario

    return load_scenario(args.scenario, changes)


def _run(args) -> int:
    from cosim.scenario.assembly import build_master
    from cosim.files import not_others_results, output_file, output_folder, safe_name
    from cosim.notes import release, show_on_stderr

    from ..experiments import run_with_files

    show_on_stderr(not args.quiet)  # what the engine decides for the user (a default step, a unit's radian)
    scenario = _scenario(args)
    with build_master(scenario) as master:  # every input refused before anything is written
        args.start_up_over()
        release()  # the inputs are taken: the notes the engine held for them (none with --quiet)
        # every place a result goes is checked before the run: nothing computed is lost for want of it
        out = not_others_results(output_folder(args.out or DEFAULT_OUT / f"run-{safe_name(scenario.name)}"), "run")
        learned_file = output_file(args.save_learned, "--save-learned") if args.save_learned else None
        _, lines, failure = run_with_files(scenario, master, out, record_every=args.record_every,
                                           profile=args.profile, save_learned=learned_file,
                                           resumed_from=args.load_learned, plots=not args.no_plots,
                                           quiet=args.quiet)
    print("\n".join(lines[4:-2]))
    print(f"results: {out}")
    if failure:
        print(f"fnn-cosim: error: {failure}", file=sys.stderr)
        return EXIT_RUN_FAILED
    return 0
