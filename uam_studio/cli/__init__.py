"""Command-line interface: ``uam-studio <command> ...``.

Commands are registered in :data:`COMMANDS` (name -> :class:`~uam_studio.cli.common.Command`): each
command's module adds its arguments to its own sub-parser and handles the parsed namespace, returning
an exit code. Bad input of any kind (an :class:`~uam_studio.errors.InputError`, or a value argparse
rejects) prints one line ``error: ...`` to stderr and exits with code 2.

Commands: ``serve`` (start the Panel app), ``simulate`` (fly a route of a mission file and report voltage and EOD),
``plan`` (plan a mission with the attention planner (default), the DQN agent, the oracle or the greedy baseline;
physics-checked), ``fly`` (fly it in
a world the operator cannot see, re-planning from its sensors, from its pack's logbook), ``logbook`` (make or read
a pack's logbook), ``data`` (the real data sets, and NASA's own files imported), ``fleet`` (a fleet's day or life under
three dispatchers), ``findings`` (the paper's four findings, agents trained on the Dask engine), ``train``
(``dynaformer``, ``dqn`` or ``attention``; never into ``pretrained/``), ``evaluate`` (``dynaformer``: a
model on held-out data; ``real``: the models on the CMU eVTOL dataset's real cells; ``lives``: leave one
of its real lives out) and ``identify`` (a real cell's parameter set), each in the module of
its name; :mod:`uam_studio.cli.common` holds what they share.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from uam_studio import __version__
from uam_studio.cli import data, evaluate, findings, fleet, fly, identify, logbook, plan, serve, simulate, train
from uam_studio.cli.common import EXIT_BROKEN_PIPE, EXIT_INPUT, EXIT_INTERRUPTED, CliExit, Command, Parser
from uam_studio.errors import InputError

COMMANDS: dict[str, Command] = {
    "simulate": simulate.COMMAND,
    "plan": plan.COMMAND,
    "fly": fly.COMMAND,
    "logbook": logbook.COMMAND,
    "data": data.COMMAND,
    "fleet": fleet.COMMAND,
    "findings": findings.COMMAND,
    "train": train.COMMAND,
    "evaluate": evaluate.COMMAND,
    "identify": identify.COMMAND,
    "serve": serve.COMMAND,
}


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="uam-studio", description="Health-aware mission planning for eVTOL aircraft.")
    parser.add_argument("--version", action="version", version=f"uam-studio {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for name, cmd in COMMANDS.items():
        p = sub.add_parser(name, help=cmd.help, description=cmd.help)
        cmd.add_arguments(p)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 ok, 2 bad input, 130 interrupted)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            raise CliExit(f"choose a command: {', '.join(COMMANDS)} (see 'uam-studio --help')", EXIT_INPUT)
        return COMMANDS[args.command].run(args)
    except (CliExit, InputError) as err:
        print(f"error: {' '.join(str(err).split())}", file=sys.stderr)
        return err.code if isinstance(err, CliExit) else EXIT_INPUT
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # Output piped into e.g. `head`, which exited: stop quietly (Python docs' recipe).
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
