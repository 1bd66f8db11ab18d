"""``uam-studio identify``: a real cell's parameter set, identified from measured data and printed as Python."""

from __future__ import annotations

import argparse

from uam_studio.cli.common import EXIT_INPUT, EXIT_OK, CliExit, Command


def _add_identify_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("cell", choices=["vtc6", "nasa", "nasa-cell"],
                   help="vtc6: the CMU eVTOL dataset's Sony-Murata VTC6 cell's parameter set; nasa: the NASA PCoE "
                        "end-of-discharge predictor's cross-cell numbers (battery/real/nasa_model.py), from every cell "
                        "file in --data; nasa-cell: the NASA 18650's parameter set (NASA_IDENTIFIED), from B0005's "
                        "first three discharges in --data")
    p.add_argument("--data", default=None, metavar="PATH",
                   help="vtc6: the CMU eVTOL dataset's folder (default: $UAM_STUDIO_CMU_DATA; "
                        "DOI 10.1184/R1/14226830); nasa: a NASA PCoE folder (default: $UAM_STUDIO_NASA_DATA)")
    p.add_argument("--hold-out", choices=["none", "landing", "cell"], default="none",
                   help="none: the bundled set (VTC6); landing: without VAH01's landing and rest "
                        "(VTC6_LANDING_HELD_OUT); cell: without VAH01 (VTC6_CELL_HELD_OUT)")


def _run_identify(args: argparse.Namespace) -> int:
    if args.cell != "vtc6" and args.hold_out != "none":
        raise CliExit("--hold-out: only with 'identify vtc6'", EXIT_INPUT)
    if args.cell == "nasa-cell":
        from ..battery.real.nasa_physics import identify_nasa, nasa_cell_literal

        print(nasa_cell_literal(identify_nasa(args.data)))
        return EXIT_OK
    if args.cell == "nasa":
        from ..battery.real.nasa_data import load_nasa_folder, nasa_folder
        from ..battery.real.nasa_eval import fit_bundled, models_literal

        print(models_literal(fit_bundled(load_nasa_folder(nasa_folder(args.data)))))
        return EXIT_OK
    from ..battery.real.cmu_data import data_folder
    from ..battery.real.cmu_replay import cell_literal, identify_vtc6

    print(cell_literal(identify_vtc6(data_folder(args.data), hold_out=args.hold_out), args.hold_out))
    return EXIT_OK


COMMAND = Command("identify a real cell's parameter set from measured data (prints it as Python)",
                  _add_identify_arguments, _run_identify)
