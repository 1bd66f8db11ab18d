"""Dump the operator's seeded flights (route, altitudes, every decision without its timing), to check
that a refactor leaves the flights unchanged: run it on two checkouts and compare the JSON files.

    python benchmarks/flights_dump.py OUT.json [N] [WORLD]    # N missions per scenario (default 6); WORLD: varied
                                                              # (the default world) or model

A checkout older than the world's choice flies only the model world: compare it with WORLD model.
"""
import dataclasses
import json
import sys

from uam_studio.studies.flying import fly_many, study_missions

n = int(sys.argv[2]) if len(sys.argv) > 2 else 6
world = {"world": sys.argv[3]} if len(sys.argv) > 3 else {}
out = {}
for scenario, seed in (("single_charge", 31337), ("multi_charge", 31338)):
    recs = fly_many(study_missions(n, seed, scenario), first_seed=7000, **world)
    out[scenario] = [{"route": list(r.route), "altitudes_m": list(r.altitudes_m), "breached": r.breached,
                      "reached_priority": r.reached_priority,
                      "events": [dataclasses.asdict(dataclasses.replace(e, compute_s=0.0)) for e in r.events]}
                     for r in recs]
json.dump(out, open(sys.argv[1], "w"), default=str)
print({k: len(v) for k, v in out.items()})
