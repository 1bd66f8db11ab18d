"""``uam-studio evaluate``: a Dynaformer on held-out synthetic data (or its noise table), ``real``: the
models on the CMU eVTOL dataset's real cells, ``lives``: every landing of its four resampled lives
predicted leave one cell out, or ``nasa``: every discharge of a folder of NASA PCoE cells predicted
online."""

from __future__ import annotations

import argparse
import json
import sys

from uam_studio.cli.common import EXIT_INPUT, EXIT_OK, CliExit, Command, seed_arg
from uam_studio.errors import check_range


def _add_evaluate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", choices=["dynaformer", "real", "lives", "nasa"],
                   help="dynaformer: held-out synthetic data; real: the battery, health and safety models on the "
                        "CMU eVTOL dataset's real VTC6 cells (needs --data); lives: each baseline mission's landing "
                        "of the dataset's four resampled lives predicted from the flight before it, on a parameter "
                        "set identified without that cell, with the 90%% interval's coverage and missed breaches "
                        "(about 10 min); nasa: every discharge of each NASA PCoE cell file in --data predicted online "
                        "from the cell's earlier discharges, its first --context-s and its planned current, beside "
                        "persistence and progpy's default model (a cell the bundled model trained on is scored "
                        "leave one cell out)")
    p.add_argument("--data", default=None, metavar="PATH",
                   help="real, lives: the CMU eVTOL dataset's folder (default: $UAM_STUDIO_CMU_DATA; DOI "
                        "10.1184/R1/14226830)")
    p.add_argument("--cell", action="append", default=None,
                   help="lives: only this life, VAH07, VAH09, VAH27 or VAH30 (repeat for more; default all four); "
                        "nasa: only this cell, e.g. B0005 (repeat for more; default every cell file in --data)")
    p.add_argument("--every", type=int, default=None,
                   help="lives: score every n-th mission; nasa: every n-th discharge (1-1000, default 1)")
    p.add_argument("--context-s", type=float, default=None,
                   help="nasa: seconds of each discharge's voltage read before predicting (10-3600, default 300)")
    p.add_argument("--cutoff-v", type=float, default=None,
                   help="nasa: the cut-off whose time is predicted (2.5-3.6 V, default 3.0)")
    p.add_argument("--method", choices=["history", "belief"], default=None,
                   help="nasa: history (default: the history predictor, nasa_predict) or belief (the one health "
                        "belief over the cell's logbook of earlier discharges, on the identified NASA cell; slower)")
    p.add_argument("--dynaformer", action="store_true",
                   help="nasa: add the bundled NASA Dynaformer's prediction of the same discharges to each row (its "
                        "history method, online; about 12 min for all 26 cells on 2 cores)")
    p.add_argument("--max-nfev", type=int, default=None,
                   help="lives: evaluations of each parameter set's identification (1-10000, default 100)")
    p.add_argument("--quick", action="store_true",
                   help="real: skip the two held-out VTC6 sets: the health and safety rows are then only the "
                        "bundled set's, in-sample")
    p.add_argument("--refit", action="store_true",
                   help="real: identify the two held-out VTC6 sets again from --data (about 10 s each) instead of "
                        "reading their bundled literals")
    p.add_argument("--weights", default=None, help="weights file (default: the bundled model)")
    p.add_argument("--table", choices=["default", "noise"], default=None,
                   help="default: the held-out sets, beside the physics fit; noise: EOD timing over sensor noise "
                        "(0, 1, 5, 10 mV) x context (20, 60, 120, 600 s) x log start (aligned, at rest), beside the "
                        "physics fit and the take-off estimator, with 90%% interval coverage and latency")
    p.add_argument("--n", type=int, default=None,
                   help="missions per held-out set (default 400; --table noise: 200 flights)")
    p.add_argument("--compare", default=None, metavar="WEIGHTS",
                   help="--table noise: one more column, another weights file with its own health estimator "
                        "(e.g. a transformer-encoder model)")
    p.add_argument("--seed", type=seed_arg, default=None,
                   help="dynaformer, lives: the draws' seed (default 12345; lives: 38200)")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")


# Each option but --json, and the models that read it: any other model refuses it in one line.
OPTION_MODELS = {"data": ("real", "lives", "nasa"), "quick": ("real",), "refit": ("real",), "cell": ("lives", "nasa"),
                 "every": ("lives", "nasa"), "context_s": ("nasa",), "cutoff_v": ("nasa",), "method": ("nasa",),
                 "dynaformer": ("nasa",),
                 "max_nfev": ("lives",),
                 "weights": ("dynaformer",), "table": ("dynaformer",),
                 "n": ("dynaformer",), "compare": ("dynaformer",), "seed": ("dynaformer", "lives")}


def _check_options(args: argparse.Namespace) -> None:
    """Refuse, in one line, every option given that ``args.model`` does not read."""
    given = [k for k, models in OPTION_MODELS.items()
             if getattr(args, k) not in (None, False) and args.model not in models]
    if given:
        flags = ", ".join("--" + k.replace("_", "-") for k in given)
        only = "; ".join(f"--{k.replace('_', '-')} only with "
                         + " or ".join(f"'evaluate {m}'" for m in OPTION_MODELS[k]) for k in given)
        raise CliExit(f"{flags}: not read by 'evaluate {args.model}' ({only})", EXIT_INPUT)


def _run_evaluate(args: argparse.Namespace) -> int:
    from ..dynaformer.evaluate import evaluate, format_noise_table, format_report, noise_table
    from ..dynaformer.predictor import load_predictor

    _check_options(args)
    if args.model == "nasa":
        return _run_nasa(args)
    if args.model == "lives":
        from ..studies.real_lives import format_scores, leave_one_cell_out, totals_line

        every = int(check_range("--every", 1 if args.every is None else args.every, 1, 1000))
        max_nfev = int(check_range("--max-nfev", 100 if args.max_nfev is None else args.max_nfev, 1, 10_000))
        seed = args.seed if args.seed is not None else 38200
        scores = leave_one_cell_out(args.data, every=every, seed=seed, max_nfev=max_nfev, cells=args.cell)
        if args.json:
            print(json.dumps([s.as_dict() for s in scores], indent=2, allow_nan=False))
        else:
            print(format_scores(scores))
            print(totals_line(scores))
        return EXIT_OK
    if args.model == "real":
        from ..battery.real.cmu_data import data_folder
        from ..battery.real.places import sample_note
        from ..studies.real_cells import format_report as format_real

        _note(sample_note(data_folder(args.data)))
        from ..studies.real_cells import real_cell_report

        report = real_cell_report(args.data, held_out=not args.quick, refit=args.refit)
        print(json.dumps(report.as_dict(), indent=2) if args.json else format_real(report))
        return EXIT_OK
    table = args.table or "default"
    n = args.n if args.n is not None else (200 if table == "noise" else 400)
    if n < 10:
        raise CliExit("--n: must be >= 10", EXIT_INPUT)
    if args.compare is not None and table != "noise":
        raise CliExit("--compare: only with --table noise", EXIT_INPUT)
    seed = args.seed if args.seed is not None else 12345
    pred = load_predictor(args.weights)
    if table == "noise":
        other = load_predictor(args.compare) if args.compare is not None else None
        compare = {other.model.cfg.health if other.model.cfg.health != "takeoff" else "other": other} if other else None
        metrics = noise_table(pred, n=n, seed=seed, compare=compare)
        print(json.dumps(metrics, indent=2) if args.json else format_noise_table(metrics))
        return EXIT_OK
    metrics = evaluate(pred, n=n, seed=seed)
    print(json.dumps(metrics, indent=2) if args.json else format_report(metrics))
    return EXIT_OK


def _note(line: str | None) -> None:
    """Say on stderr (so that --json stays clean) which data the command runs on, where it is the sample."""
    if line:
        print(f"note: {line}", file=sys.stderr)


def _run_nasa(args: argparse.Namespace) -> int:
    from ..battery.real.nasa_data import NasaDataError, load_nasa_folder, nasa_folder
    from ..battery.real.nasa_eval import evaluate_nasa, format_table, skipped_summary
    from ..battery.real.nasa_model import bundled_model
    from ..battery.real.places import sample_note

    context_s = check_range("--context-s", 300.0 if args.context_s is None else args.context_s, 10.0, 3600.0, " s")
    cutoff_v = check_range("--cutoff-v", 3.0 if args.cutoff_v is None else args.cutoff_v, 2.5, 3.6, " V")
    every = int(check_range("--every", 1 if args.every is None else args.every, 1, 1000))
    folder = nasa_folder(args.data)
    _note(sample_note(folder))
    cells = load_nasa_folder(folder, args.cell, cutoff_v)
    if args.method == "belief":
        from ..battery.real.nasa_belief import evaluate_belief

        rows = evaluate_belief(cells, cutoff_v, context_s, every=every)
    else:
        model = bundled_model(context_s, cutoff_v)
        training = None
        if any(c.name in model.trained_on for c in cells):
            training = [c for c in load_nasa_folder(folder, None, cutoff_v) if c.name in model.trained_on]
        rows = evaluate_nasa(cells, model, training, every=every)
    if not rows:
        raise NasaDataError(folder, "data", f"no discharge to score at {cutoff_v:g} V after {context_s:g} s: "
                                            + skipped_summary(cells, context_s))
    if args.dynaformer:
        from ..dynaformer.nasa_discharges import with_dynaformer

        rows = with_dynaformer(rows, cells, context_s, cutoff_v, every)
    if args.json:
        print(json.dumps({"context_s": context_s, "cutoff_v": cutoff_v, "discharges": [r.as_dict() for r in rows]},
                         indent=1, allow_nan=False))
    else:
        print(f"NASA PCoE cells in {folder}: time to {cutoff_v:g} V predicted {context_s:g} s after the load; errors "
              "in % of the true time left then; cov90: share inside the 90% interval; miss95/miss99: share below "
              "the 5%/1% risk bound; (loco): scored by a model fitted without that cell")
        print(format_table(rows, cells, context_s))
    return EXIT_OK


COMMAND = Command("evaluate a model on held-out synthetic data, or the models on real cells and real lives",
                  _add_evaluate_arguments, _run_evaluate)
