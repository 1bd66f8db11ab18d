"""``uam-studio train``: train the Dynaformer, the DQN agent or the attention planner into a run folder
(never into the bundled ``pretrained/``), each model refusing the options of the others."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from uam_studio.cli.common import EXIT_INPUT, EXIT_OK, CliExit, Command, seed_arg

# uam_studio.dynaformer.cells.DYNAFORMER_CELLS' keys (that module imports torch; the parser must not)
DYNAFORMER_CELL_KEYS = ["nasa18650", "vtc6", "vtc6_landing_held_out", "vtc6_cell_held_out"]

# which models each train option belongs to (the others refuse it)
_OPTION_MODELS = {
    "steps": ("dynaformer", "dqn"),
    "device": ("dynaformer", "attention"),
    **dict.fromkeys(("n_train", "no_resume", "cell"), ("dynaformer",)),
    "init_from": ("dqn", "dynaformer"),
    **dict.fromkeys(("scenario", "mission", "alpha", "beta", "gamma", "safe_return"), ("dqn",)),
    **dict.fromkeys(("oracle_missions", "search_missions", "epochs"), ("attention",)),
}


def _add_train_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", choices=list(_RUNS), help="what to train")
    p.add_argument("--out", default=None,
                   help="run folder; default runs/dynaformer (dynaformer), runs/dqn_<scenario> (dqn: writes "
                        "agent.zip and card.json; a path ending in .zip names the agent file itself)")
    p.add_argument("--steps", type=int, default=None,
                   help="optimiser steps (dynaformer, default 60000) or env transitions (dqn, default 50000)")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--device", default=None,
                   help="dynaformer and attention: auto (CUDA when available, default), cpu or cuda")
    p.add_argument("--init-from", default=None, metavar="FILE",
                   help="dqn and dynaformer: fine-tune this file (an agent zip, e.g. pretrained/dqn_single_charge.zip, "
                        "exploration starting at epsilon 0.2; or Dynaformer weights, e.g. pretrained/dynaformer.pt, "
                        "the take-off health refitted) instead of starting from random weights")
    g = p.add_argument_group("dynaformer only")
    g.add_argument("--n-train", type=int, default=None, help="synthetic training discharges (default 24000)")
    g.add_argument("--no-resume", action="store_true", default=None,
                   help="start from scratch even if a checkpoint exists")
    g.add_argument("--cell", default=None, choices=DYNAFORMER_CELL_KEYS,
                   help="the cell type to train for: nasa18650 (the paper's, default), vtc6 (the VTC6 identified "
                        "on the CMU eVTOL dataset, loads flown by power), or vtc6_landing_held_out / "
                        "vtc6_cell_held_out (the VTC6 sets identified without VAH01's landing / without cell "
                        "VAH01); see uam_studio/dynaformer/cells.py")
    g = p.add_argument_group("dqn only")
    g.add_argument("--scenario", default=None,
                   help="single_flight, single_charge or multi_charge; default: the mission's, else single_charge")
    g.add_argument("--mission", default=None, metavar="FILE",
                   help="train on this mission's map (battery health drawn at random each episode); "
                        "default: a random mission every episode")
    g.add_argument("--alpha", type=float, default=None, help="reward per reached destination x priority (default 1)")
    g.add_argument("--beta", type=float, default=None, help="penalty per charging stop (default 1)")
    g.add_argument("--gamma", type=float, default=None, help="penalty for an end of discharge (default 5)")
    g.add_argument("--safe-return", action="store_true", default=None,
                   help="a leg that would leave no way home ends the episode with -gamma (the planner's "
                        "safety rule, learnt in training); default off, the paper's setting")
    g = p.add_argument_group("attention only (the default planner; writes attention_planner.pt and card.json)")
    g.add_argument("--oracle-missions", type=int, default=None,
                   help="phase 1: missions of 2-8 destinations solved by the exact oracle (default 1200)")
    g.add_argument("--search-missions", type=int, default=None,
                   help="phase 2: missions of 9-20 destinations per scenario planned by the network's own "
                        "beam search (default 300; 0 skips the phase)")
    g.add_argument("--epochs", type=int, default=None, help="phase 1 epochs (default 40)")


def _refuse_bundled(out) -> None:
    from uam_studio.bundled import is_bundled

    if is_bundled(out):
        raise CliExit("--out: must not be the bundled pretrained/ folder (copy weights there by hand)", EXIT_INPUT)


def _check_out_folder(folder) -> None:
    """Create the run folder ``folder`` if needed and check a file can be written in it, before any work."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise CliExit(f"--out: {folder} exists and is not a folder", EXIT_INPUT) from None
    except OSError as err:
        raise CliExit(f"--out: cannot create the folder {folder} ({err.strerror or err})", EXIT_INPUT) from None
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        raise CliExit(f"--out: cannot write in {folder} ({err.strerror or err})", EXIT_INPUT) from None


def _reject_options(args: argparse.Namespace) -> None:
    for name, models in _OPTION_MODELS.items():
        if getattr(args, name) is not None and args.model not in models:
            flag = "--" + name.replace("_", "-")
            raise CliExit(f"{flag}: not an option of 'train {args.model}' (only of 'train {' / '.join(models)}')",
                          EXIT_INPUT)


def _run_train(args: argparse.Namespace) -> int:
    _reject_options(args)
    return _RUNS[args.model](args)


def _run_train_attention(args: argparse.Namespace) -> int:
    from ..dynaformer.train import pick_device
    from ..planning.agents.attention.train import AttentionTrainConfig, train_attention

    out = Path(args.out or "runs/attention")
    _refuse_bundled(out)
    cfg = AttentionTrainConfig(seed=args.seed)
    cfg.device = str(pick_device(args.device or "auto"))
    for name, lo in (("oracle_missions", 10), ("search_missions", 0), ("epochs", 1)):
        value = getattr(args, name)
        if value is not None:
            if value < lo:
                raise CliExit(f"--{name.replace('_', '-')}: must be >= {lo}", EXIT_INPUT)
            setattr(cfg, name, value)
    _check_out_folder(out)
    weights = train_attention(cfg, out)
    print(f"wrote {weights}")
    return EXIT_OK


def _run_train_dynaformer(args: argparse.Namespace) -> int:
    from ..dynaformer.model import DynaformerConfig
    from ..dynaformer.train import TrainConfig, pick_device, read_init, train

    out = args.out or "runs/dynaformer"
    _refuse_bundled(out)
    cfg = TrainConfig(seed=args.seed, device=args.device or "auto", cell=args.cell or "nasa18650",
                      init=args.init_from)
    pick_device(cfg.device)
    if cfg.init is not None:  # a weights file that does not load is refused before the run folder is made
        read_init(cfg.init, DynaformerConfig.for_cell(cfg.cell))
    if args.steps is not None:
        if args.steps < 1:
            raise CliExit("--steps: must be >= 1", EXIT_INPUT)
        cfg.steps = args.steps
    if args.n_train is not None:
        if args.n_train < 64:
            raise CliExit("--n-train: must be >= 64", EXIT_INPUT)
        cfg.n_train = args.n_train
    _check_out_folder(out)
    weights = train(cfg, out, resume=not args.no_resume)
    print(f"wrote {weights}")
    return EXIT_OK


def _run_train_dqn(args: argparse.Namespace) -> int:
    from uam_studio.planning import SCENARIOS, load_mission
    from uam_studio.planning.agents.retrain import retrain_dqn, training_setup
    from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO

    if args.scenario is not None and args.scenario not in SCENARIOS:
        raise CliExit(f"--scenario: {args.scenario!r} is not a scenario; allowed: {', '.join(SCENARIOS)}",
                      EXIT_INPUT)
    mission = load_mission(args.mission) if args.mission is not None else None
    scenario = args.scenario or (mission.scenario if mission is not None else DEFAULT_SCENARIO)
    out = Path(args.out or f"runs/dqn_{scenario}")
    agent = out if out.suffix == ".zip" else out / "agent.zip"
    _refuse_bundled(agent)
    if agent.exists() and not agent.is_file():
        raise CliExit(f"--out: {agent} exists and is not a file", EXIT_INPUT)
    if args.steps is not None and args.steps < 1:
        raise CliExit("--steps: must be >= 1", EXIT_INPUT)
    # Shared with the app's Retrain tab: validation, env, card and atomic save live in the library. Every
    # option is checked there before the run folder is made.
    cfg, env_fn = training_setup(scenario, mission, args.alpha, args.beta, args.gamma, args.steps, args.seed,
                                 safe_return=bool(args.safe_return), init_agent=args.init_from)
    _check_out_folder(agent.parent)
    card_path = agent.with_name("card.json") if agent.name == "agent.zip" else agent.with_suffix(".card.json")
    res = retrain_dqn(cfg, env_fn, agent, mission=mission, progress_bar=True, source="cli", card_path=card_path)
    assert res is not None  # None only for a run stopped through its stop event, which the CLI never sets
    card, final = res.card, res.card["final_stats"]
    summary = (f"{final['episodes']} episodes; last {final['last_episodes']}: mean reward "
               f"{final['mean_reward']:.2f}, EOD rate {final['eod_rate']:.0%}" if final["last_episodes"]
               else "no finished episode")
    print(f"wrote {agent} ({summary}; {card['timing']['wall_s']:.0f} s)")
    return EXIT_OK


_RUNS = {"dynaformer": _run_train_dynaformer, "dqn": _run_train_dqn, "attention": _run_train_attention}
COMMAND = Command("train a model (writes to a run folder, never over pretrained/)", _add_train_arguments, _run_train)
