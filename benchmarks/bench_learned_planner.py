"""The learned planner against the exact oracle (6-8 destinations), greedy and the routing solver's
reference (18-20 destinations), on held-out missions scored under physics (issue #19).

    python benchmarks/bench_learned_planner.py --n 40 --n-large 20          # the tables
    python benchmarks/bench_learned_planner.py --n 40 --n-large 20 --progpy # + re-fly on progpy
    python benchmarks/bench_learned_planner.py --n 0 --n-large 40 --latency-only  # latency alone

Held-out: ``held_out_missions(n, SEED_SMALL / SEED_LARGE, ...)``, health in the default box, radii
8-45 km; training used ``random_mission`` with seeds ``[0, k]`` and ``[0, 1, k]`` (8-60 km).
Every plan is flown on the physics model (:func:`uam_studio.planning.check_plan`); an unsafe plan
scores 0 (no priority, no destinations). Rows:

- ``default``: ``plan_mission(m, "attention")``, the default planner (network + search + filter);
- ``no search``: the network's best safe move each step (beam 1, filter on);
- ``raw``: the network alone (beam 1, no filter: nothing flown while planning);
- ``dqn``: the paper's DQN as ``plan_mission(m, "dqn")`` plans (its safety filter; 8 destinations at most);
- ``greedy``; ``oracle`` (exact up to 8; the OR-Tools reference beyond, ``exact: false``).

Latency: ``plan_mission`` in-process, p95 over the large missions, without the Dynaformer's
voltage prediction (``predictor=False``: planning and the physics check) and with it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from uam_studio.planning import check_plan, held_out_missions, plan_mission  # noqa: E402
from uam_studio.planning.agents.attention.decode import attention_plan, load_policy_cached  # noqa: E402
from uam_studio.planning.missions.mission import VERTIPORT  # noqa: E402

SEED_SMALL = 2611
SEED_LARGE = 2612
SCENARIOS = ("single_charge", "multi_charge")


def score(m, route, alts) -> tuple[int, int, int, bool]:
    """(priority, destinations, charging cycles, safe) of a route flown on the physics model."""
    c = check_plan(m, route, alts)
    if not c.safe:
        return 0, 0, 0, False
    if c.sim is None:
        return 0, 0, 0, True
    prio = {d.name: d.priority for d in m.destinations}
    return sum(prio[n] for n in c.sim.reached), len(c.sim.reached), c.sim.charging_cycles, True


def run(missions, rows) -> dict[str, dict[str, list]]:
    out = {k: {"score": [], "time": [], "plan": []} for k in rows}
    for m in missions:
        for k, fn in rows.items():
            t = time.perf_counter()
            route, alts = fn(m)
            out[k]["time"].append(time.perf_counter() - t)
            out[k]["score"].append(score(m, route, alts))
            out[k]["plan"].append((route, alts))
    return out


def _pm(policy):
    def fn(m):
        r = plan_mission(m, policy, predictor=False)
        return r.route, r.altitudes_m
    return fn


def _att(beam, filt):
    net = load_policy_cached()

    def fn(m):
        p = attention_plan(m, net, beam_width=beam, safety_filter=filt)
        return list(p.route), list(p.altitudes_m)
    return fn


def table(res, scenario: str, base: str) -> None:
    b = np.array(res[base]["score"], dtype=float)
    for k, r in res.items():
        s = np.array(r["score"], dtype=float)
        unsafe = int((s[:, 3] == 0).sum())
        p95 = np.percentile(r["time"], 95) * 1e3
        if scenario == "single_charge":
            pos = b[:, 0] > 0
            gap = np.mean(1 - s[pos, 0] / b[pos, 0])
            print(f"  {k:10s} priority {int(s[:, 0].sum()):4d}  ({s[:, 0].sum() / b[:, 0].sum():7.2%} of {base}; "
                  f"mean gap {gap:6.2%})  unsafe {unsafe:2d}  p95 {p95:6.0f} ms")
        else:
            same = np.mean((s[:, 1] == b[:, 1]) & (s[:, 2] == b[:, 2]))
            more = int((s[:, 2] > b[:, 2]).sum())
            fewer = int((s[:, 2] < b[:, 2]).sum())
            print(f"  {k:10s} destinations {int(s[:, 1].sum()):4d} cycles {int(s[:, 2].sum()):4d}  "
                  f"{base}'s cycles and destinations {same:6.1%}  more cycles {more:2d} fewer {fewer:2d}  "
                  f"unsafe {unsafe:2d}  p95 {p95:6.0f} ms")


def progpy_breaches(missions, plans) -> tuple[int, int]:
    """Re-fly each plan's sorties on NASA progpy's BatteryElectroChemEOD: (sorties flown, sorties that
    reach EOD)."""
    from progpy.models import BatteryElectroChemEOD

    flown = breached = 0
    for m, (route, alts) in zip(missions, plans):
        c = check_plan(m, route, alts)
        if c.sim is None or not c.safe:
            continue
        sim = c.sim
        cuts = [0] + [int(round(leg.end_s / sim.dt_s)) for leg in sim.legs if leg.to == VERTIPORT]
        for a, b in zip(cuts[:-1], cuts[1:]):
            cur = sim.current_a[a:b]
            model = BatteryElectroChemEOD(qMobile=m.battery.q_max, Ro=m.battery.r0)

            def load(t, x=None, cur=cur, model=model):
                return model.InputContainer({"i": float(cur[min(int(t), cur.size - 1)])})

            res = model.simulate_to_threshold(load, dt=1.0, save_freq=1.0, horizon=float(cur.size))
            flown += 1
            breached += bool(model.threshold_met(res.states[-1])["EOD"])
    return flown, breached


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=40, help="missions of 6-8 destinations per scenario")
    ap.add_argument("--n-large", type=int, default=20, help="missions of 18-20 destinations per scenario")
    ap.add_argument("--progpy", action="store_true", help="re-fly the default plans on progpy")
    ap.add_argument("--latency-only", action="store_true",
                    help="only the plan_mission latency on the 18-20 destination missions (use with --n 0)")
    args = ap.parse_args()
    small_rows = {"default": _pm("attention"), "no search": _att(1, True), "raw": _att(1, False),
                  "dqn": _pm("dqn"), "greedy": _pm("greedy"), "oracle": _pm("oracle")}
    large_rows = {"default": _pm("attention"), "no search": _att(1, True), "raw": _att(1, False),
                  "greedy": _pm("greedy"), "reference": _pm("oracle")}
    refly = []
    for scenario in SCENARIOS:
        if args.n > 0:
            ms = held_out_missions(args.n, SEED_SMALL, n_dest=(6, 8), scenario=scenario)
            res = run(ms, small_rows)
            print(f"\n{scenario}, {args.n} held-out missions of 6-8 destinations (seed {SEED_SMALL}), "
                  "against the exact oracle")
            table(res, scenario, "oracle")
            refly.append((ms, res["default"]["plan"]))
        ml = held_out_missions(args.n_large, SEED_LARGE, n_dest=(18, 20), scenario=scenario)
        if not args.latency_only:
            res = run(ml, large_rows)
            print(f"\n{scenario}, {args.n_large} held-out missions of 18-20 destinations (seed {SEED_LARGE}), "
                  "against greedy and against the reference")
            table(res, scenario, "greedy")
            table({"default": res["default"], "reference": res["reference"]}, scenario, "reference")
            refly.append((ml, res["default"]["plan"]))
        lat, lat_pred = [], []
        for m in ml:
            t = time.perf_counter()
            plan_mission(m, "attention", predictor=False)
            lat.append(time.perf_counter() - t)
        for m in ml[: max(1, len(ml) // 4)]:
            t = time.perf_counter()
            plan_mission(m, "attention")
            lat_pred.append(time.perf_counter() - t)
        print(f"  plan_mission latency, 18-20 destinations: p95 {np.percentile(lat, 95) * 1e3:.0f} ms, "
              f"median {np.median(lat) * 1e3:.0f} ms (planning + physics check); with the Dynaformer's "
              f"prediction: median {np.median(lat_pred) * 1e3:.0f} ms over {len(lat_pred)}")
    if args.progpy:
        flown = breached = 0
        for ms, plans in refly:
            f, b = progpy_breaches(ms, plans)
            flown += f
            breached += b
        print(f"\nprogpy re-fly of the default plans: {flown} sorties, {breached} reach the cut-off")


if __name__ == "__main__":
    main()
