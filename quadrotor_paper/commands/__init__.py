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
share at most (:mod:`quadrotor_paper.commands.options`: ``--set``,
``--workers``, ``--fmu-log``);
what a command's options or its run need is imported when its arguments are
added or it runs, so a command pays for no other's (docs/cosim.md,
"Start-up of a run"). The top-level parser and ``main`` are
:mod:`quadrotor_paper.cli`'s.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from importlib import import_module
from typing import Callable, Iterator

__all__ = ["GROUPS", "Commands", "declared", "out_folder", "output_options", "DEFAULT_OUT", "EXIT_RUN_FAILED", "EXIT_BAD_INPUT"]

GROUPS = ("run", "studies", "files", "stability", "calibrate")
DEFAULT_OUT = Path("results")
EXIT_RUN_FAILED = 1  # a run diverged or an FMU failed mid-run (partial results kept)
EXIT_BAD_INPUT = 2  # a scenario, connection or FMU file is wrong: refused before anything ran

Arguments = Callable[[argparse.ArgumentParser], None]


class Commands:
    """``fnn-cosim``'s subcommands, declared by the groups' modules
    (:meth:`add`) and made on argparse's public API (``add_subparsers``,
    ``add_parser``): :meth:`make` adds the parsers of the commands asked for
    (their names and lines of help: the usage lines, ``--help`` and the
    refusal of an unknown command list them), :meth:`complete` adds a
    command's arguments. A run makes its own parser alone, and neither adds
    the tables' options nor imports what their help names (the variants, the
    option rows); argparse makes a parser per command, asking gettext for
    its headings' translations (start-up, docs/cosim.md). What a command
    accepts, refuses and prints is the same as with every parser made and
    every command's arguments added."""

    def __init__(self) -> None:
        self._declared: dict[str, tuple[Arguments | None, Callable, dict]] = {}
        self._made: dict[str, argparse.ArgumentParser] = {}

    def add(self, name: str, arguments: Arguments | None, handler: Callable[[argparse.Namespace], int],
            **kwargs) -> None:
        """The command ``name``: ``arguments(parser)`` adds its arguments and
        ``handler(args)`` (``args.func``) runs it and returns the exit
        status; ``kwargs`` go to ``add_parser`` (``help``: its line in the
        listing, ``description``)."""
        self._declared[name] = (arguments, handler, kwargs)

    def __contains__(self, name: object) -> bool:
        return name in self._declared

    def __iter__(self) -> Iterator[str]:
        """The commands' names, in the order declared (the listing's)."""
        return iter(self._declared)

    def make(self, subparsers, name: str | None = None) -> None:
        """Add the parser of the command ``name`` (``None``: of every command,
        in the order declared) to ``subparsers``, without its arguments."""
        for command in self._declared if name is None else [name]:
            # without its -h until completed: a command's help is its arguments' (see complete)
            self._made[command] = subparsers.add_parser(command, add_help=False, **self._declared[command][2])

    def complete(self, name: str | None = None) -> None:
        """Add the arguments of the command ``name`` (``None``: of every
        command made): argparse's ``-h`` first, as ``add_help`` puts it,
        then the command's own."""
        for command in list(self._made) if name is None else [name]:
            parser = self._made.pop(command)
            arguments, handler, _ = self._declared[command]
            parser.add_argument("-h", "--help", action="help", help="show this help message and exit")
            if arguments is not None:
                arguments(parser)
            parser.set_defaults(func=handler)


def declared() -> Commands:
    """Every command of :data:`GROUPS`, declared in their order (made by
    ``quadrotor_paper.cli``'s parser)."""
    commands = Commands()
    for group in GROUPS:
        import_module(f"{__name__}.{group}").add_commands(commands)
    return commands


def out_folder(given: str | None, default: Path) -> Path:
    """The output folder, checked (made, writable) before anything runs."""
    from cosim.files import output_folder

    return output_folder(given or default)


def output_options(parser: argparse.ArgumentParser) -> None:
    """``--out``, ``--fmu-log`` and ``--quiet``: what every command that flies
    runs into a results folder takes."""
    from .options import fmu_log_option

    parser.add_argument("--out", help="output directory (default: under results/)")
    fmu_log_option(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no notes")
