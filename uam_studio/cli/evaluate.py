"""``uam-studio evaluate``: a Dynaformer on held-out synthetic data (or its noise table), or ``real``: the
models on the CMU eVTOL dataset's real cells."""

from __future__ import annotations

import argparse
import json

from uam_studio.cli.common import EXIT_INPUT, EXIT_OK, CliExit, Command, seed_arg


def _add_evaluate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", choices=["dynaformer", "real"],
                   help="dynaformer: held-out synthetic data; real: the battery, health and safety models on the "
                        "CMU eVTOL dataset's real VTC6 cells (needs --data)")
    p.add_argument("--data", default=None, metavar="PATH",
                   help="real: the CMU eVTOL dataset's folder (default: $UAM_STUDIO_CMU_DATA; DOI 10.1184/R1/14226830)")
    p.add_argument("--quick", action="store_true",
                   help="real: skip the two held-out VTC6 sets: the health and safety rows are then only the "
                        "bundled set's, in-sample")
    p.add_argument("--refit", action="store_true",
                   help="real: identify the two held-out VTC6 sets again from --data (about 10 s each) instead of "
                        "reading their bundled literals")
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
    p.add_argument("--seed", type=seed_arg, default=12345)
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")


def _run_evaluate(args: argparse.Namespace) -> int:
    from ..dynaformer.evaluate import evaluate, format_noise_table, format_report, noise_table
    from ..dynaformer.predictor import load_predictor

    if args.model == "real":
        from ..studies.real_cells import format_report as format_real
        from ..studies.real_cells import real_cell_report

        report = real_cell_report(args.data, held_out=not args.quick, refit=args.refit)
        print(json.dumps(report.as_dict(), indent=2) if args.json else format_real(report))
        return EXIT_OK
    if args.data is not None or args.quick or args.refit:
        raise CliExit("--data, --quick, --refit: only with 'evaluate real'", EXIT_INPUT)
    n = args.n if args.n is not None else (200 if args.table == "noise" else 400)
    if n < 10:
        raise CliExit("--n: must be >= 10", EXIT_INPUT)
    if args.compare is not None and args.table != "noise":
        raise CliExit("--compare: only with --table noise", EXIT_INPUT)
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


COMMAND = Command("evaluate a model on held-out synthetic data, or the models on real cells",
                  _add_evaluate_arguments, _run_evaluate)
