"""Command-line interface: ``uam-studio <command> ...``.

Commands are registered in :data:`COMMANDS` (name -> :class:`Command`): each adds its
arguments to its own sub-parser and handles the parsed namespace, returning an exit
code. Bad input of any kind (an :class:`~uam_studio.errors.InputError`, or a value
argparse rejects) prints one line ``error: ...`` to stderr and exits with code 2.

Commands: ``simulate`` (fly a route of a mission file and report voltage and EOD).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NoReturn

from uam_studio import __version__
from uam_studio.errors import InputError

EXIT_OK = 0
EXIT_INPUT = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141


class _CliExit(Exception):
    """Raised instead of printing usage and exiting, so :func:`main` reports one line."""

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code


class _Parser(argparse.ArgumentParser):
    """argparse that turns its errors into a single ``error: ...`` line (no usage dump)."""

    def error(self, message: str) -> NoReturn:
        raise _CliExit(f"{message} (see '{self.prog} --help')", EXIT_INPUT)


@dataclass(frozen=True)
class Command:
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


# --------------------------------------------------------------------------- parsing helpers


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


# --------------------------------------------------------------------------- simulate


def _add_simulate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", metavar="MISSION.json", help="mission file (see assets/example_mission.json)")
    p.add_argument("--route", required=True, help="comma-separated node names, e.g. A,B,vertiport")
    p.add_argument("--altitudes", required=True, help="cruise altitude (m) of each leg, e.g. 500,1000,500")
    p.add_argument("--q-max", type=float, default=None, help="override the mission's q_max (C)")
    p.add_argument("--r0", type=float, default=None, help="override the mission's r0 (ohm)")
    p.add_argument("--eod-v", type=float, default=None, help="override the mission's EOD cut-off (V)")
    p.add_argument("--dt", type=float, default=1.0, help="sample step (s), default 1")
    p.add_argument("--json", action="store_true", help="print the simulation as JSON")


def _run_simulate(args: argparse.Namespace) -> int:
    from uam_studio.planning import load_mission, simulate_route

    route = parse_list("route", args.route)
    altitudes = parse_floats("altitudes", args.altitudes)
    mission = load_mission(args.mission)
    sim = simulate_route(mission, route, altitudes, q_max=args.q_max, r0=args.r0, eod_v=args.eod_v, dt_s=args.dt)
    if args.json:
        json.dump(sim.to_dict(), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
        return EXIT_OK

    def fmt(x: float | None, spec: str) -> str:
        return "-" if x is None else format(x, spec)

    name_w = max([len("from"), len("to")] + [len(g.from_node) for g in sim.legs] + [len(g.to) for g in sim.legs])
    print(
        f"{mission.name}: q_max {sim.q_max:g} C, r0 {sim.r0:g} ohm, EOD {sim.eod_v:g} V, dt {sim.dt_s:g} s"
    )
    print(f"{'leg':>3}  {'from':<{name_w}}  {'to':<{name_w}}  {'km':>6}  {'alt m':>6}  "
          f"{'start s':>8}  {'end s':>8}  {'min V':>6}")
    for i, g in enumerate(sim.legs, 1):
        print(f"{i:>3}  {g.from_node:<{name_w}}  {g.to:<{name_w}}  {g.distance_km:>6.1f}  {g.altitude_m:>6g}  "
              f"{fmt(g.start_s, '.0f'):>8}  {fmt(g.end_s, '.0f'):>8}  {fmt(g.min_voltage_v, '.3f'):>6}")
    recharges = f"{sim.charging_cycles} recharge{'' if sim.charging_cycles == 1 else 's'}"
    if sim.safe:
        print(f"EOD: not reached; safe ({recharges}, min {sim.min_voltage_v:.3f} V)")
    else:
        lost = sum(not g.reached for g in sim.legs)
        print(f"EOD: reached at {sim.eod_s:.0f} s; UNSAFE ({lost} of {len(sim.legs)} legs not completed)")
    return EXIT_OK


def _add_train_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", choices=["dynaformer"], help="what to train")
    p.add_argument("--out", default="runs/dynaformer", help="run folder (checkpoints, weights); default runs/dynaformer")
    p.add_argument("--steps", type=int, default=None, help="optimiser steps (default 5000)")
    p.add_argument("--n-train", type=int, default=None, help="synthetic training discharges (default 24000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="auto", help="auto (CUDA when available), cpu or cuda")
    p.add_argument("--no-resume", action="store_true", help="start from scratch even if a checkpoint exists")


def _run_train(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .dynaformer.train import TrainConfig, train

    out = Path(args.out).resolve()
    bundled = (Path(__file__).resolve().parent.parent / "pretrained").resolve()
    if out == bundled or bundled in out.parents:
        raise _CliExit("--out: must not be the bundled pretrained/ folder (copy weights there by hand)", EXIT_INPUT)
    cfg = TrainConfig(seed=args.seed, device=args.device)
    if args.steps is not None:
        if args.steps < 1:
            raise _CliExit("--steps: must be >= 1", EXIT_INPUT)
        cfg.steps = args.steps
    if args.n_train is not None:
        if args.n_train < 64:
            raise _CliExit("--n-train: must be >= 64", EXIT_INPUT)
        cfg.n_train = args.n_train
    weights = train(cfg, out, resume=not args.no_resume)
    print(f"wrote {weights}")
    return EXIT_OK


def _add_evaluate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", choices=["dynaformer"], help="what to evaluate")
    p.add_argument("--weights", default=None, help="weights file (default: the bundled model)")
    p.add_argument("--n", type=int, default=400, help="missions per held-out set (default 400)")
    p.add_argument("--seed", type=int, default=12345)
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")


def _run_evaluate(args: argparse.Namespace) -> int:
    import json

    from .dynaformer.evaluate import evaluate, format_report
    from .dynaformer.predictor import load_predictor

    if args.n < 10:
        raise _CliExit("--n: must be >= 10", EXIT_INPUT)
    metrics = evaluate(load_predictor(args.weights), n=args.n, seed=args.seed)
    print(json.dumps(metrics, indent=2) if args.json else format_report(metrics))
    return EXIT_OK


COMMANDS: dict[str, Command] = {
    "simulate": Command(
        "fly a route of a mission and report voltage and end of discharge",
        _add_simulate_arguments,
        _run_simulate,
    ),
    "train": Command("train a model (writes to a run folder, never over pretrained/)", _add_train_arguments, _run_train),
    "evaluate": Command("evaluate a model on held-out synthetic data", _add_evaluate_arguments, _run_evaluate),
}


# --------------------------------------------------------------------------- entry point


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="uam-studio", description="Health-aware mission planning for eVTOL aircraft.")
    parser.add_argument("--version", action="version", version=f"uam-studio {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
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
            raise _CliExit(f"choose a command: {', '.join(COMMANDS)} (see 'uam-studio --help')", EXIT_INPUT)
        return COMMANDS[args.command].run(args)
    except (_CliExit, InputError) as err:
        print(f"error: {' '.join(str(err).split())}", file=sys.stderr)
        return err.code if isinstance(err, _CliExit) else EXIT_INPUT
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # Output piped into e.g. `head`, which exited: stop quietly (Python docs' recipe).
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())
