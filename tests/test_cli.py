"""Tests for the ``uam-studio`` CLI.

The process-level cases (exit code, one-line stderr, no traceback) run through ``main()``
in this process with stdout and stderr captured; three of them (the JSON and table output,
a malformed file) also as real subprocesses of the console script, started at once by one
module fixture. Extra argument-handling cases call ``main()`` in-process.
"""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from pathlib import Path

import pytest

from uam_studio.cli import COMMANDS, main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "assets" / "example_mission.json"
SAFE_ROUTE = ["--route", "Richmond,Hayward,vertiport", "--altitudes", "1000,1000,500"]


def _example() -> dict:
    return json.loads(EXAMPLE.read_text())


def _cases(tmp: Path) -> dict[str, tuple[list[str], str | None]]:
    """name -> (arguments after ``simulate``, field the error must name or None for success)."""
    windy = _example()
    windy["destinations"][0]["wind_kts"] = 45.0
    (tmp / "windy.json").write_text(json.dumps(windy))
    incomplete = _example()
    del incomplete["battery"]["r0"]
    (tmp / "incomplete.json").write_text(json.dumps(incomplete))
    (tmp / "malformed.json").write_text('{\n  "name": "Bay shuttle",\n  "vertiport": {"x_km": 0.0\n}\n')
    ex = str(EXAMPLE)
    return {
        "json": ([ex, *SAFE_ROUTE, "--json"], None),
        "table": ([ex, *SAFE_ROUTE], None),
        "altitude_range": ([ex, "--route", "Richmond,vertiport", "--altitudes", "500,3500"], "altitudes[1]"),
        "infeasible_leg": ([ex, "--route", "Richmond", "--altitudes", "3000"], "altitudes[0]"),
        "wind": ([str(tmp / "windy.json"), *SAFE_ROUTE], "destinations[0].wind_kts"),
        "q_max": ([ex, *SAFE_ROUTE, "--q-max=-5"], "q_max"),
        "unknown_name": ([ex, "--route", "Richmond,Oakland", "--altitudes", "500,500"], "route"),
        "malformed_json": ([str(tmp / "malformed.json"), *SAFE_ROUTE], "file"),
        "missing_field": ([str(tmp / "incomplete.json"), *SAFE_ROUTE], "battery.r0"),
    }


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli")
    cases = _cases(tmp)
    procs = {
        name: subprocess.Popen(
            [sys.executable, "-m", "uam_studio.cli", "simulate", *cases[name][0]],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp,
        )
        for name in AS_SUBPROCESS
    }
    out = {}
    for name, (args, field) in cases.items():
        if name not in AS_SUBPROCESS:
            stdout, stderr = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
                code = main(["simulate", *args])
            out[name] = (code, stdout.getvalue(), stderr.getvalue(), field)
    for name, p in procs.items():
        stdout, stderr = p.communicate(timeout=120)
        out[name] = (p.returncode, stdout, stderr, cases[name][1])
    return out


# the console script in a process of its own (its output as a user's shell gets it); the error cases
# run through uam_studio.cli.main in this process
AS_SUBPROCESS = ("json", "table", "malformed_json")


ERROR_CASES = ["altitude_range", "infeasible_leg", "wind", "q_max", "unknown_name", "malformed_json",
               "missing_field"]


@pytest.mark.parametrize("case", ERROR_CASES)
def test_bad_input_exits_2_with_one_line(runs, case):
    code, stdout, stderr, field = runs[case]
    assert code == 2, stderr
    assert "Traceback" not in stderr and stdout == ""
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"error: {field}: "), lines[0]


def test_error_details(runs):
    assert "line 5, column 1" in runs["malformed_json"][2]
    assert "valid names: vertiport, Richmond, Hayward, Fremont, Napa" in runs["unknown_name"][2]
    assert "too short to cruise at 3000 m" in runs["infeasible_leg"][2]
    assert "[-39, 39]" in runs["wind"][2]
    assert "missing" in runs["missing_field"][2]


def test_json_output(runs):
    code, stdout, stderr, _ = runs["json"]
    assert code == 0 and stderr == ""
    d = json.loads(stdout)
    assert list(d) == ["time_s", "current_a", "voltage_v", "eod_s", "safe", "complete", "legs"]
    assert d["eod_s"] is None and d["safe"] and d["complete"]  # the README route is safe and returns
    n = len(d["time_s"])
    assert n > 1000 and len(d["current_a"]) == n and len(d["voltage_v"]) == n
    assert all(isinstance(x, float) for x in d["voltage_v"][:50])
    assert d["time_s"][0] == 1.0 and d["time_s"][-1] == float(n)
    assert min(d["voltage_v"]) > 3.0
    assert [g["to"] for g in d["legs"]] == ["Richmond", "Hayward", "vertiport"]
    for g in d["legs"]:
        assert set(g) == {"to", "altitude_m", "start_s", "end_s", "min_voltage_v"}
        assert all(isinstance(g[k], float) for k in ("altitude_m", "start_s", "end_s", "min_voltage_v"))
    assert [g["altitude_m"] for g in d["legs"]] == [1000.0, 1000.0, 500.0]
    assert d["legs"][-1]["end_s"] == d["time_s"][-1]


def test_table_output(runs):
    code, stdout, stderr, _ = runs["table"]
    assert code == 0 and stderr == ""
    lines = stdout.splitlines()
    assert lines[0].startswith("Bay shuttle")
    assert "min V" in lines[1]
    assert [line.split()[2] for line in lines[2:5]] == ["Richmond", "Hayward", "vertiport"]
    assert lines[-1].startswith("EOD: not reached; safe")


# --------------------------------------------------------------------------- in-process


@pytest.mark.parametrize(
    ("argv", "start"),
    [
        ([], "error: choose a command: simulate"),
        (["simulate"], "error: the following arguments are required"),
        (["simulate", str(EXAMPLE), "--route", "Richmond", "--altitudes", "high"], "error: altitudes[0]: "),
        (["simulate", str(EXAMPLE), "--route", "Richmond,,vertiport", "--altitudes", "500,500"],
         "error: route: "),
        (["simulate", str(EXAMPLE), "--route", "Richmond,Richmond", "--altitudes", "500,500"],
         "error: route: leg 2 (Richmond -> Richmond) has zero length"),
        (["simulate", str(EXAMPLE), *SAFE_ROUTE, "--dt", "abc"], "error: argument --dt: invalid float value"),
        (["simulate", str(EXAMPLE), *SAFE_ROUTE, "--eod-v", "5"], "error: eod_v: "),
        (["simulate", "missing.json", *SAFE_ROUTE], "error: file: "),
        (["soar", str(EXAMPLE)], "error: argument COMMAND: invalid choice"),
    ],
)
def test_argument_errors_in_process(capsys, argv, start):
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1 and err.startswith(start), err


def test_unsafe_route_is_reported(capsys):
    argv = ["simulate", str(EXAMPLE), "--route", "Napa,Richmond,Hayward,Fremont,vertiport",
            "--altitudes", "500,500,500,500,500"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "UNSAFE" in out and "EOD: reached at" in out


def test_commands_registry():
    assert "simulate" in COMMANDS and callable(COMMANDS["simulate"].run)


def test_serve_help_names_every_tab():
    from uam_studio.app.main import TABS

    summary = COMMANDS["serve"].help
    assert all(title in summary for title, _ in TABS), summary


def test_the_readme_simulate_examples_run_on_the_bundled_missions(capsys):
    import shlex

    lines = [line.strip() for line in (ROOT / "README.md").read_text().splitlines()]
    examples = [shlex.split(line)[1:] for line in lines if line.startswith("uam-studio simulate assets/")]
    assert examples
    for args in examples:
        args[1] = str(ROOT / args[1])  # the README's paths are from the repository root
        assert main(args) == 0, args
        assert "EOD" in capsys.readouterr().out


def _subparser(name: str):
    import argparse

    from uam_studio.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


def _option(parser, flag: str):
    return next(a for a in parser._actions if flag in a.option_strings)


def test_the_cli_states_the_librarys_defaults_and_choices_and_keeps_no_copy_of_them():
    """The fly command's numeric options default to None (the library's value then applies) and their
    help states the library's value; the fly and fleet choices are the library's lists."""
    import re

    from uam_studio.fleet.day import PACK_LAWS
    from uam_studio.planning.operations import defaults
    from uam_studio.planning.planners import IN_FLIGHT_PLANNERS

    fly = _subparser("fly")
    stated = {"--forecast-sigma": defaults.DEFAULT_FORECAST_SIGMA_KT,
              "--sensor-noise-mv": defaults.DEFAULT_SENSOR_NOISE_MV,
              "--sensor-noise-ma": defaults.DEFAULT_SENSOR_NOISE_MA, "--reserve": defaults.WEATHER_RESERVE_KT}
    for flag, value in stated.items():
        action = _option(fly, flag)
        assert action.default is None, flag
        assert float(re.search(r"default (\d+(?:\.\d+)?)", action.help).group(1)) == value, flag
    policy = _option(fly, "--policy")
    assert tuple(policy.choices) == IN_FLIGHT_PLANNERS and policy.default == IN_FLIGHT_PLANNERS[0]
    law = _option(_subparser("fleet"), "--law")
    assert set(law.choices) == set(PACK_LAWS)
