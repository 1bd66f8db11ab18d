"""What every command of the CLI shares: exit codes, the one-line error, the parser class, the
:class:`Command` record and the parsers of comma-separated values."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from typing import NoReturn

from uam_studio.errors import MAX_SEED, InputError, check_seed

EXIT_OK = 0
EXIT_INPUT = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141


class CliExit(Exception):
    """Raised instead of printing usage and exiting, so :func:`~uam_studio.cli.main` reports one line."""

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code


class Parser(argparse.ArgumentParser):
    """argparse that turns its errors into a single ``error: ...`` line (no usage dump)."""

    def error(self, message: str) -> NoReturn:
        raise CliExit(f"{message} (see '{self.prog} --help')", EXIT_INPUT)


@dataclass(frozen=True)
class Command:
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def parse_list(field: str, text: str) -> list[str]:
    """Split ``"A, B,vertiport"`` into ``["A", "B", "vertiport"]``; empty entries are errors."""
    items = [s.strip() for s in text.split(",")]
    if not text.strip() or any(not s for s in items):
        raise InputError(field, f"{text!r} has an empty entry; expected comma-separated values like A,B,vertiport")
    return items


def parse_floats(field: str, text: str) -> list[float]:
    """Split ``"500,1000"`` into floats, naming the bad entry if one is not a number."""
    out = []
    for i, s in enumerate(parse_list(field, text)):
        try:
            out.append(float(s))
        except ValueError:
            raise InputError(f"{field}[{i}]", f"{s!r} is not a number") from None
    return out


def seed_arg(text: str) -> int:
    """argparse type of ``--seed``: an integer in [0, ``MAX_SEED``], checked before anything runs."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text[:40]!r} is not an integer; a seed is an integer in "
                                         f"[0, {MAX_SEED}]") from None
    try:
        return check_seed("--seed", value)
    except InputError as err:
        raise argparse.ArgumentTypeError(str(err)[len("--seed: "):]) from None


# planning.operations.world's WORLDS, the default first (written here so that parsing imports no model;
# tests/test_world.py holds the two equal)
WORLD_CHOICES = ("varied", "model")


def add_world_arguments(p: argparse.ArgumentParser, what: str, pack: str | None = None) -> None:
    """``--world`` (``what``: what flies in it) and, where ``pack`` says what the number is read with, ``--pack``."""
    p.add_argument("--world", choices=WORLD_CHOICES, default=WORLD_CHOICES[0],
                   help=f"the world {what} in: varied (default; a pack is not its model: its own diffusion, "
                        "open-circuit curve and heat, drifting sensors) or model (a pack is exactly its cell type's "
                        "model, for teaching)")
    if pack is not None:
        p.add_argument("--pack", type=seed_arg, default=None, metavar="N",
                       help="the pack's number: seeds its own parameters in the varied world (default: --seed); "
                            + pack)


def add_engine_arguments(p: argparse.ArgumentParser, what: str) -> None:
    """``--workers`` and ``--address``: where :func:`uam_studio.engine.run_tasks` runs ``what``."""
    p.add_argument("--workers", type=int, default=None,
                   help=f"Dask workers of the local cluster that runs the {what} (default: one per core; 0: "
                        "no cluster, one after another here)")
    p.add_argument("--address", default=None, metavar="tcp://HOST:PORT",
                   help=f"run the {what} on this running Dask scheduler instead of a local cluster")


def check_workers(args: argparse.Namespace) -> None:
    """``--workers`` within 0-256 (one line naming the flag otherwise)."""
    from uam_studio.errors import check_range

    if args.workers is not None:
        check_range("--workers", args.workers, 0, 256)
