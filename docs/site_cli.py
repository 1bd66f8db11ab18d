"""The Command line page's generated parts: every ``uam-studio`` command's options, read from the parser the
command line itself builds (:func:`uam_studio.cli.build_parser`), and the bad-input examples, run through
:func:`uam_studio.cli.main` at build time. The docs hook (``docs/hooks.py``) puts them where ``docs/cli.md``
says ``<!-- cli: options -->`` and ``<!-- cli: errors -->``, so the page cannot drift from the code."""

from __future__ import annotations

import argparse
import contextlib
import io
import os
from pathlib import Path
from unittest import mock

ROOT = Path(__file__).resolve().parents[1]

# Bad input, one line each (run from the repository root; each fails while its arguments are read, before
# any model loads): (what is wrong, the arguments after ``uam-studio``).
BAD_INPUT: list[tuple[str, list[str]]] = [
    ("no command", []),
    ("a value out of its range", ["plan", "assets/example_mission.json", "--q-max", "-1"]),
    ("a file that is not there", ["plan", "nothere.json"]),
    ("a choice that is not offered", ["plan", "assets/example_mission.json", "--policy", "best"]),
    ("a place the mission does not have",
     ["simulate", "assets/example_mission.json", "--route", "Fremont,Nowhere,vertiport", "--altitudes",
      "500,500,500"]),
    ("a number that is not one", ["simulate", "assets/example_mission.json", "--route", "Fremont,vertiport",
                                  "--altitudes", "500,high"]),
    ("an event in the wrong form", ["fly", "assets/example_mission.json", "--event", "wind+30"]),
    ("a fleet out of range", ["fleet", "--aircraft", "0"]),
    ("a port out of range", ["serve", "--port", "99999"]),
    ("a file that is not a logbook", ["logbook", "show", "assets/example_mission.json"]),
]


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _cell(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _flags(action: argparse.Action) -> str:
    if action.option_strings:
        names = ", ".join(f"`{s}`" for s in action.option_strings)
        if action.nargs != 0:
            meta = action.metavar or (("{" + ",".join(map(str, action.choices)) + "}") if action.choices
                                      else action.dest.upper())
            names += f" `{meta}`"
        return names
    if action.choices and not isinstance(action, argparse._SubParsersAction):
        return f"`{action.metavar or action.dest}`: " + " \\| ".join(f"`{c}`" for c in action.choices)
    return f"`{action.metavar or action.dest}`"


def _default(action: argparse.Action) -> str:
    if action.option_strings and action.nargs != 0 and action.default not in (None, argparse.SUPPRESS):
        return f"`{action.default}`"
    return ""


def _options_table(parser: argparse.ArgumentParser) -> str:
    rows = []
    for group in parser._action_groups:
        for action in group._group_actions:
            if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            helptext = parser._get_formatter()._expand_help(action) if action.help else ""
            section = group.title if group.title not in ("options", "positional arguments") else ""
            what = f"*{section}*: {helptext}" if section and helptext else (helptext or section)
            rows.append(f"| {_flags(action)} | {_cell(what)} | {_default(action)} |")
    if not rows:
        return ""
    return "| argument | what it does | default |\n|---|---|---|\n" + "\n".join(rows) + "\n"


def command_names() -> list[str]:
    """Every command and sub-command of the parser, e.g. ``["simulate", ..., "data import", ...]``."""
    from uam_studio.cli import build_parser

    names = []
    for name, parser in _subparsers(build_parser()).items():
        names.append(name)
        names += [f"{name} {sub}" for sub in _subparsers(parser)]
    return names


def _section(level: str, name: str, parser: argparse.ArgumentParser) -> list[str]:
    """One command's section: its heading (anchor: the name with '-' for spaces), summary, usage and options."""
    return [f"{level} `uam-studio {name}` {{#{name.replace(' ', '-')}}}\n", f"{parser.description or ''}\n",
            f"```text\n{parser.format_usage().strip()}\n```\n", _options_table(parser)]


def options_markdown() -> str:
    """One section per command (and sub-command): its summary, usage and options, from the parser. The usage
    lines are wrapped at 80 columns on every machine (``COLUMNS`` is set while they are written, then put
    back)."""
    from uam_studio.cli import build_parser

    out: list[str] = []
    with mock.patch.dict(os.environ, {"COLUMNS": "80"}):
        for name, parser in _subparsers(build_parser()).items():
            out += _section("##", name, parser)
            for sub_name, sub in _subparsers(parser).items():
                out += _section("###", f"{name} {sub_name}", sub)
    return "\n".join(out)


def run_bad_input(argv: list[str]) -> tuple[str, int]:
    """``uam-studio ARGV`` run in this process from the repository root: (its stderr, its exit code)."""
    from uam_studio.cli import main

    err = io.StringIO()
    here = Path.cwd()
    os.chdir(ROOT)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(argv)
    finally:
        os.chdir(here)
    return err.getvalue().strip(), code


def errors_markdown() -> str:
    """The bad-input examples as a shell shows them. Raises ``ValueError`` if one does not fail in one
    ``error:`` line with exit code 2."""
    out = []
    for what, argv in BAD_INPUT:
        text, code = run_bad_input(argv)
        if code != 2 or len(text.splitlines()) != 1 or not text.startswith("error: "):
            raise ValueError(f"uam-studio {' '.join(argv)}: expected one 'error:' line and exit 2, got {code}: "
                             f"{text!r}")
        out.append(f"{what}:\n\n```console\n$ uam-studio {' '.join(argv)}\n{text}\n$ echo $?\n{code}\n```\n")
    return "\n".join(out)
