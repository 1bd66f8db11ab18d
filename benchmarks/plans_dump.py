"""Dump the routes and altitudes the planners give on the gap benchmark's held-out missions, to check
that a refactor leaves plans unchanged: run it on two checkouts and compare the JSON files.

    python benchmarks/plans_dump.py OUT.json [N] [N_ORACLE]     # defaults 200 and 20

Works on this layout (``uam_studio.planning.planner``) and on the flat one before it (``policy``).
"""
import json
import sys

try:
    from uam_studio.planning.planner import plan_mission
except ImportError:
    from uam_studio.planning.policy import plan_mission
from uam_studio.planning import held_out_missions

out = {}
n = int(sys.argv[2]) if len(sys.argv) > 2 else 200
n_oracle = int(sys.argv[3]) if len(sys.argv) > 3 else 20
for scenario in ("single_flight", "single_charge", "multi_charge"):
    ms = held_out_missions(n, 20261121, scenario=scenario)
    for pol in ("attention", "dqn", "greedy"):
        try:
            plan_mission(ms[0], pol, predictor=False)
        except Exception:  # a checkout without this policy
            continue
        out[f"{scenario}/{pol}"] = [(r["route"], r["altitudes_m"]) for r in
                                    (plan_mission(m, pol, predictor=False) for m in ms)]
    out[f"{scenario}/oracle"] = [(r["route"], r["altitudes_m"]) for r in
                                 (plan_mission(m, "oracle", predictor=False) for m in ms[:n_oracle])]
# single flight: every planner's one leg (the oracle's and the reference solver's: the safest level)
ms = held_out_missions(n_oracle, 20261121, scenario="single_flight")
for pol in ("attention", "greedy", "oracle", "reference"):
    try:
        if pol == "reference":
            from uam_studio.planning.solvers.reference import reference_plan

            plans = [reference_plan(m) for m in ms]
            out[f"single_flight/{pol}"] = [(list(p.route), list(p.altitudes_m), p.messages) for p in plans]
        else:
            out[f"single_flight/{pol}"] = [(r["route"], r["altitudes_m"], r["messages"]) for r in
                                           (plan_mission(m, pol, predictor=False).to_dict() for m in ms)]
    except Exception:  # a checkout without this policy or scenario
        continue
json.dump(out, open(sys.argv[1], "w"))
print({k: len(v) for k, v in out.items()})
