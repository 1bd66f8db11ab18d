"""Planning benchmarks (issue #4): env throughput, DQN/greedy vs the exact oracle, per-mission retraining.

    python benchmarks/bench_planning.py throughput            # env steps/s: physics, dynaformer, naive loop
    python benchmarks/bench_planning.py gap --n 200           # bundled DQN and greedy vs oracle, 200 missions
    python benchmarks/bench_planning.py retrain --budget 180  # per-mission training on 8-destination maps
    python benchmarks/bench_planning.py retrain --init-from pretrained/dqn_single_charge.zip  # fine-tuned
    python benchmarks/bench_planning.py findings              # the paper's qualitative findings

Every part measures its reference in the same run: the naive loop for throughput (the same env with
a per-sample explicit-Euler battery written as a plain Python loop), the exact oracle for plan quality.
Results go to stdout and, with ``--json FILE``, to a JSON file.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from uam_studio.battery import DEFAULT_CELL, STATE_NAMES, BatteryState, full_charge  # noqa: E402
from uam_studio.battery.solver import output_voltage, step  # noqa: E402
from uam_studio.planning import held_out_missions  # noqa: E402
from uam_studio.planning.env import BatteryBackend, LegOutcome, UAMPlanningEnv  # noqa: E402


class NaiveEulerBattery(BatteryBackend):
    """Reference: the same model stepped one sample at a time in Python (no time vectorisation)."""

    name = "naive"

    def reset(self, cell, context_current_a=None, context_voltage_v=None) -> None:
        self.q_max, self.eod_v = float(cell.q_max), float(cell.eod_v)
        self.q_total = np.array([DEFAULT_CELL.q_total(self.q_max)])
        self.r0 = np.array([float(cell.r0)])
        self.recharge()

    def recharge(self) -> None:
        self.state = full_charge(self.q_max)

    def fly_leg(self, current_a: np.ndarray) -> LegOutcome:
        x = self.state
        out = []
        for i in np.asarray(current_a, dtype=float):
            x = step(x, np.array([i]), self.q_total, self.r0, 1.0, DEFAULT_CELL)
            v = float(output_voltage({n: getattr(x, n) for n in STATE_NAMES}, self.q_total, DEFAULT_CELL)[0])
            out.append(v)
            if not v >= self.eod_v:
                return LegOutcome(np.array(out), True, min(out), v)
        self.state = BatteryState(**{n: getattr(x, n).copy() for n in STATE_NAMES})
        return LegOutcome(np.array(out), False, min(out), out[-1])


def _steps_per_s(env: UAMPlanningEnv, seconds: float, seed: int = 0) -> tuple[float, int]:
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    n = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        valid = np.flatnonzero(env.action_masks())
        _, _, term, trunc, _ = env.step(int(rng.choice(valid)))
        n += 1
        if term or trunc:
            env.reset()
    return n / (time.perf_counter() - t0), n


def _vec_steps_per_s(n_workers: int, seconds: float, seed: int = 0, envs_per_worker: int = 1,
                     dynaformer: bool = False) -> float:
    """Env transitions per second of ``n_workers`` processes of physics (or Dynaformer) envs.

    ``envs_per_worker=1``: SB3's ``SubprocVecEnv`` (one env per process, one pipe round trip per
    env step). More: :class:`~uam_studio.planning.agents.vec_env.GroupedSubprocVecEnv` (a group of envs per
    process, one round trip per group step). Random masked actions; each env's mask is read from
    its observation (the last ``N_ACTIONS`` entries). Finished episodes reset inside the workers.
    The clock starts after the workers have started and reset.
    """
    from stable_baselines3.common.vec_env import SubprocVecEnv

    from uam_studio.planning.agents.vec_env import GroupedSubprocVecEnv
    from uam_studio.planning.env import N_FEATURES, make_env

    if dynaformer:
        from uam_studio.dynaformer import load_pretrained

        kind = {"backend": "dynaformer", "predictor": load_pretrained()}
    else:
        kind = {"backend": "physics"}
    fns = [make_env(**kind) for _ in range(n_workers * envs_per_worker)]
    vec = SubprocVecEnv(fns) if envs_per_worker == 1 else GroupedSubprocVecEnv(fns, n_workers=n_workers)
    try:
        vec.seed(seed)
        obs = vec.reset()
        rng = np.random.default_rng(seed)
        n = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            actions = [int(rng.choice(np.flatnonzero(o[N_FEATURES:] > 0.5))) for o in obs]
            obs, _, _, _ = vec.step(np.array(actions))
            n += len(fns)
        return n / (time.perf_counter() - t0)
    finally:
        vec.close()


def throughput(seconds: float, workers: int = 2, repeats: int = 3, group: int = 32) -> dict:
    """Steps/s of each backend. The physics backend, the goal's subject, is measured ``repeats``
    times (fresh env, seeds 0, 1, ...) and reported as the median: on this kind of machine one run
    swings by about +/-8% from run to run. So is the physics backend on both cores: ``workers``
    processes of ``group`` envs each (:class:`~uam_studio.planning.agents.vec_env.GroupedSubprocVecEnv`)."""
    from uam_studio.dynaformer import load_pretrained

    res = {}
    runs = [_steps_per_s(UAMPlanningEnv(backend="physics"), seconds, seed=k)[0] for k in range(repeats)]
    res["physics_runs"] = runs
    res["physics"] = float(np.median(runs))
    res["physics_subproc"] = _vec_steps_per_s(workers, seconds)
    res["subproc_workers"] = workers
    grouped = [_vec_steps_per_s(workers, seconds, seed=k, envs_per_worker=group) for k in range(repeats)]
    res["physics_grouped_runs"] = grouped
    res["physics_grouped"] = float(np.median(grouped))
    res["group"] = group
    res["dynaformer"], _ = _steps_per_s(UAMPlanningEnv(backend="dynaformer", predictor=load_pretrained()), seconds)
    res["dynaformer_grouped"] = _vec_steps_per_s(workers, seconds, envs_per_worker=group, dynaformer=True)
    res["naive_loop"], _ = _steps_per_s(UAMPlanningEnv(backend=NaiveEulerBattery()), seconds)
    print(f"env steps/s (random masked actions, random 1-8 destination missions, {seconds:.0f} s each):")
    print(f"  physics backend     {res['physics']:8.0f}   (one env, one process; median of "
          f"{', '.join(f'{r:.0f}' for r in runs)}; goal >= 1000)")
    print(f"  physics, SubprocVecEnv x{workers} {res['physics_subproc']:8.0f}   "
          f"({res['physics_subproc'] / res['physics']:.2f}x one env; SB3, one env per process)")
    print(f"  physics, grouped {workers}x{group}   {res['physics_grouped']:8.0f}   "
          f"({workers} processes of {group} envs, both cores; median of "
          f"{', '.join(f'{r:.0f}' for r in grouped)}; "
          f"{res['physics_grouped'] / res['physics']:.2f}x one env; goal >= 1000)")
    print(f"  dynaformer backend  {res['dynaformer']:8.0f}   (one env, one process; goal >= 200)")
    print(f"  dynaformer, grouped {workers}x{group} {res['dynaformer_grouped']:6.0f}   "
          f"({workers} processes of {group} envs, one torch thread each; goal >= 200)")
    print(f"  naive Euler loop    {res['naive_loop']:8.1f}   "
          f"-> physics is {res['physics'] / res['naive_loop']:.0f}x faster")
    return res


def gap(n: int, seed: int, agents: dict[str, str | None]) -> dict:
    from tqdm import tqdm

    from uam_studio.studies.compare import compare_planners, summarize

    out = {}
    for scenario, agent in agents.items():
        missions = held_out_missions(n, seed, scenario=scenario)
        policies = ("oracle", "greedy") + (("dqn", "dqn_raw", "dqn_rollout", "dqn_rollout_agent") if agent else ())
        t0 = time.perf_counter()
        with tqdm(total=n, desc=scenario, file=sys.stderr) as bar:
            scores = compare_planners(missions, agent, policies, progress=lambda k: bar.update(1))
        s = summarize(scores)
        out[scenario] = {"summary": s, "wall_s": time.perf_counter() - t0, "agent": agent,
                         "scores": [x.to_dict() for x in scores]}
        print(f"\n{scenario}: {n} held-out missions (seed {seed}, 6-8 destinations), agent {agent}")
        print(f"  {'policy':17s} mean prio  mean gap  p90 gap  worst  same cycles  mean cycles  EOD breach  "
              "median plan")
        for p, r in s.items():
            print(f"  {p:17s} {r['mean_priority']:9.2f} {100 * r['mean_gap']:8.1f}% {100 * r['p90_gap']:7.1f}% "
                  f"{100 * r['worst_gap']:5.0f}% {100 * r['same_cycles']:10.1f}% {r['mean_cycles']:11.2f} "
                  f"{100 * r['eod_breach_rate']:10.1f}% {1000 * r['median_plan_s']:9.1f} ms")
    return out


def retrain(n_maps: int, budget_s: float, seed: int, init_agent: str | None = None) -> dict:
    """Per-mission training (the paper's per-map setting) against the oracle on 8-destination maps.

    ``init_agent``: fine-tune that agent (warm start, ``FINE_TUNE`` exploration) instead of training
    from random weights. Scores: the agent alone (raw, the paper's setting), with the safety filter,
    and with policy rollout (planning time, not training time).
    """
    from uam_studio.planning.agents.dqn.rollout import rollout_agent
    from uam_studio.planning.agents.dqn.training import DQNTrainConfig, fine_tuning, train_dqn
    from uam_studio.planning.env import make_env
    from uam_studio.planning.missions.check import check_plan
    from uam_studio.planning.solvers.oracle import oracle_plan
    from uam_studio.studies.compare import ROLLOUT_K

    rows = []
    for k, m in enumerate(held_out_missions(n_maps, seed, n_dest=(8, 8))):
        ref = oracle_plan(m)
        stop = threading.Event()
        timer = threading.Timer(budget_s, stop.set)
        cfg = DQNTrainConfig(scenario="single_charge", steps=10**7, seed=k, learning_starts=500,
                             exploration_fraction=0.05, buffer_size=100_000)
        if init_agent:
            cfg = fine_tuning(cfg, init_agent)
        t0 = time.perf_counter()
        timer.start()
        model = train_dqn(cfg, make_env(mission=m, scenario="single_charge"), stop_event=stop)
        wall = time.perf_counter() - t0
        timer.cancel()
        row = {"mission": m.name, "oracle": ref.reached_priority, "train_s": wall,
               "timesteps": int(model.num_timesteps), "init_agent": init_agent}
        variants = (("raw", {"shield": False}), ("shield", {"shield": True}),
                    ("rollout", {"shield": True, "lookahead": ROLLOUT_K}))
        for name, kw in variants:  # raw: the agent alone (the paper's setting)
            plan = rollout_agent(m, model, **kw)
            check = check_plan(m, plan.route, plan.altitudes_m)
            prio = plan.reached_priority if check.safe else 0
            row[name] = prio
            row[f"{name}_safe"] = bool(check.safe)
            row[f"{name}_gap"] = (ref.reached_priority - prio) / ref.reached_priority if ref.reached_priority else 0.0
        row["gap"] = row["raw_gap"]
        rows.append(row)
        print(f"  {m.name}: oracle {ref.reached_priority}, DQN {row['raw']} (safe {row['raw_safe']}, gap "
              f"{100 * row['raw_gap']:.1f}%), with the safety filter {row['shield']} (gap "
              f"{100 * row['shield_gap']:.1f}%), with rollout {row['rollout']} (gap {100 * row['rollout_gap']:.1f}%); "
              f"{wall:.0f} s, {model.num_timesteps} steps")
    start = f"fine-tuned from {init_agent}" if init_agent else "from random weights"
    for name in ("raw", "shield", "rollout"):
        gaps = [r[f"{name}_gap"] for r in rows]
        print(f"per-mission training ({start}), {budget_s:.0f} s budget, {name}: mean gap "
              f"{100 * np.mean(gaps):.1f}%, within 5% on {sum(g <= 0.05 for g in gaps)}/{len(rows)} maps")
    return {"rows": rows}


def findings(quick: bool) -> dict:
    """The paper's four findings (``uam-studio findings``): the same library function and text."""
    from uam_studio.studies.findings import format_findings, paper_findings

    out = paper_findings(quick=quick)
    print(format_findings(out))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", choices=["throughput", "gap", "retrain", "findings"])
    ap.add_argument("--seconds", type=float, default=10.0, help="throughput: seconds per backend")
    ap.add_argument("--n", type=int, default=200, help="gap: missions per scenario; retrain: maps")
    ap.add_argument("--seed", type=int, default=20261121, help="held-out mission seed (never used in training)")
    ap.add_argument("--scenarios", default="single_charge,multi_charge")
    ap.add_argument("--agent-dir", default="pretrained", help="gap: folder with dqn_<scenario>.zip")
    ap.add_argument("--budget", type=float, default=180.0, help="retrain: training seconds per map")
    ap.add_argument("--init-from", default=None, help="retrain: fine-tune this agent zip (warm start)")
    ap.add_argument("--workers", type=int, default=2, help="throughput: worker processes of the vector envs")
    ap.add_argument("--group", type=int, default=32, help="throughput: envs per process of the grouped vector env")
    ap.add_argument("--repeats", type=int, default=3, help="throughput: physics runs (median reported)")
    ap.add_argument("--quick", action="store_true", help="findings: fewer steps and missions")
    ap.add_argument("--json", help="write the results here")
    a = ap.parse_args()
    if a.part == "throughput":
        res = throughput(a.seconds, a.workers, a.repeats, a.group)
    elif a.part == "gap":
        agents = {}
        for s in a.scenarios.split(","):
            p = Path(a.agent_dir) / f"dqn_{s}.zip"
            agents[s] = str(p) if p.is_file() else None
            if agents[s] is None:
                print(f"note: no agent {p}; oracle and greedy only")
        res = gap(a.n, a.seed, agents)
    elif a.part == "retrain":
        res = retrain(a.n, a.budget, a.seed, a.init_from)
    else:
        res = findings(a.quick)
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(res, indent=1, default=float))


if __name__ == "__main__":
    main()
