"""``uam-studio logbook``: a pack's logbook. ``new`` makes the logbook of a pack that has flown a mission before
(simulated: the mission's cell as it aged, read by the same sensors); ``show`` prints what a logbook holds and the
health belief it gives at the next take-off."""

from __future__ import annotations

import argparse

from uam_studio.cli.common import EXIT_OK, Command, add_world_arguments, seed_arg


def _add_logbook_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True, parser_class=type(p))
    new = sub.add_parser("new", help="the logbook of a pack that has flown MISSION N times before")
    new.add_argument("mission", metavar="MISSION.json", help="mission file: its battery is the pack now")
    new.add_argument("--flights", type=int, required=True, metavar="N", help="earlier flights (0-200)")
    new.add_argument("--seed", type=seed_arg, default=0, help="seeds the earlier flights' worlds")
    new.add_argument("--age-efc", type=float, default=None, metavar="EFC",
                     help="the pack's equivalent full cycles now (0-2000; default: new at its first logged flight)")
    new.add_argument("--sensor-noise-mv", type=float, default=None, metavar="MV",
                     help="voltage sensor noise std (mV, 0-100; default 5)")
    add_world_arguments(new, "the earlier flights flew", pack="fly it with the same number (fly --pack)")
    new.add_argument("--out", required=True, metavar="FILE", help="where to write the logbook (JSON)")
    show = sub.add_parser("show", help="a logbook's flights and the belief it gives at the next take-off")
    show.add_argument("logbook", metavar="FILE")


def _run_logbook(args: argparse.Namespace) -> int:
    import numpy as np

    from uam_studio.battery.health import Logbook
    from uam_studio.battery.health.belief import HealthBelief

    if args.action == "new":
        from uam_studio.planning import load_mission
        from uam_studio.planning.operations.pack_history import simulate_logbook

        mission = load_mission(args.mission)
        noise = {} if args.sensor_noise_mv is None else {"sensor_noise_mv": args.sensor_noise_mv}
        book = simulate_logbook(mission, args.flights, args.seed, args.age_efc, world=args.world, pack=args.pack,
                                **noise)
        book.save(args.out)
        print(f"wrote {args.out}: {len(book)} flights of {mission.name}'s pack (seed {args.seed})")
    else:
        book = Logbook.load(args.logbook)
    belief = HealthBelief(book.noise_v, book.eod_v, logbook=book)
    h = belief.prior_health()
    print(f"{len(book)} flights, {book.delivered_c() / 3600.0:.2f} Ah delivered in all; belief at the next take-off "
          f"({belief.source}): q_max {h.q_max_c:.0f} +- {h.q_max_sd_c:.0f} C, R0 {h.r0_ohm:.4f} +- "
          f"{h.r0_sd_ohm:.4f} ohm; model error {1e3 * belief.model_error.sd_v:.1f} mV (the cell type's "
          f"{1e3 * belief.model_error.prior_sd_v:.0f} mV pooled with {belief.model_error.flights} flights' residuals)")
    if book.flights:  # the share of the model error in the belief's interval of the last flight's lowest voltage
        last = book.flights[-1]
        share = belief.model_error_share(np.asarray(last.current_a, dtype=float), 0)
        print(f"on the last flight's load, the model error is {share:.0%} of the variance of the lowest voltage's "
              "interval (the rest: the health's uncertainty)")
    return EXIT_OK


COMMAND = Command("a pack's logbook: make one for a pack that has flown a mission before (new), or read one (show)",
                  _add_logbook_arguments, _run_logbook)
