"""Hostile and malformed input: one line naming the field, exit code 2, never a traceback.

The CLI cases run through ``uam_studio.cli.main`` in this process (the console script's parser, checks
and one-line errors; stdout and stderr captured, warnings included), two of them also as real
subprocesses (``python -m uam_studio.cli``, started together by the module fixture); the library and app
cases call the same functions in-process.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from uam_studio.cli import main
from uam_studio.errors import InputError
from uam_studio.flight import leg_profile
from uam_studio.planning import load_mission, mission_from_json

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "assets" / "example_mission.json"


def _example() -> dict:
    return json.loads(EXAMPLE.read_text())


def _hostile_files(tmp: Path) -> dict[str, Path]:
    """name -> mission file: the hostile JSON of the security probe, and printable-name cases."""
    text = EXAMPLE.read_text()
    files = {
        # 401 digits: parses as an int, too large for a float (OverflowError before the fix)
        "int_401_digits": text.replace('"q_max": 7600.0', '"q_max": 1' + "0" * 400),
        # 5000 digits: more than Python's int-string limit (ValueError before the fix)
        "int_5000_digits": text.replace('"q_max": 7600.0', '"q_max": 1' + "0" * 4999),
        # arrays nested 100 000 deep (RecursionError before the fix)
        "nested_100000": '{"name": ' + "[" * 100_000 + "]" * 100_000 + "}",
    }
    escape = _example()
    escape["destinations"][0]["name"] = "Rich\x1b[31mmond"
    files["escape_in_name"] = json.dumps(escape)
    newline = _example()
    newline["name"] = "Bay\nshuttle"
    files["newline_in_name"] = json.dumps(newline)
    many = _example()  # one more than the 20 a mission may have
    many["destinations"] = [{"name": f"P{k}", "x_km": 10.0 + 8 * k, "y_km": 30.0, "priority": 1, "wind_kts": 0}
                            for k in range(21)]
    files["many_destinations"] = json.dumps(many)
    out = {}
    for name, body in files.items():
        p = tmp / f"{name}.json"
        p.write_text(body)
        out[name] = p
    return out


# name -> (argv after `uam-studio`, field the one-line error must start with)
def _cases(tmp: Path) -> dict[str, tuple[list[str], str]]:
    files = _hostile_files(tmp)
    plan = {name: (["plan", str(p), "--policy", "greedy"], "file" if name.startswith(("int", "nested"))
                   else "destinations" if name.startswith("many") else "")
            for name, p in files.items()}
    plan["int_401_digits"] = (plan["int_401_digits"][0], "battery.q_max")
    plan["escape_in_name"] = (plan["escape_in_name"][0], "destinations[0].name")
    plan["newline_in_name"] = (plan["newline_in_name"][0], "name")
    a_file = tmp / "a_file"
    a_file.write_text("not a folder")
    locked = tmp / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    return {
        **{f"plan_{k}": v for k, v in plan.items()},
        "simulate_int_401": (["simulate", str(files["int_401_digits"]), "--route", "Richmond,vertiport",
                              "--altitudes", "500,500"], "battery.q_max"),
        "train_dqn_out_file": (["train", "dqn", "--out", str(a_file), "--steps", "100000"], "--out"),
        "train_dqn_out_under_file": (["train", "dqn", "--out", str(a_file / "run"), "--steps", "100000"], "--out"),
        "train_dqn_out_zip_under_file": (["train", "dqn", "--out", str(a_file / "a.zip")], "--out"),
        "train_dynaformer_out_file": (["train", "dynaformer", "--out", str(a_file), "--steps", "5"], "--out"),
        "train_dynaformer_no_cuda": (["train", "dynaformer", "--out", str(tmp / "dyn"), "--device", "cuda"],
                                     "device"),
        "train_dynaformer_bad_device": (["train", "dynaformer", "--out", str(tmp / "dyn"), "--device", "tpu"],
                                        "device"),
        # root can write in a 0o500 folder, so this case names --out only for other users; it must
        # in any case not fail after training: it either errors at once or trains the 1 step.
        "train_dqn_out_locked": (["train", "dqn", "--out", str(locked / "run"), "--steps", "64"], "--out?"),
    }


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    if torch.cuda.is_available():
        pytest.skip("the no-CUDA case needs a machine without CUDA")
    tmp = tmp_path_factory.mktemp("tail")
    cases = _cases(tmp)
    started = time.monotonic()
    procs = {name: subprocess.Popen([sys.executable, "-m", "uam_studio.cli", *cases[name][0]],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp)
             for name in AS_SUBPROCESS}
    out = {}
    here = os.getcwd()
    os.chdir(tmp)
    try:
        for name, (argv, _) in cases.items():
            if name in AS_SUBPROCESS:
                continue
            stdout, stderr = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
                code = main(list(argv))
            out[name] = (code, stdout.getvalue(), stderr.getvalue(), time.monotonic() - started)
    finally:
        os.chdir(here)
    for name, p in procs.items():
        stdout, stderr = p.communicate(timeout=300)
        out[name] = (p.returncode, stdout, stderr, time.monotonic() - started)
    return cases, out


# the console script itself, in a process of its own: a hostile file, and a folder it may not write in
AS_SUBPROCESS = ("plan_int_401_digits", "train_dqn_out_locked")


@pytest.mark.parametrize("name", [
    "plan_int_401_digits", "plan_int_5000_digits", "plan_nested_100000", "plan_escape_in_name",
    "plan_newline_in_name", "plan_many_destinations", "simulate_int_401", "train_dqn_out_file",
    "train_dqn_out_under_file", "train_dqn_out_zip_under_file", "train_dynaformer_out_file",
    "train_dynaformer_no_cuda", "train_dynaformer_bad_device"])
def test_cli_bad_input_is_one_line_and_exit_2(runs, name):
    cases, out = runs
    code, stdout, stderr, _ = out[name]
    field = cases[name][1]
    assert code == 2, (name, code, stderr[-2000:])
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr[-2000:]
    assert lines[0].startswith(f"error: {field}"), lines[0]
    assert "\x1b" not in stderr and "\x1b" not in stdout
    assert len(lines[0]) < 400


def test_train_out_checked_before_any_work(runs):
    """`train dqn --out FILE` asks for 100 000 steps and still fails within seconds."""
    _, out = runs
    for name in ("train_dqn_out_file", "train_dqn_out_under_file", "train_dynaformer_out_file"):
        code, _, _, _ = out[name]
        assert code == 2
    # All cases ran in parallel on 2 cores: the whole batch ends long before 100 000 steps could.
    assert max(t for *_, t in out.values()) < 120


def test_unwritable_out_never_loses_the_trained_agent(runs):
    code, stdout, stderr, _ = runs[1]["train_dqn_out_locked"]
    if code == 2:
        assert stderr.startswith("error: --out") and len(stderr.strip().splitlines()) == 1
    else:  # root ignores the folder's mode: the agent was written
        assert code == 0 and "wrote" in stdout, stderr[-2000:]


@pytest.mark.parametrize("body, field", [
    ('{"a": ' + "1" * 401 + "}", "name"),
    ('{"a": ' + "1" * 5000 + "}", "file"),
    ("[" * 100_000 + "]" * 100_000, "file"),
    ("{" * 50_000, "file"),
    ('{"name": "x", "name": "y"}', "file"),
    ("x" * 1_000_001, "file"),
])
def test_library_parser_turns_hostile_json_into_input_error(body, field):
    with pytest.raises(InputError) as err:
        mission_from_json(body)
    assert err.value.field == field and "\n" not in str(err.value) and len(str(err.value)) < 300


def test_big_numbers_name_their_field():
    d = _example()
    d["battery"]["q_max"] = 10 ** 400
    with pytest.raises(InputError) as err:
        mission_from_json(json.dumps(d))
    assert err.value.field == "battery.q_max" and "401-digit number is out of range" in str(err.value)
    d = _example()
    d["destinations"][0]["priority"] = 10 ** 400
    with pytest.raises(InputError) as err:
        mission_from_json(json.dumps(d))
    assert err.value.field == "destinations[0].priority" and len(str(err.value)) < 200


def test_unknown_field_with_escape_is_quoted(tmp_path):
    d = _example()
    d["\x1b[2Jboom"] = 1
    p = tmp_path / "m.json"
    p.write_text(json.dumps(d))
    with pytest.raises(InputError) as err:
        load_mission(p)
    assert "\x1b" not in str(err.value) and "unknown field" in str(err.value)


def test_app_loader_reports_hostile_json_and_keeps_the_mission():
    from uam_studio.app.planner.state import PlannerState

    s = PlannerState()
    before = s.mission
    for body in ('{"a": ' + "1" * 5000 + "}", "[" * 100_000 + "]" * 100_000,
                 EXAMPLE.read_text().replace('"q_max": 7600.0', '"q_max": 1' + "0" * 400)):
        assert not s.load_json(body.encode(), "hostile.json")
        assert s.error.startswith("file hostile.json") or s.error.startswith("battery.q_max"), s.error
        assert "\n" not in s.error and s.mission == before


def test_leg_profile_caps_its_samples():
    with pytest.raises(InputError) as err:
        leg_profile(50.0, 1000.0, 0.0, dt_s=1e-6)
    assert err.value.field == "dt_s" and "at most" in str(err.value)
    assert len(leg_profile(50.0, 1000.0, 0.0, dt_s=0.01).time_s) > 100_000  # fine steps still work


def test_weights_of_nan_are_refused(tmp_path, capsys):
    from uam_studio.dynaformer.artifact import WeightsError, load_artifact

    blob = torch.load(ROOT / "pretrained" / "dynaformer.pt", map_location="cpu", weights_only=True)
    key = next(k for k, v in blob["state_dict"].items() if v.is_floating_point())
    blob["state_dict"][key] = torch.full_like(blob["state_dict"][key], float("nan"))
    bad = tmp_path / "nan.pt"
    torch.save(blob, bad)
    with pytest.raises(WeightsError, match="NaN or inf"):
        load_artifact(bad)
    code = main(["evaluate", "dynaformer", "--weights", str(bad), "--n", "10", "--json"])
    out = capsys.readouterr()
    assert code == 2 and out.err.startswith("error: weights") and "NaN" in out.err
    assert "NaN" not in out.out


def test_mismatched_scenario_note_is_not_doubled(tmp_path, capsys):
    d = _example()
    d["scenario"] = "multi_charge"
    p = tmp_path / "m.json"
    p.write_text(json.dumps(d))
    agent = ROOT / "pretrained" / "dqn_single_charge.zip"
    assert main(["plan", str(p), "--policy", "dqn", "--agent", str(agent)]) == 0
    out = capsys.readouterr().out
    assert "note: note:" not in out and "note: the agent was trained for scenario" in out


def test_every_input_error_crosses_a_process_pool_whole(tmp_path):
    """An InputError raised in a worker process reaches the caller as itself: its class, field and one line."""
    import pickle
    from concurrent.futures import ProcessPoolExecutor

    from uam_studio.battery.real.cmu_data import CellDataError
    from uam_studio.battery.real.nasa_data import NasaDataError
    from uam_studio.dynaformer.artifact import WeightsError
    from uam_studio.flight.profile import InfeasibleLegError

    errors = [InputError("wind_kts", "99 is out of range; allowed [-39, 39] kt"),
              WeightsError(tmp_path / "w.pt", "gone"),
              InfeasibleLegError("distance_km", "too short"), CellDataError(tmp_path / "a.csv", "time_s", "empty"),
              NasaDataError(tmp_path / "b.csv", "voltage_v", "missing")]
    for err in errors:
        back = pickle.loads(pickle.dumps(err))
        assert (type(back), str(back), back.field, back.__dict__) == (type(err), str(err), err.field, err.__dict__)
    with ProcessPoolExecutor(1) as pool, pytest.raises(InputError, match=r"^wind_kts: 99.0 is out of range") as caught:
        pool.submit(leg_profile, 50.0, 1000.0, 99.0).result()
    assert caught.value.field == "wind_kts"
