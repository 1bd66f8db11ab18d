"""``uam-studio serve``: start the Panel app on an address and port, answering only the allowed hosts."""

from __future__ import annotations

import argparse
import errno
import socket
import sys

from uam_studio.cli.common import EXIT_INPUT, EXIT_OK, CliExit, Command


def _add_serve_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=int, default=5006, help="port to listen on (default 5006)")
    p.add_argument("--address", default=None,
                   help="address to listen on (default 127.0.0.1: this machine only); e.g. 0.0.0.0 for "
                        "all interfaces, which lets anyone who can reach the port use the app, with no login")
    p.add_argument("--allow-origin", action="append", default=[], metavar="HOST[:PORT]",
                   help="also answer requests addressed to HOST[:PORT] (the name or IP other machines use "
                        "to reach this one; PORT defaults to --port); repeatable. Other names get 403")
    p.add_argument("--num-procs", default="1", metavar="N",
                   help="app processes (auto or 0: one per core; default 1). With more than one, a front process "
                        "holds the port and sends each page's websocket to the process that built the page")
    p.add_argument("--show", action=argparse.BooleanOptionalAction, default=True,
                   help="open the app in a browser (default: yes)")


def _run_serve(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        raise CliExit(f"--port: {args.port} is out of range; allowed [0, 65535]", EXIT_INPUT)
    procs = "0" if str(args.num_procs).strip().lower() == "auto" else str(args.num_procs).strip()
    if not (procs.isdigit() and 0 <= int(procs) <= 64):
        raise CliExit(f"--num-procs: {args.num_procs} is out of range; allowed [0, 64] or auto (one per core)",
                      EXIT_INPUT)
    args.num_procs = int(procs)
    try:
        from uam_studio.app.serve import DEFAULT_ADDRESS, serve, split_host
    except ImportError as err:
        raise CliExit(f"serve: the app needs panel and holoviews ({err})", EXIT_INPUT) from None
    for value in args.allow_origin:
        try:
            split_host(value)
        except ValueError as err:
            raise CliExit(f"--allow-origin: {err}", EXIT_INPUT) from None
    address = args.address or DEFAULT_ADDRESS
    if address in ("0.0.0.0", "::") and not args.allow_origin:
        print(f"note: --address {address}: other machines get 403 unless the name or IP they use for this "
              "one is allowed with --allow-origin HOST[:PORT]", file=sys.stderr)
    try:
        serve(port=args.port, show=args.show, address=address, allow_origin=args.allow_origin,
              num_procs=args.num_procs)
    except OSError as err:
        if isinstance(err, socket.gaierror) or err.errno in (errno.EADDRNOTAVAIL, errno.EAFNOSUPPORT):
            raise CliExit(f"--address: cannot listen on {address} ({err.strerror or err})", EXIT_INPUT) from None
        raise CliExit(f"--port: cannot listen on {address}:{args.port} ({err.strerror or err})",
                      EXIT_INPUT) from None
    return EXIT_OK


COMMAND = Command("start the app in a browser: Planner, Fly, Battery lab, Retrain, Fleet and Glossary tabs",
                  _add_serve_arguments,
                  _run_serve)
