"""``uam-studio fleet``: a fleet's day or life (SimPy, packs aging in a hidden world), health-aware,
health-blind and hindsight dispatchers side by side on the same demand and the same packs."""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path

from uam_studio.cli.common import EXIT_OK, Command, add_engine_arguments, add_world_arguments, check_workers, seed_arg
from uam_studio.risk import DEFAULT_RISK


def _add_fleet_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--aircraft", type=int, default=6, help="aircraft in the fleet (1-50; default 6)")
    p.add_argument("--days", type=int, default=1, help="operating days of 12 h (1-3650; default 1)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seeds the packs, the demand and the world")
    p.add_argument("--rate", type=float, default=4.0, metavar="PER_H",
                   help="Poisson demand: requests per hour (0-60; default 4)")
    p.add_argument("--demand", default=None, metavar="FILE",
                   help="a day's requests from a CSV or JSON file instead (columns t_s,name,x_km,y_km,"
                        "priority,wind_kts,window_s,vertiport); flown on every day")
    p.add_argument("--max-km", type=float, default=45.0, metavar="KM",
                   help="Poisson demand: the farthest request (8-100 km; default 45)")
    p.add_argument("--chargers", type=int, default=2, help="chargers at each vertiport (1-50; default 2)")
    p.add_argument("--vertiports", type=int, default=1,
                   help="vertiports the aircraft are spread over, each with its own chargers and requests "
                        "(1-10, at most one per aircraft; default 1)")
    p.add_argument("--age-spread", type=float, default=None, metavar="EFC",
                   help="the packs' age at the start: U(0, EFC) equivalent full cycles (0-2000; default 60%% of "
                        "the law's cycles to 80%% capacity: about 54 for nasa, 294 for vtc6)")
    add_world_arguments(p, "the fleet's packs fly")
    p.add_argument("--risk", type=float, default=DEFAULT_RISK, metavar="P",
                   help="the declared risk the health-aware dispatcher's margins follow from (0.0001 to below 0.5; "
                        "default 0.05): its health P to the weak side, each leg's wind P/5 to the head side")
    p.add_argument("--law", choices=["nasa", "vtc6"], default="nasa",
                   help="the packs' cell type and the aging law they follow: nasa (the paper's cell, fitted to the "
                        "NASA PCoE lives; default) or vtc6 (fitted to the CMU lives)")
    p.add_argument("--keep-retired", action="store_true",
                   help="over a life, a retired pack stays grounded (default: it is replaced overnight)")
    p.add_argument("--dispatcher", action="append", choices=["aware", "blind", "hindsight"], default=None,
                   help="which dispatchers (repeatable; default all three)")
    p.add_argument("--seeds", type=int, default=1, help="lives per dispatcher, seeded --seed, --seed+1, ... "
                                                        "(1-1000; default 1)")
    add_engine_arguments(p, "lives")
    p.add_argument("--json", action="store_true", help="print every day's numbers as JSON")
    p.add_argument("--csv", default=None, metavar="FILE",
                   help="also write every day's numbers as CSV, one row per dispatcher, seed and day (atomic)")


DAY_FIELDS = ("priority", "served", "refused", "breaches", "bound")  # each day's numbers in the CSV (bound: hindsight)
CSV_FIELDS = ("dispatcher", "seed", "day", *DAY_FIELDS)


def _check_csv_path(path: str | None) -> None:
    """``--csv``: a file in an existing folder (checked before any work)."""
    from uam_studio.errors import InputError

    if path is not None and (not Path(path).parent.is_dir() or Path(path).is_dir()):
        raise InputError("--csv", f"{path}: not a file in an existing folder")


def _write_csv(path: str, rows: list[dict]) -> None:
    """The rows (keys :data:`CSV_FIELDS`) as CSV at ``path``, written atomically."""
    from uam_studio.atomic_io import atomic_save

    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=CSV_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_save(path, lambda f: f.write(text.getvalue().encode()))


def _run_fleet(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from uam_studio.errors import check_range
    from uam_studio.fleet.day import Fleet, default_age_spread, fly_day_of_life
    from uam_studio.fleet.demand import load_demand
    from uam_studio.risk import check_risk

    for flag, value, lo, hi in (("--aircraft", args.aircraft, 1, 50), ("--days", args.days, 1, 3650),
                                ("--rate", args.rate, 0.0, 60.0), ("--chargers", args.chargers, 1, 50),
                                ("--max-km", args.max_km, 8.0, 100.0),
                                ("--vertiports", args.vertiports, 1, min(10, args.aircraft))):
        check_range(flag, value, lo, hi)  # before any work: one line naming the flag
    if args.age_spread is None:
        args.age_spread = default_age_spread(args.law)
    check_range("--age-spread", args.age_spread, 0.0, 2000.0)
    check_risk(args.risk)
    _check_csv_path(args.csv)
    dispatchers = args.dispatcher or ["aware", "blind", "hindsight"]
    out = {}
    if args.demand is not None:
        demand = load_demand(args.demand)
        for d in dispatchers:
            fleet = Fleet.new(args.aircraft, args.seed, args.age_spread, args.vertiports, args.law, args.world)
            days = [fly_day_of_life(fleet, demand, d, args.seed, k, args.chargers, not args.keep_retired,
                                    args.risk)[0].to_dict()
                    for k in range(int(args.days))]
            out[d] = {"dispatcher": d, "days": days}
    else:
        from uam_studio.fleet.study import fleet_study, summarize

        check_range("--seeds", args.seeds, 1, 1000)
        check_workers(args)
        seeds = range(args.seed, args.seed + int(args.seeds))
        with tqdm(total=len(dispatchers) * len(seeds), desc="fleet lives", disable=args.json, file=sys.stderr) as bar:
            rows = fleet_study((args.aircraft,), args.days, seeds, dispatchers, args.rate, args.chargers,
                               args.age_spread, workers=args.workers, address=args.address,
                               progress=lambda done, _n: bar.update(done - bar.n), max_km=args.max_km,
                               vertiports=args.vertiports, law=args.law, renew=not args.keep_retired,
                               world=args.world, risk=args.risk)
        if args.csv is not None:
            _write_csv(args.csv, [{"dispatcher": r["dispatcher"], "seed": r["seed"], "day": d + 1,
                                   **{k: r[k][d] for k in DAY_FIELDS}}
                                  for r in rows for d in range(len(r["priority"]))])
        if args.json:
            json.dump({"lives": rows, "summary": summarize(rows)}, sys.stdout, allow_nan=False)
            sys.stdout.write("\n")
            return EXIT_OK
        print(f"{args.aircraft} aircraft at {args.vertiports} vertiport(s), {args.days} day(s) x {len(seeds)} seed(s) "
              f"from {args.seed}, Poisson {args.rate:g} requests/h up to {args.max_km:g} km, "
              f"{args.chargers} charger(s) per vertiport, {args.law} packs aged U(0, {args.age_spread:.0f}) cycles, "
              f"{'retired packs grounded' if args.keep_retired else 'a retired pack replaced overnight'}, "
              f"world {args.world}, declared risk {args.risk:g}")
        print(f"{'dispatcher':10} {'priority/day':>12} {'5-95%':>9} {'served':>7} {'refused':>8} {'breaches':>9} "
              f"{'packs retired':>13} {'mean day':>8} {'bound/day':>9}")
        for r in summarize(rows):
            day = "-" if r["mean_retirement_day"] is None else f"{r['mean_retirement_day']:.0f}"
            print(f"{r['dispatcher']:10} {r['priority_per_day']:12.1f} {r['p5']:4.0f}-{r['p95']:<4.0f} "
                  f"{r['served']:7d} {r['refused']:8d} {r['breaches']:9d} {r['packs_retired']:13d} {day:>8} "
                  f"{_per_day(r['bound_per_day']):>9}")
        print("bound/day: the most stars any dispatcher could serve from hindsight's fleet, knowing the day "
              "(uam_studio.fleet.hindsight)")
        return EXIT_OK
    if args.csv is not None:
        _write_csv(args.csv, [{"dispatcher": d, "seed": args.seed, "day": k + 1, **{f: day[f] for f in DAY_FIELDS}}
                              for d, life in out.items() for k, day in enumerate(life["days"])])
    if args.json:
        json.dump(out, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
        return EXIT_OK
    print(f"{args.aircraft} aircraft at {args.vertiports} vertiport(s), {args.days} day(s), seed {args.seed}, "
          f"{'demand ' + args.demand if args.demand else f'Poisson {args.rate:g} requests/h'}, "
          f"{args.chargers} charger(s) per vertiport")
    print(f"{'dispatcher':10} {'priority/day':>12} {'served':>7} {'refused':>8} {'breaches':>9} {'flights':>8} "
          f"{'charge Ah/day':>13} {'retired packs':>13} {'bound/day':>9}")
    for d, life in out.items():
        days = life["days"]
        n = len(days)
        retired = [r for r in life.get("retired_day", []) if r is not None]
        print(f"{d:10} {sum(x['priority'] for x in days) / n:12.1f} {sum(x['served'] for x in days):7d} "
              f"{sum(x['refused'] for x in days):8d} {sum(x['breaches'] for x in days):9d} "
              f"{sum(x['flights'] for x in days):8d} {sum(x['charge_ah'] for x in days) / n:13.1f} "
              f"{len(retired):13d} "
              f"{_per_day(None if days[0]['bound'] is None else sum(x['bound'] for x in days) / n):>9}")
    return EXIT_OK


def _per_day(value: float | None) -> str:
    """A per-day mean for the tables: one decimal, or "-" where there is none."""
    return "-" if value is None else f"{value:.1f}"


COMMAND = Command(
    "a fleet's day or life: health-aware, health-blind and hindsight dispatchers on the same demand and packs",
    _add_fleet_arguments,
    _run_fleet,
)
