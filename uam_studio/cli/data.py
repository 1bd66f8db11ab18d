"""``uam-studio data``: the real data sets, where each was found (a folder given, an environment variable, beside a
source checkout, or the sample that ships with the package), how many cells and whether their checksums hold, and
where to get the full sets. ``uam-studio data import nasa SRC --out DIR`` converts NASA's own ``.mat`` files into
the format the loader reads."""

from __future__ import annotations

import argparse

from uam_studio.cli.common import EXIT_OK, Command


def _add_data_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--nasa", default=None, metavar="DIR", help="look for the NASA PCoE cells here first")
    p.add_argument("--cmu", default=None, metavar="DIR", help="look for the CMU eVTOL cells here first")
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=False, parser_class=type(p))
    imp = sub.add_parser("import", help="convert a data set's original files into the loader's format")
    imp.add_argument("dataset", choices=["nasa"], help="nasa: NASA PCoE's BXXXX.mat files")
    imp.add_argument("source", metavar="SRC", help="the folder of the original files")
    imp.add_argument("--out", required=True, metavar="DIR", help="where to write the converted cells")


def _run_data(args: argparse.Namespace) -> int:
    if args.action == "import":
        from uam_studio.battery.real.nasa_import import import_nasa

        cells = import_nasa(args.source, args.out)
        n = sum(len(c.discharges) for c in cells)
        print(f"wrote {len(cells)} cell(s), {n} discharges, to {args.out} "
              f"({', '.join(c.name for c in cells)}); use it with --data {args.out}")
        return EXIT_OK
    from uam_studio.battery.real.datasets import describe

    for key, path in (("nasa", args.nasa), ("cmu", args.cmu)):
        d = describe(key, path)
        print(f"{d['title']}:")
        if d["folder"] is None:
            print(f"  not found: {d['how']}")
        else:
            print(f"  found: {d['folder']} ({d['how']}); {d['cells']} cell file(s); checksums {d['checksums']}")
        print(f"  cite: {d['cite']}")
        print(f"  the full set: {d['source']}")
        print(f"  to use it: {d['steps']}")
    return EXIT_OK


COMMAND = Command("the real data sets: where each was found, and how to get and import the full sets",
                  _add_data_arguments, _run_data)
