"""``fnn-cosim``'s commands, one module per group; each adds its commands'
parsers and calls the library (the engine, :mod:`cosim`, and this
application's modules) with what the command line says.

* :mod:`~quadrotor_paper.commands.run` -- ``run``: one scenario, its files;
* :mod:`~quadrotor_paper.commands.studies` -- ``table2``, ``table3``,
  ``reproduce``, ``sweep``: studies, many runs;
* :mod:`~quadrotor_paper.commands.files` -- ``export-ssp``, ``schema``,
  ``scenarios``, ``build-fmu``: what the tool writes and lists besides runs;
* :mod:`~quadrotor_paper.commands.stability` -- ``linearize``, ``stability``:
  linear systems from FMUs;
* :mod:`~quadrotor_paper.commands.calibrate` -- ``calibrate``: an FMU fitted
  to a log.

:data:`GROUPS` lists them in the order ``fnn-cosim --help`` lists their
commands. A group's module imports argparse and the options the commands
share at most (:mod:`quadrotor_paper.set_option`,
:mod:`quadrotor_paper.workers_option`, :mod:`quadrotor_paper.fmu_log_option`);
what a command's options or its run need is imported when its arguments are
added or it runs, so a command pays for no other's (docs/cosim.md,
"Start-up of a run"). The top-level parser and ``main`` are
:mod:`quadrotor_paper.cli`'s.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable

__all__ = ["GROUPS", "Commands", "out_folder", "output_options", "DEFAULT_OUT", "EXIT_RUN_FAILED", "EXIT_BAD_INPUT"]

GROUPS = ("run", "studies", "files", "stability", "calibrate")
DEFAULT_OUT = Path("results")
EXIT_RUN_FAILED = 1  # a run diverged or an FMU failed mid-run (partial results kept)
EXIT_BAD_INPUT = 2  # a scenario, connection or FMU file is wrong: refused before anything ran

Arguments = Callable[[argparse.ArgumentParser], None]


class Commands:
    """``fnn-cosim``'s subcommands on argparse's public API
    (``add_subparsers``, ``add_parser``): every command's parser is made at
    once with its name and line of help (the usage lines, ``--help`` and
    the refusal of an unknown command need them), and its arguments are
    added when asked (:meth:`complete`): the command given, or every one.
    A run adds neither the tables' options nor imports what their help
    names (the variants, the option rows). What a command accepts, refuses
    and prints is the same either way."""

    def __init__(self, subparsers) -> None:
        self._subparsers = subparsers
        self._pending: dict[str, tuple[argparse.ArgumentParser, Arguments | None, Callable]] = {}

    def add(self, name: str, arguments: Arguments | None, handler: Callable[[argparse.Namespace], int],
            **kwargs) -> None:
        """The command ``name``: ``arguments(parser)`` adds its arguments and
        ``handler(args)`` (``args.func``) runs it and returns the exit
        status; ``kwargs`` go to ``add_parser`` (``help``: its line in the
        listing, ``description``)."""
        # without its -h until completed: a command's help is its arguments' (see complete)
        parser = self._subparsers.add_parser(name, add_help=False, **kwargs)
        self._pending[name] = (parser, arguments, handler)

    def complete(self, name: str | None = None) -> None:
        """Add the arguments of the command ``name`` (``None``: of every
        command not yet completed): argparse's ``-h`` first, as
        ``add_help`` puts it, then the command's own."""
        for command in list(self._pending) if name is None else [name]:
            parser, arguments, handler = self._pending.pop(command)
            parser.add_argument("-h", "--help", action="help", help="show this help message and exit")
            if arguments is not None:
                arguments(parser)
            parser.set_defaults(func=handler)


def out_folder(given: str | None, default: Path) -> Path:
    """The output folder, checked (made, writable) before anything runs."""
    from cosim.files import output_folder

    return output_folder(given or default)


def output_options(parser: argparse.ArgumentParser) -> None:
    """``--out``, ``--fmu-log`` and ``--quiet``: what every command that flies
    runs into a results folder takes."""
    from ..fmu_log_option import fmu_log_option

    parser.add_argument("--out", help="output directory (default: under results/)")
    fmu_log_option(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no notes")
