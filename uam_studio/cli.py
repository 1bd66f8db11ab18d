"""Command-line interface: ``uam-studio <command> ...``.

Commands are registered in :data:`COMMANDS` (name -> :class:`Command`): each adds its
arguments to its own sub-parser and handles the parsed namespace, returning an exit
code. Bad input of any kind (an :class:`~uam_studio.errors.InputError`, or a value
argparse rejects) prints one line ``error: ...`` to stderr and exits with code 2.

Commands: ``serve`` (start the Panel app), ``simulate`` (fly a route of a mission file and report voltage and EOD), ``plan`` (plan
a mission with the DQN agent, the oracle or the greedy baseline; physics-checked), ``fly`` (fly it in
a world the operator cannot see, re-planning from its sensors), ``train``
(``dynaformer`` or ``dqn``; never into ``pretrained/``), ``evaluate`` (a model on held-out data, or ``real``: the models on
the CMU eVTOL dataset's real cells) and ``identify`` (a real cell's parameter set).
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import socket
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
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


# --------------------------------------------------------------------------- plan


def _add_plan_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", metavar="MISSION.json", help="mission file (see assets/example_mission.json)")
    p.add_argument("--policy", choices=["attention", "dqn", "oracle", "greedy"], default="attention",
                   help="attention (the bundled learned planner, default; 1-20 destinations), dqn (the paper's "
                        "agent; at most 8 destinations), oracle (knows the cell; exact up to 8 destinations, "
                        "an OR-Tools reference, not proven optimal, for 9-20) or greedy (baseline)")
    p.add_argument("--agent", default=None, metavar="FILE",
                   help="attention: a weights file (default: the bundled pretrained/attention_planner.pt); "
                        "dqn: an agent zip (default: the bundled pretrained/dqn_<scenario>.zip)")
    p.add_argument("--lookahead", type=int, default=0, metavar="K",
                   help="dqn: improve the agent by policy rollout over its K best safe actions and the "
                        "greedy rule's action per step, each continued by the agent and by the greedy rule "
                        "(0 = off, default; 6 is what benchmarks/RESULTS.md measures; costs up to "
                        "2(K + 1) extra episodes per step)")
    p.add_argument("--q-max", type=float, default=None, help="override the mission's q_max (C)")
    p.add_argument("--r0", type=float, default=None, help="override the mission's r0 (ohm)")
    p.add_argument("--json", action="store_true", help="print the plan as JSON")


_PLAN_FLAGS = {"agent_path": "--agent", "lookahead": "--lookahead", "policy": "--policy"}
"""``plan_mission``'s field names -> the ``plan`` command's flags, for its one-line errors."""


def _run_plan(args: argparse.Namespace) -> int:
    from uam_studio.planning import load_mission
    from uam_studio.planning.planner import plan_mission

    mission = load_mission(args.mission)  # a Mission holds 1-20 destinations: checked in the mission
    try:
        res = plan_mission(mission, args.policy, q_max=args.q_max, r0=args.r0, agent_path=args.agent,
                           lookahead=args.lookahead)
    except InputError as err:  # plan_mission's checks, in the words of the flags
        flag = _PLAN_FLAGS.get(err.field)
        if flag is None:
            raise
        raise _CliExit(f"{flag}{str(err)[len(err.field):]}", EXIT_INPUT) from None
    if args.json:
        json.dump(res.to_dict(), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
        return EXIT_OK
    battery = mission.with_battery(args.q_max, args.r0).battery
    print(f"{mission.name} ({mission.scenario}), policy {res.policy}: q_max {battery.q_max:g} C, "
          f"r0 {battery.r0:g} ohm, EOD {mission.eod_v:g} V")
    if res.route:
        legs = " -> ".join(f"{n} ({a:g} m)" for n, a in zip(res.route, res.altitudes_m))
        print(f"route: vertiport -> {legs}")
    else:
        print("route: none (nothing is flown)")
    reached = ", ".join(res.reached) or "none"
    print(f"reached: {reached} (priority {res.reached_priority})")
    print(f"charging cycles: {res.charging_cycles}")
    if not res.route:
        print("safe: yes (empty route)")
    elif res.safe:
        print(f"safe: yes, min {res.min_voltage_v:.3f} V")
    else:
        print(f"safe: NO, end of discharge at {res.physics['eod_s']:.0f} s (min {res.min_voltage_v:.3f} V)")
    if res.predicted is not None and res.predicted["voltage_v"]:
        print(f"Dynaformer: predicted min {min(res.predicted['voltage_v']):.3f} V")
    for m in res.messages:
        print(f"note: {m}")
    return EXIT_OK


# --------------------------------------------------------------------------- fly


def _add_fly_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", metavar="MISSION.json", help="mission file: its battery is the true cell, its "
                                                           "winds the forecast")
    p.add_argument("--policy", choices=["attention", "oracle"], default="attention",
                   help="the operator's planner, on what it believes: attention (the learned planner; default) "
                        "or oracle (exact search, slower)")
    p.add_argument("--seed", type=int, default=0, help="seeds the forecast errors and the sensor noise")
    p.add_argument("--forecast-sigma", type=float, default=13.0, metavar="KT",
                   help="std of the forecast error of each node's wind (kt, 0-60; default 13)")
    p.add_argument("--sensor-noise-mv", type=float, default=5.0, metavar="MV",
                   help="voltage sensor noise std (mV, 0-100; default 5)")
    p.add_argument("--sensor-noise-ma", type=float, default=20.0, metavar="MA",
                   help="current sensor noise std (mA, 0-1000; default 20)")
    p.add_argument("--event", action="append", default=[], metavar="wind+KT@S",
                   help="scripted wind change, e.g. wind+30@1200: 30 kt more headwind on legs taking off "
                        "from t = 1200 s (repeatable)")
    p.add_argument("--q-max", type=float, default=None, help="override the true cell's q_max (C)")
    p.add_argument("--r0", type=float, default=None, help="override the true cell's r0 (ohm)")
    p.add_argument("--json", action="store_true", help="print the flight record as JSON")
    p.add_argument("--series", action="store_true", help="with --json: include the 1 Hz time series")


def _run_fly(args: argparse.Namespace) -> int:
    from uam_studio.planning import load_mission
    from uam_studio.planning.operations import fly_mission, parse_event

    events = [parse_event(e) for e in args.event]
    mission = load_mission(args.mission).with_battery(args.q_max, args.r0)
    rec = fly_mission(mission, args.policy, seed=args.seed, forecast_sigma_kt=args.forecast_sigma,
                      sensor_noise_mv=args.sensor_noise_mv, sensor_noise_ma=args.sensor_noise_ma, events=events)
    if args.json:
        json.dump(rec.to_dict(series=args.series), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
        return EXIT_OK
    print(f"{mission.name} ({rec.scenario}): seed {rec.seed}, forecast sigma {rec.forecast_sigma_kt:g} kt, "
          f"sensor noise {rec.sensor_noise_mv:g} mV / {rec.sensor_noise_ma:g} mA, events: "
          f"{', '.join(rec.wind_events) or 'none'}")
    legs = iter(zip(rec.route, rec.altitudes_m, rec.actual_winds_kts, rec.forecast_winds_kts, rec.leg_end_s))
    for d in rec.events:
        print(f"t={d.time_s:>6.0f} s at {d.node}: {d.kind}: {d.reason}")
        print(f"           knows q_max {d.q_max_c:.0f} +- {d.q_max_sd_c:.0f} C, R0 {d.r0_ohm:.3f} +- "
              f"{d.r0_sd_ohm:.3f} ohm, wind shift {d.wind_shift_kts:+.1f} kt; plans "
              f"{' -> '.join(d.route) or 'nothing more'}")
        if d.next_to is not None:
            to, alt, wind, forecast, end = next(legs)
            print(f"           flies to {to} at {alt:g} m: wind {wind:+.0f} kt (forecast {forecast:+.0f}), "
                  f"lands at {end:.0f} s")
    reached = ", ".join(rec.reached) or "none"
    verdict = "BREACHED the cut-off: priority 0" if rec.breached else f"priority {rec.reached_priority}"
    print(f"flown: reached {reached}; {verdict}; {rec.charging_cycles} recharges; min {rec.min_voltage_v:.3f} V")
    print(f"blind pre-flight plan: {' -> '.join(rec.static_route) or 'nothing'}: "
          f"{'BREACHED, priority 0' if rec.static_breached else f'priority {rec.static_priority}'}")
    exact = "" if rec.hindsight_exact else (" at each leg's time; the best of the exact plans for each period of "
                                            "constant winds and the route flown")
    print(f"hindsight oracle (true cell, actual winds{exact}): priority {rec.hindsight_priority}")
    return EXIT_OK


# --------------------------------------------------------------------------- train

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
    p.add_argument("model", choices=["dynaformer", "dqn", "attention"], help="what to train")
    p.add_argument("--out", default=None,
                   help="run folder; default runs/dynaformer (dynaformer), runs/dqn_<scenario> (dqn: writes "
                        "agent.zip and card.json; a path ending in .zip names the agent file itself)")
    p.add_argument("--steps", type=int, default=None,
                   help="optimiser steps (dynaformer, default 60000) or env transitions (dqn, default 50000)")
    p.add_argument("--seed", type=int, default=0)
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
    g.add_argument("--cell", default=None, choices=["nasa18650", "vtc6"],
                   help="the cell type to train for: nasa18650 (the paper's, default) or vtc6 (the VTC6 identified "
                        "on the CMU eVTOL dataset, loads flown by power); see uam_studio/dynaformer/cells.py")
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
        raise _CliExit("--out: must not be the bundled pretrained/ folder (copy weights there by hand)", EXIT_INPUT)


def _check_out_folder(folder) -> None:
    """Create the run folder ``folder`` if needed and check a file can be written in it, before any work."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise _CliExit(f"--out: {folder} exists and is not a folder", EXIT_INPUT) from None
    except OSError as err:
        raise _CliExit(f"--out: cannot create the folder {folder} ({err.strerror or err})", EXIT_INPUT) from None
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        raise _CliExit(f"--out: cannot write in {folder} ({err.strerror or err})", EXIT_INPUT) from None


def _reject_options(args: argparse.Namespace) -> None:
    for name, models in _OPTION_MODELS.items():
        if getattr(args, name) is not None and args.model not in models:
            flag = "--" + name.replace("_", "-")
            raise _CliExit(f"{flag}: not an option of 'train {args.model}' (only of 'train {' / '.join(models)}')",
                           EXIT_INPUT)


def _run_train(args: argparse.Namespace) -> int:
    _reject_options(args)
    if args.model == "dqn":
        return _run_train_dqn(args)
    if args.model == "attention":
        return _run_train_attention(args)
    return _run_train_dynaformer(args)


def _run_train_attention(args: argparse.Namespace) -> int:
    from .dynaformer.train import pick_device
    from .planning.agents.attention.train import AttentionTrainConfig, train_attention

    out = Path(args.out or "runs/attention")
    _refuse_bundled(out)
    cfg = AttentionTrainConfig(seed=args.seed)
    cfg.device = str(pick_device(args.device or "auto"))
    for name, lo in (("oracle_missions", 10), ("search_missions", 0), ("epochs", 1)):
        value = getattr(args, name)
        if value is not None:
            if value < lo:
                raise _CliExit(f"--{name.replace('_', '-')}: must be >= {lo}", EXIT_INPUT)
            setattr(cfg, name, value)
    _check_out_folder(out)
    weights = train_attention(cfg, out)
    print(f"wrote {weights}")
    return EXIT_OK


def _run_train_dynaformer(args: argparse.Namespace) -> int:
    from .dynaformer.model import DynaformerConfig
    from .dynaformer.train import TrainConfig, pick_device, read_init, train

    out = args.out or "runs/dynaformer"
    _refuse_bundled(out)
    cfg = TrainConfig(seed=args.seed, device=args.device or "auto", cell=args.cell or "nasa18650",
                      init=args.init_from)
    pick_device(cfg.device)
    if cfg.init is not None:  # a weights file that does not load is refused before the run folder is made
        read_init(cfg.init, DynaformerConfig.for_cell(cfg.cell))
    if args.steps is not None:
        if args.steps < 1:
            raise _CliExit("--steps: must be >= 1", EXIT_INPUT)
        cfg.steps = args.steps
    if args.n_train is not None:
        if args.n_train < 64:
            raise _CliExit("--n-train: must be >= 64", EXIT_INPUT)
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
        raise _CliExit(f"--scenario: {args.scenario!r} is not a scenario; allowed: {', '.join(SCENARIOS)}",
                       EXIT_INPUT)
    mission = load_mission(args.mission) if args.mission is not None else None
    scenario = args.scenario or (mission.scenario if mission is not None else DEFAULT_SCENARIO)
    out = Path(args.out or f"runs/dqn_{scenario}")
    agent = out if out.suffix == ".zip" else out / "agent.zip"
    _refuse_bundled(agent)
    if agent.exists() and not agent.is_file():
        raise _CliExit(f"--out: {agent} exists and is not a file", EXIT_INPUT)
    if args.steps is not None and args.steps < 1:
        raise _CliExit("--steps: must be >= 1", EXIT_INPUT)
    _check_out_folder(agent.parent)
    # Shared with the app's Retrain tab: validation, env, card and atomic save live in the library.
    cfg, env_fn = training_setup(scenario, mission, args.alpha, args.beta, args.gamma, args.steps, args.seed,
                                 safe_return=bool(args.safe_return), init_agent=args.init_from)
    card_path = agent.with_name("card.json") if agent.name == "agent.zip" else agent.with_suffix(".card.json")
    res = retrain_dqn(cfg, env_fn, agent, mission=mission, progress_bar=True, source="cli", card_path=card_path)
    card, final = res.card, res.card["final_stats"]
    summary = (f"{final['episodes']} episodes; last {final['last_episodes']}: mean reward "
               f"{final['mean_reward']:.2f}, EOD rate {final['eod_rate']:.0%}" if final["last_episodes"]
               else "no finished episode")
    print(f"wrote {agent} ({summary}; {card['timing']['wall_s']:.0f} s)")
    return EXIT_OK


def _add_evaluate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", choices=["dynaformer", "real"],
                   help="dynaformer: held-out synthetic data; real: the battery, health and safety models on the "
                        "CMU eVTOL dataset's real VTC6 cells (needs --data)")
    p.add_argument("--data", default=None, metavar="PATH",
                   help="real: the CMU eVTOL dataset's folder (default: $UAM_STUDIO_CMU_DATA; DOI 10.1184/R1/14226830)")
    p.add_argument("--quick", action="store_true",
                   help="real: skip the two held-out refits of the VTC6 set (about a minute each)")
    p.add_argument("--weights", default=None, help="weights file (default: the bundled model)")
    p.add_argument("--table", choices=["default", "noise"], default="default",
                   help="default: the held-out sets, beside the physics fit; noise: EOD timing over sensor noise "
                        "(0, 1, 5, 10 mV) x context (20, 60, 120, 600 s) x log start (aligned, at rest), beside the "
                        "physics fit and the take-off estimator, with 90%% interval coverage and latency")
    p.add_argument("--n", type=int, default=None,
                   help="missions per held-out set (default 400; --table noise: 200 flights)")
    p.add_argument("--compare", default=None, metavar="WEIGHTS",
                   help="--table noise: one more column, another weights file with its own health estimator "
                        "(e.g. a transformer-encoder model)")
    p.add_argument("--seed", type=int, default=12345)
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")


def _run_evaluate(args: argparse.Namespace) -> int:
    from .dynaformer.evaluate import evaluate, format_noise_table, format_report, noise_table
    from .dynaformer.predictor import load_predictor

    if args.model == "real":
        from .studies.real_cells import format_report as format_real
        from .studies.real_cells import real_cell_report

        report = real_cell_report(args.data, refit=not args.quick)
        print(json.dumps(report.as_dict(), indent=2) if args.json else format_real(report))
        return EXIT_OK
    if args.data is not None or args.quick:
        raise _CliExit("--data, --quick: only with 'evaluate real'", EXIT_INPUT)
    n = args.n if args.n is not None else (200 if args.table == "noise" else 400)
    if n < 10:
        raise _CliExit("--n: must be >= 10", EXIT_INPUT)
    if args.compare is not None and args.table != "noise":
        raise _CliExit("--compare: only with --table noise", EXIT_INPUT)
    pred = load_predictor(args.weights)
    if args.table == "noise":
        other = load_predictor(args.compare) if args.compare is not None else None
        compare = {other.model.cfg.health if other.model.cfg.health != "takeoff" else "other": other} if other else None
        metrics = noise_table(pred, n=n, seed=args.seed, compare=compare)
        print(json.dumps(metrics, indent=2) if args.json else format_noise_table(metrics))
        return EXIT_OK
    metrics = evaluate(pred, n=n, seed=args.seed)
    print(json.dumps(metrics, indent=2) if args.json else format_report(metrics))
    return EXIT_OK


# --------------------------------------------------------------------------- identify


def _add_identify_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("cell", choices=["vtc6"], help="the cell to identify (the CMU eVTOL dataset's Sony-Murata VTC6)")
    p.add_argument("--data", default=None, metavar="PATH",
                   help="the CMU eVTOL dataset's folder (default: $UAM_STUDIO_CMU_DATA; DOI 10.1184/R1/14226830)")
    p.add_argument("--hold-out", choices=["none", "landing", "cell"], default="none",
                   help="none: the bundled set; landing: without VAH01's landing and rest; cell: without VAH01")


def _run_identify(args: argparse.Namespace) -> int:
    from .battery.cmu_data import data_folder
    from .battery.real_cells import cell_literal, identify_vtc6

    print(cell_literal(identify_vtc6(data_folder(args.data), hold_out=args.hold_out)))
    return EXIT_OK


# --------------------------------------------------------------------------- serve


def _add_serve_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=int, default=5006, help="port to listen on (default 5006)")
    p.add_argument("--address", default=None,
                   help="address to listen on (default 127.0.0.1: this machine only); e.g. 0.0.0.0 for "
                        "all interfaces, which lets anyone who can reach the port use the app, with no login")
    p.add_argument("--allow-origin", action="append", default=[], metavar="HOST[:PORT]",
                   help="also answer requests addressed to HOST[:PORT] (the name or IP other machines use "
                        "to reach this one; PORT defaults to --port); repeatable. Other names get 403")
    p.add_argument("--show", action=argparse.BooleanOptionalAction, default=True,
                   help="open the app in a browser (default: yes)")


def _run_serve(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        raise _CliExit(f"--port: {args.port} is out of range; allowed [0, 65535]", EXIT_INPUT)
    try:
        from uam_studio.app.serve import DEFAULT_ADDRESS, serve, split_host
    except ImportError as err:
        raise _CliExit(f"serve: the app needs panel and holoviews ({err})", EXIT_INPUT) from None
    for value in args.allow_origin:
        try:
            split_host(value)
        except ValueError as err:
            raise _CliExit(f"--allow-origin: {err}", EXIT_INPUT) from None
    address = args.address or DEFAULT_ADDRESS
    if address in ("0.0.0.0", "::") and not args.allow_origin:
        print(f"note: --address {address}: other machines get 403 unless the name or IP they use for this "
              "one is allowed with --allow-origin HOST[:PORT]", file=sys.stderr)
    try:
        serve(port=args.port, show=args.show, address=address, allow_origin=args.allow_origin)
    except OSError as err:
        if isinstance(err, socket.gaierror) or err.errno in (errno.EADDRNOTAVAIL, errno.EAFNOSUPPORT):
            raise _CliExit(f"--address: cannot listen on {address} ({err.strerror or err})", EXIT_INPUT) from None
        raise _CliExit(f"--port: cannot listen on {address}:{args.port} ({err.strerror or err})",
                       EXIT_INPUT) from None
    return EXIT_OK


COMMANDS: dict[str, Command] = {
    "simulate": Command(
        "fly a route of a mission and report voltage and end of discharge",
        _add_simulate_arguments,
        _run_simulate,
    ),
    "plan": Command(
        "plan a mission with a policy (attention, dqn, oracle, greedy), checked with the physics model",
        _add_plan_arguments,
        _run_plan,
    ),
    "fly": Command(
        "fly a mission in a hidden world: the operator estimates health and wind from its sensors and "
        "re-plans at every arrival",
        _add_fly_arguments,
        _run_fly,
    ),
    "train": Command("train a model (writes to a run folder, never over pretrained/)", _add_train_arguments, _run_train),
    "evaluate": Command("evaluate a model on held-out synthetic data, or the models on real cells",
                        _add_evaluate_arguments, _run_evaluate),
    "identify": Command("identify a real cell's parameter set from measured data (prints it as Python)",
                        _add_identify_arguments, _run_identify),
    "serve": Command("start the app in a browser: Planner, Fly, Battery lab, Retrain and Glossary tabs",
                     _add_serve_arguments,
                     _run_serve),
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
