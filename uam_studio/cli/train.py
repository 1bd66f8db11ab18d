"""``uam-studio train``: train the Dynaformer or any retrainable planner of the catalogue
(:data:`~uam_studio.planning.planners.PLANNERS`, through its
:class:`~uam_studio.planning.agents.trainer.Trainer`) into a run folder, never into the bundled
``pretrained/``; each model refuses the options of the others."""

from __future__ import annotations

import argparse
from typing import Any

from uam_studio.cli.common import EXIT_INPUT, EXIT_OK, CliExit, Command, seed_arg
from uam_studio.errors import InputError
from uam_studio.planning.agents.trainer import SHARED_CLI_OPTIONS, trainers

# uam_studio.dynaformer.cells.DYNAFORMER_CELLS' keys (that module imports torch; the parser must not)
DYNAFORMER_CELL_KEYS = ["nasa18650", "nasa18650_4a", "vtc6", "vtc6_landing_held_out", "vtc6_cell_held_out"]


class DynaformerRun:
    """``uam-studio train dynaformer``: the predictor's run, in the shape of a planner's trainer's CLI part."""

    cli_title = "dynaformer only"
    cli_shared = {
        "out": "default runs/dynaformer",
        "steps": "optimiser steps (default 60000)",
        "device": "auto (CUDA when available, default), cpu or cuda",
        "init_from": "fine-tune these Dynaformer weights (e.g. pretrained/dynaformer.pt), the take-off health "
                     "refitted",
    }

    def add_cli_arguments(self, group: Any) -> tuple[str, ...]:
        return tuple(action.dest for action in (
            group.add_argument("--n-train", type=int, default=None, help="synthetic training discharges "
                                                                          "(default 24000)"),
            group.add_argument("--no-resume", action="store_true", default=None,
                               help="start from scratch even if a checkpoint exists"),
            group.add_argument("--cell", default=None, choices=DYNAFORMER_CELL_KEYS,
                               help="the cell type to train for: nasa18650 (the paper's, default), nasa18650_4a "
                                    "(the same cell at the NASA PCoE data set's loads, up to 4.5 A), vtc6 (the VTC6 "
                                    "identified on the CMU eVTOL dataset, loads flown by power), or "
                                    "vtc6_landing_held_out / vtc6_cell_held_out (the VTC6 sets identified without "
                                    "VAH01's landing / without cell VAH01); see uam_studio/dynaformer/cells.py"),
        ))

    def train_cli(self, args: argparse.Namespace) -> str:
        from uam_studio.atomic_io import make_writable_folder
        from uam_studio.bundled import refuse_bundled
        from uam_studio.dynaformer.model import DynaformerConfig
        from uam_studio.dynaformer.train import TrainConfig, pick_device, read_init, train

        out = args.out or "runs/dynaformer"
        refuse_bundled(out, "--out")
        cfg = TrainConfig(seed=args.seed, device=args.device or "auto", cell=args.cell or "nasa18650",
                          init=args.init_from)
        pick_device(cfg.device)
        if cfg.init is not None:  # a weights file that does not load is refused before the run folder is made
            read_init(cfg.init, DynaformerConfig.for_cell(cfg.cell))
        if args.steps is not None:
            if args.steps < 1:
                raise InputError("--steps", "must be >= 1")
            cfg.steps = args.steps
        if args.n_train is not None:
            if args.n_train < 64:
                raise InputError("--n-train", "must be >= 64")
            cfg.n_train = args.n_train
        make_writable_folder(out, "--out")
        return f"wrote {train(cfg, out, resume=not args.no_resume)}"


def _models() -> dict[str, Any]:
    """What ``uam-studio train`` trains, by name: the Dynaformer, then every retrainable planner."""
    return {"dynaformer": DynaformerRun(), **trainers()}


# the shared options (SHARED_CLI_OPTIONS): what each is, and its argparse keywords besides its default None
_SHARED: dict[str, tuple[str, dict[str, Any]]] = {
    "out": ("run folder", {}), "steps": ("how long to train", {"type": int}), "device": ("the torch device", {}),
    "init_from": ("start from this file instead of random weights", {"metavar": "FILE"})}


def _add_train_arguments(p: argparse.ArgumentParser) -> None:
    """The models' options; the parser's defaults carry the models (``train_models``) and, for each option but
    ``--seed``, the models that read it (``train_option_models``: the others refuse it)."""
    models = _models()
    p.add_argument("model", choices=list(models), help="what to train")
    p.add_argument("--seed", type=seed_arg, default=0)
    owners: dict[str, list[str]] = {}
    for name in SHARED_CLI_OPTIONS:
        what, kind = _SHARED[name]
        owners[name] = [m for m, model in models.items() if name in model.cli_shared]
        uses = "; ".join(f"{m}: {models[m].cli_shared[name]}" for m in owners[name])
        p.add_argument("--" + name.replace("_", "-"), default=None, help=f"{what}. {uses}", **kind)
    for m, model in models.items():
        for name in model.add_cli_arguments(p.add_argument_group(model.cli_title)):
            owners.setdefault(name, []).append(m)
    p.set_defaults(train_models=models, train_option_models=owners)


def _run_train(args: argparse.Namespace) -> int:
    for name, models in args.train_option_models.items():
        if getattr(args, name) is not None and args.model not in models:
            flag = "--" + name.replace("_", "-")
            raise CliExit(f"{flag}: not an option of 'train {args.model}' (only of 'train {' / '.join(models)}')",
                          EXIT_INPUT)
    print(args.train_models[args.model].train_cli(args))
    return EXIT_OK


COMMAND = Command("train a model (writes to a run folder, never over pretrained/)", _add_train_arguments, _run_train)
