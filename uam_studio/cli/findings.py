"""``uam-studio findings``: the paper's four findings measured on our physics, on the Dask engine."""

from __future__ import annotations

import argparse
import json
import sys

from uam_studio.cli.common import EXIT_OK, Command, add_engine_arguments, check_workers


def _add_findings_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true",
                   help="10 missions for finding 2; 20,000 steps and 30 evaluation missions per agent (default: "
                        "40 missions; 80,000 steps and 100 missions, about 3 minutes per agent on one core)")
    add_engine_arguments(p, "missions and agents")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")


def _run_findings(args: argparse.Namespace) -> int:
    from uam_studio.studies.findings import format_findings, paper_findings

    check_workers(args)
    out = paper_findings(quick=args.quick, workers=args.workers, address=args.address)
    if args.json:
        json.dump(out, sys.stdout, allow_nan=False, default=float)
        sys.stdout.write("\n")
    else:
        print(format_findings(out))
    return EXIT_OK


COMMAND = Command("the paper's four findings measured on the physics model (agents trained on the Dask engine)",
                  _add_findings_arguments, _run_findings)
