"""``fnn-cosim``: run scenarios, reproduce Table 2 and Table 3, build the FMUs.

Subcommands::

    fnn-cosim run SCENARIO|FILE.ssp [--out DIR] [--set KEY=VALUE ...] [--seed N] [--variant V] [--no-plots] [--record-every K]
                 [--profile] [--save-learned FILE] [--load-learned FILE] [--fmu-log [INSTANCE=]LEVEL]
    fnn-cosim export-ssp SCENARIO --out FILE.ssp [--set KEY=VALUE ...]
    fnn-cosim table2 [--out DIR] [--seeds 10] [--winds 1,3,5] [--duration S] [--workers 2] [--scheduler ADDRESS]
    fnn-cosim table3 [--out DIR] [--seeds 10] [--duration S] [--workers 2] [--scheduler ADDRESS]
    fnn-cosim reproduce [--out DIR] [--seeds 10] [--duration S] [--workers 2] [--scheduler ADDRESS]
    fnn-cosim sweep STUDY.toml|NAME [--out DIR] [--workers N] [--scheduler ADDRESS] [--no-plots]
    fnn-cosim scenarios
    fnn-cosim schema scenario|study|settings|column-map [--out FILE]
    fnn-cosim build-fmu [--out DIR]
    fnn-cosim linearize FMU|MODEL [--fmi 2|3] [--parameter N=V ...] [--input N=V ...] [--start N=V ...]
                 [--method auto|derivatives|differences] [--interface auto|me|cs] [--bode IN:OUT ...] [--out DIR]
    fnn-cosim linearize INSTANCE --scenario SCENARIO --time T [--set KEY=VALUE ...] [--bode IN:OUT ...] [--out DIR]
    fnn-cosim stability [--out DIR] [--kp KP] [--kd KD] [--speed V] [--wind W] [--no-cosim] [--along-flight [--along-every S]]
                 [--figures [NAME ...]] [--workers N]
    fnn-cosim calibrate LOG --fmu FILE|MODEL|--scenario SCENARIO [--fit NAMES] [--fix K=V ...] [--columns MAP] [--out DIR]

SCENARIO is a TOML file or the name of a shipped scenario (``circles``, ``circles_sensors``,
``figure8``); STUDY a study file (``docs/studies.md``) or the name of a
shipped one (``quadrotor_paper/studies/``). The sweeps run on Dask: a local
cluster of ``--workers`` processes (``--workers 1``: in this process), or
the running cluster at ``--scheduler``. Results go under ``results/`` unless
``--out`` says otherwise.
Errors print one line on stderr (``--debug`` adds the traceback): a bad
scenario, connection or FMU file (a broken archive, no binary for this
platform, a parameter the FMU refuses) exits with status 2 before anything
runs; a run that diverges or fails mid-way exits with status 1 and keeps its
partial results.

This module is the entry point: the top-level parser and :func:`main`. Each
command's arguments and handler are in :mod:`quadrotor_paper.commands`, one
module per group of commands.
"""
from __future__ import annotations

import argparse
import gc
import os
import sys
from typing import Sequence

from .commands import EXIT_BAD_INPUT, EXIT_RUN_FAILED, declared
from .commands.options import apply_fmu_log

__all__ = ["main", "EXIT_BAD_INPUT", "EXIT_RUN_FAILED"]

# the commands that end their start-up themselves (see _started): a run, when its master is built
_OWN_START_UP = ("run",)


class _Parser(argparse.ArgumentParser):
    """argparse with its refusals in the tool's one line (exit 2: nothing ran)."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"fnn-cosim: error: {self.prog.removeprefix('fnn-cosim ')}: {message}\n"
                  if self.prog != "fnn-cosim" else f"fnn-cosim: error: {message}\n")


def _parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """``fnn-cosim``'s parser for the command line ``argv``
    (:mod:`quadrotor_paper.commands`, one module per group of commands).

    ``fnn-cosim COMMAND ...``, the usual form: the parser of COMMAND alone,
    with its arguments: argparse gives the rest of the line to the parser of
    the first positional word, so no other command's parser can be asked
    for, nor the listing of them all (the top-level refusals print no
    usage: :class:`_Parser`). Any other line (options first, an unknown
    command, none): every command named with its line of help, and argparse's
    own parse of ``argv`` finds the command whose arguments are added (or
    ends the process as it would: ``--help``, no command, an unknown one).
    Without ``argv``: every command with its arguments."""
    p = _Parser(prog="fnn-cosim", description=__doc__.split("\n\n")[0])
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    p.set_defaults(start_up_over=_started)  # a command that ends its own start-up calls it (_OWN_START_UP)
    commands = declared()
    subparsers = p.add_subparsers(dest="command", required=True)
    if argv and argv[0] in commands:
        commands.make(subparsers, argv[0])
        commands.complete(argv[0])
        return p
    commands.make(subparsers)
    commands.complete(None if argv is None else p.parse_known_args(argv)[0].command)
    return p


# The command's own process (main() of the command line, not a caller's main([...])) starts with Python's
# cycle collector off: start-up (imports, the parser, the master's build) makes thousands of objects that
# live as long as the process and few cycles, and the collector scanned them again and again (a tenth of a
# run's start-up). When start-up is over (_started), they are set aside for good (gc.freeze) and the
# collector runs as before on what the command makes from then on.
_START_UP = [False]


def _started() -> None:
    """Start-up is over: the cycle collector on again, what start-up made set aside (see above)."""
    if _START_UP[0]:
        _START_UP[0] = False
        gc.freeze()
        gc.enable()


def _end(code: int) -> None:
    """The command's own process ends with the command: its output flushed
    and the ``atexit`` handlers run, as Python's exit does them, then
    ``os._exit(code)``, without the interpreter's teardown, which frees
    every object of the process one by one (what the system does at once
    with the process's memory) and was a run's longest step after its loop.
    Left to Python's exit, as before, when another thread is alive (its
    exit waits for it) or the output cannot be flushed (Python's exit
    reports it and its status). Every file a command writes is closed by the
    command (docs/cosim.md, "Start-up of a run")."""
    import atexit
    import threading

    if threading.active_count() > 1:
        return
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:  # e.g. a closed pipe: Python's exit says so and exits with 120
        return
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:
        return
    os._exit(code)


def main(argv: Sequence[str] | None = None) -> int:
    """``fnn-cosim``: ``main()`` is the command's own process (the entry
    point's call), which ends the process once the command returns
    (:func:`_end`); ``main([...])`` runs a command for a caller (the tests,
    an application) and returns its exit status."""
    if argv is None and gc.isenabled():  # the process is the command: see _started
        gc.disable()
        _START_UP[0] = True
    try:
        code = _main(argv)
    except SystemExit as exc:  # argparse's end: --help, or arguments refused (exit 2)
        if argv is None and (exc.code is None or isinstance(exc.code, int)):
            code = exc.code or 0
        else:
            raise
    finally:
        _started()
        if argv is None:  # the process ends with the command: its exit need not scan what the command made
            gc.freeze()
    if argv is None:
        _end(code)
    return code


def _main(argv: Sequence[str] | None) -> int:
    from cosim.errors import ConnectionCheckError, CosimError, FmuLoadError, ScenarioError, one_line

    argv = sys.argv[1:] if argv is None else list(argv)
    args = _parser(argv).parse_args(argv)
    try:
        apply_fmu_log(getattr(args, "fmu_log", ()))
        if args.command not in _OWN_START_UP:
            _started()
        return args.func(args)
    except CosimError as exc:
        if args.debug:
            import traceback

            traceback.print_exc()
        print(f"fnn-cosim: error: {one_line(str(exc))}", file=sys.stderr)
        bad_input = isinstance(exc, (ScenarioError, ConnectionCheckError, FmuLoadError))
        return EXIT_BAD_INPUT if bad_input else EXIT_RUN_FAILED
    except KeyboardInterrupt:
        print("fnn-cosim: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a fault of ours, not of the input: still one line (the traceback with --debug)
        if args.debug:
            raise
        print(f"fnn-cosim: internal error: {type(exc).__name__}: {one_line(str(exc))[:300]} "
              f"(a bug of fnn-cosim; --debug shows where)", file=sys.stderr)
        return EXIT_RUN_FAILED


if __name__ == "__main__":
    sys.exit(main())
