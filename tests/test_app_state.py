"""The app's state models (no browser, no server): validation, files, replanning, retraining, battery lab.

Planning uses the greedy policy (tens of ms); the retraining cases train for a few hundred steps.
Every test runs with ``UAM_STUDIO_HOME`` in a temporary folder.
"""

from __future__ import annotations

import json
import re
import threading
import time
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from uam_studio.app.battery_lab.state import BatteryLabState
from uam_studio.app.planner.mission import EXAMPLE_MISSION
from uam_studio.app.planner.state import PlannerState
from uam_studio.app.retrain.state import RetrainState
from uam_studio.app.services import population, registry
from uam_studio.planning import load_mission, mission_from_dict
from uam_studio.planning.agents.retrain import (
    agents_dir,
    is_bundled,
    list_agents,
    new_agent_path,
    retrain_dqn,
    training_setup,
    user_home,
)
from uam_studio.planning.missions.mission import Battery

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "assets" / "example_mission.json"


@pytest.fixture(autouse=True)
def home(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("UAM_STUDIO_HOME", str(tmp_path / "home"))
    registry().refresh()
    yield tmp_path / "home"
    registry().refresh()


def _state(**kw) -> PlannerState:
    s = PlannerState(**kw)
    if s.policy in ("attention", "dqn") and kw.get("policy") is None:
        s.apply(policy="greedy")
    return s


def _rows(s: PlannerState) -> list[dict]:
    return s.destination_rows()


# ----------------------------------------------------------------------------- planning state


def test_example_matches_the_bundled_file_and_plans():
    assert mission_from_dict(EXAMPLE_MISSION) == load_mission(EXAMPLE)
    s = _state()
    assert s.plan is not None and s.plan_error == "" and s.error == ""
    names = {d.name for d in s.destinations}
    assert s.plan["route"] and set(s.plan["route"]) <= names | {"vertiport"}
    assert s.plan_request.mission == s.mission
    assert s.health is not None and len(s.health) == 2


def test_slider_change_replans_with_the_new_cell():
    s = _state()
    before = s.plan_count
    assert s.apply(r0=0.2, q_max=6000)
    assert s.plan_count == before + 1  # one replan for a batch of changes
    assert s.plan_request.mission.battery.r0 == 0.2 and s.plan_request.mission.battery.q_max == 6000
    assert s.plan["route"] and s.plan["min_voltage_v"] is not None


def test_the_state_holds_one_mission_built_once_per_accepted_edit():
    s = _state()
    m = s.mission
    assert s.mission is m and s.mission is m  # every read is the same value, none rebuilt
    assert s.plan_request.mission == m  # (the plan cache may answer with an equal request of another state)
    assert not s.apply(q_max=1.0) and s.mission is m  # a refused edit keeps it
    assert s.apply(q_max=6000.0, r0=0.2)
    assert s.mission is not m and s.mission.battery.q_max == 6000.0 and s.mission.battery.r0 == 0.2
    assert s.plan_request.mission == s.mission  # the replan read the new one
    assert s.load_json(s.to_json().replace('"Bay shuttle"', '"Another"'), "x.json")
    assert s.mission.name == "Another" and s.mission_name == "Another"
    s.reset_example()
    assert s.mission == mission_from_dict(EXAMPLE_MISSION)


@pytest.mark.parametrize("change, field, allowed", [
    ({"r0": 0.9}, "r0", "[0.017, 0.45]"),
    ({"q_max": 100.0}, "q_max", "[5000, 8000]"),
    ({"eod_v": 5.0}, "eod_v", "[2.5, 3.5]"),
    ({"return_wind": 60}, "return_wind", "[-39, 39]"),
    ({"policy": "astar"}, "policy", "greedy"),
    ({"scenario": "tour"}, "scenario", "single_charge"),
])
def test_out_of_range_is_a_message_and_keeps_the_mission(change, field, allowed):
    s = _state()
    mission, count = s.mission, s.plan_count
    assert not s.apply(**change)
    assert s.error.startswith(field) and allowed in s.error and "\n" not in s.error
    assert s.mission == mission and s.plan_count == count
    assert s.apply(r0=0.2) and s.error == ""  # the next good edit clears the message


def test_zero_and_too_many_destinations_are_refused():
    s = _state()
    mission = s.mission
    assert not s.set_destinations([])
    assert "at least 1 destination" in s.error and s.mission == mission
    rows = [{"name": f"P{k}", "x_km": -150.0 + 8 * k, "y_km": 30.0, "priority": 1, "wind_kts": 0}
            for k in range(21)]
    assert not s.set_destinations(rows)
    assert s.error == "destinations: 21 destinations; allowed 1 to 20" and s.mission == mission
    assert s.set_destinations(rows[:20]) and len(s.destinations) == 20 and s.error == ""


def test_new_map_point_gets_a_name_and_priority():
    s = _state()
    rows = _rows(s) + [{"name": None, "x_km": 30.04, "y_km": 29.96, "priority": 0, "wind_kts": float("nan"),
                        "dwell_s": None}]
    assert s.set_destinations(rows), s.error
    d = s.destinations[-1]
    assert (d.name, d.x_km, d.y_km, d.priority, d.wind_kts, d.dwell_s) == ("D1", 30.0, 30.0, 1, 0.0, 0.0)
    # a second new point takes the next free name
    assert s.set_destinations(_rows(s) + [{"x_km": -30.0, "y_km": 10.0}])
    assert s.destinations[-1].name == "D2"


def test_table_edits_priority_and_wind_replan():
    s = _state()
    rows = _rows(s)
    rows[0]["priority"] = 3
    rows[1]["wind_kts"] = -30.0
    count = s.plan_count
    assert s.set_destinations(rows)
    assert s.destinations[0].priority == 3 and s.destinations[1].wind_kts == -30.0
    assert s.plan_count == count + 1
    assert s.set_destinations(_rows(s)) and s.plan_count == count + 1  # unchanged rows: no replan


@pytest.mark.parametrize("key, value, expect", [
    ("wind_kts", 50.0, "destinations[1] (Hayward).wind_kts: 50.0 is out of range; allowed [-39, 39] kt"),
    ("priority", 4, "destinations[1] (Hayward).priority: 4 is out of range; allowed [1, 3]"),
    ("x_km", 500.0, "destinations[1] (Hayward).x_km"),
    ("name", "vertiport", "reserved for the vertiport"),
    ("name", "Richmond", "already used"),
])
def test_bad_row_values_name_the_field(key, value, expect):
    s = _state()
    mission = s.mission
    rows = _rows(s)
    rows[1][key] = value
    assert not s.set_destinations(rows)
    assert expect in s.error and s.mission == mission


def test_json_round_trip_in_the_cli_format(tmp_path):
    s = _state()
    assert s.apply(q_max=6000.0, r0=0.2, eod_v=3.1, return_wind=-5.0, scenario="multi_charge")
    text = s.to_json()
    p = tmp_path / "m.json"
    p.write_text(text)
    assert load_mission(p) == s.mission  # the CLI's reader
    t = _state()
    assert t.load_json(text.encode(), "m.json") and t.error == ""
    assert t.mission == s.mission and "loaded m.json" in t.notice


@pytest.mark.parametrize("content, expect", [
    (b"{not json", "file bad.json: is not valid JSON"),
    (b"", "file bad.json: is empty"),
    (b"\xff\xfe", "not UTF-8"),
    (json.dumps({**EXAMPLE_MISSION, "destinations": []}).encode(), "at least 1 destination"),
    (json.dumps({**EXAMPLE_MISSION, "battery": {"q_max": 7600, "r0": 0.9}}).encode(), "r0"),
    (json.dumps({**EXAMPLE_MISSION, "eod_v": "3"}).encode(), "eod_v"),
    (json.dumps({**EXAMPLE_MISSION, "extra": 1}).encode(), "extra: unknown field"),
    (json.dumps([1, 2]).encode(), "expected a JSON object"),
    (b'{"name": "a", "name": "b"}', "duplicate key"),
])
def test_invalid_file_is_a_message_and_keeps_the_mission(content, expect):
    s = _state()
    assert s.apply(r0=0.25)
    mission = s.mission
    assert not s.load_json(content, "bad.json")
    assert s.error.startswith("file bad.json") and expect in s.error and "\n" not in s.error
    assert s.mission == mission


def test_too_many_destinations_in_a_file():
    d = dict(EXAMPLE_MISSION)
    d["destinations"] = [{"name": f"P{k}", "x_km": -150.0 + 8 * k, "y_km": 30.0, "priority": 1, "wind_kts": 0}
                         for k in range(21)]
    s = _state()
    assert not s.load_json(json.dumps(d), "many.json")
    assert s.error == "file many.json: destinations: 21 destinations; allowed 1 to 20"
    d["destinations"] = d["destinations"][:20]
    assert s.load_json(json.dumps(d), "twenty.json") and len(s.destinations) == 20


def test_reset_example():
    s = _state()
    assert s.set_destinations(_rows(s)[:1])
    s.reset_example()
    assert s.mission == mission_from_dict(EXAMPLE_MISSION)


def test_missing_bundled_agent_is_a_visible_error(monkeypatch, tmp_path):
    import uam_studio.bundled as bundled

    monkeypatch.setattr(bundled, "package_dir", lambda: tmp_path)  # an install without the agents
    s = _state()
    assert s.policy == "greedy"  # no bundled agent: greedy is the default planner
    assert s.apply(policy="dqn")
    assert s.plan_error.startswith("agent: bundled agent dqn_single_charge.zip is not installed")
    assert s.plan is None
    assert s.apply(policy="attention")
    assert s.plan_error.startswith("agent: bundled agent attention_planner.pt is not installed")
    assert s.plan is None and "\n" not in s.plan_error
    assert list(s.policy_objects.items())[0] == ("Attention (not installed)", "attention")  # no false promise


def test_the_attention_planner_is_the_first_and_default_policy():
    from uam_studio.app.planner.summary import summary_html

    s = PlannerState()
    assert s.policy == "attention" and s.plan_error == ""
    assert list(s.policy_objects.items())[:2] == [("Attention (bundled, default)", "attention"),
                                                   ("DQN (paper, up to 8)", "dqn")]
    assert s.plan["policy"] == "attention" and s.plan["safe"] and s.plan["reached_priority"] == 6
    assert "<b>Policy:</b> Attention (bundled, default)" in summary_html(s)
    s.close()


def _spread_rows(n: int) -> list[dict]:
    """``n`` destinations 15-40 km out, spread around the vertiport, priorities 1-3."""
    return [{"name": f"P{k + 1}", "x_km": round((15 + 25 * (k % 5) / 4) * np.cos(2.4 * k), 1),
             "y_km": round((15 + 25 * (k % 5) / 4) * np.sin(2.4 * k), 1), "priority": 1 + k % 3,
             "wind_kts": float(5 * (k % 4) - 5), "dwell_s": 0.0} for k in range(n)]


def test_twenty_destinations_plan_safely_with_the_default_policy():
    from uam_studio.app.planner.summary import summary_html

    s = PlannerState()
    assert s.set_destinations(_spread_rows(20)), s.error
    assert s.policy == "attention" and len(s.plan_request.mission.destinations) == 20
    assert s.plan_error == "" and s.plan["policy"] == "attention" and s.plan["exact"] is None
    assert s.plan["safe"] and s.plan["reached"] and s.plan["route"][-1] == "vertiport"
    v = s.verdict()
    assert v["physics_margin_v"] >= 0 and v["level"] in ("safe", "uncertain", "disagree")
    html = summary_html(s)
    assert "<b>Policy:</b> Attention (bundled, default)" in html and "Planning error" not in html
    assert f"of 20 (priority {s.plan['reached_priority']})" in html
    s.close()


def test_dqn_past_eight_destinations_is_a_one_line_error_naming_8():
    from uam_studio.app.planner.summary import summary_html

    s = PlannerState(policy="dqn")
    assert s.plan_error == "" and s.plan["policy"] == "dqn"
    assert s.set_destinations(_spread_rows(9)), s.error  # the mission itself is fine (up to 20)
    assert s.error == "" and s.plan is None
    assert s.plan_error == "destinations: 9 destinations; the dqn policy plans at most 8 (allowed 1 to 8)"
    assert "<b>Planning error:</b> destinations: 9 destinations; the dqn policy plans at most 8" in summary_html(s)
    assert s.apply(policy="attention") and s.plan_error == "" and s.plan["safe"]  # the default plans it
    s.close()


def test_the_oracle_says_whether_its_plan_is_exact_or_the_reference_solvers():
    from uam_studio.app.planner.summary import summary_html

    s = PlannerState(policy="oracle")
    assert s.plan["exact"] is True and s.plan_label() == "Oracle (exact optimum)"
    assert s.set_destinations(_spread_rows(9)), s.error
    assert s.plan_error == "" and s.plan["exact"] is False and s.plan["safe"]
    assert s.plan_label() == "Oracle: the reference solver's plan (OR-Tools), not proven optimal"
    assert f"<b>Policy:</b> {s.plan_label()}" in summary_html(s).replace("&#x27;", "'")
    s.close()


def test_background_replanning_keeps_only_the_latest():
    applied = []

    def dispatch(cb):  # what the server does: hand the result to the session's thread
        applied.append(threading.current_thread().name)
        cb()

    s = PlannerState(background=True, dispatch=dispatch, policy="greedy")
    assert s.wait_idle(60)
    for r0 in (0.05, 0.1, 0.15, 0.2, 0.25):
        s.apply(r0=r0)
    assert s.wait_idle(60) and not s.busy
    assert s.plan_request.mission.battery.r0 == 0.25  # the last request wins
    assert s.plan_count <= 6 and all(n.startswith("uam-plan") for n in applied)


# ----------------------------------------------------------------------------- user folder, agents


def test_user_folder_from_env(home):
    assert user_home() == home and agents_dir() == home / "agents"
    p = new_agent_path("single_charge", "map")
    assert p.parent == home / "agents" and p.suffix == ".zip" and not is_bundled(p)
    assert is_bundled(ROOT / "pretrained" / "x.zip")
    assert list_agents() == []


def test_retrain_into_pretrained_is_refused():
    cfg, env_fn = training_setup(steps=10)
    with pytest.raises(Exception, match="pretrained"):
        retrain_dqn(cfg, env_fn, ROOT / "pretrained" / "refused.zip")
    assert not (ROOT / "pretrained" / "refused.zip").exists()


def test_a_dqn_run_stopped_before_its_first_episode_saves_nothing(home):
    """An agent that finished no episode learned nothing: no file, no card, nothing in the agent list."""
    import threading

    cfg, env_fn = training_setup(steps=500)
    stop = threading.Event()
    stop.set()
    path = new_agent_path("single_charge", "random")
    assert retrain_dqn(cfg, env_fn, path, stop_event=stop) is None
    assert not path.exists() and list(path.parent.glob("*")) == [] and list_agents() == []


def test_training_setup_safe_return_reaches_the_env_and_the_card():
    for flag in (False, True):
        cfg, env_fn = training_setup(steps=10, safe_return=flag)
        assert cfg.safe_return is flag and cfg.to_dict()["safe_return"] is flag
        assert env_fn().safe_return is flag


@pytest.mark.parametrize("kw, field", [({"alpha": -1}, "alpha"), ({"steps": 0}, "steps"),
                                       ({"scenario": "tour"}, "scenario")])
def test_training_setup_errors(kw, field):
    from uam_studio.errors import InputError

    with pytest.raises(InputError) as err:
        training_setup(**kw)
    assert err.value.field == field


def test_retrain_state_trains_saves_and_the_planner_can_use_it(home):
    planner = _state()
    rs = RetrainState(source="map", scenario="single_charge", steps=300, seed=1)  # in a child process
    assert rs.runner == "process"
    assert rs.start(planner.mission), rs.error
    assert rs.running and not rs.start(planner.mission)  # one run at a time
    assert "already going" in rs.error
    rs.join(120)
    rows = rs.poll()
    assert not rs.running and rs.error == "" and rs.timesteps >= 300
    assert rows and rs.episodes == len(rows) and rows[-1]["episode"] == len(rows)
    assert set(rows[0]) == {"episode", "reached", "cycles", "reward", "breach", "reached_ma", "cycles_ma",
                            "reward_ma", "breach_ma"}
    assert all(r["breach"] in (0.0, 1.0) and 0.0 <= r["breach_ma"] <= 1.0 for r in rows)
    n = min(len(rows), RetrainState.MA_WINDOW)  # the moving average is the mean of the last episodes
    assert rows[n - 1]["reward_ma"] == pytest.approx(sum(r["reward"] for r in rows[:n]) / n)
    path = Path(rs.agent_path)
    assert path.parent == home / "agents" and path.is_file() and "saved" in rs.status
    card = json.loads(zipfile.ZipFile(path).read("card.json"))
    assert card["source"] == "app" and card["env"]["mission"]["name"] == planner.mission.name
    assert card["stopped_early"] is False and card["final_stats"]["timesteps"] >= 300

    registry().refresh()
    value = f"agent:{path}"
    assert value in planner.policy_objects.values()
    assert planner.apply(policy=value), planner.error
    assert planner.plan_error == "" and planner.plan["policy"] == "dqn" and planner.plan["route"]
    from uam_studio.app.planner.summary import summary_html

    label = planner.policy_label(value)
    assert label.startswith("Retrained: ") and path.stem in label and str(path) not in label
    assert re.search(r"\(DQN, \d+ steps, ", label), label  # what it learned, from its card
    assert f"<b>Policy:</b> {label}" in summary_html(planner)  # its label, never the file path
    planner.close()


def test_retrain_state_fine_tunes_the_bundled_agent(home):
    """Start from the bundled agent: the child process fine-tunes pretrained/dqn_<scenario>.zip
    (recorded in the card, exploration from epsilon 0.2) and never writes over it."""
    bundled = ROOT / "pretrained" / "dqn_single_charge.zip"
    before = bundled.read_bytes()
    planner = _state()
    rs = RetrainState(source="map", scenario="single_charge", steps=300, seed=2, start_from="bundled")
    assert rs.start(planner.mission), rs.error
    assert rs.status.startswith("fine-tuning the bundled agent 300 steps")
    rs.join(120)
    rs.poll()
    assert not rs.running and rs.error == "" and rs.timesteps >= 300
    card = json.loads(zipfile.ZipFile(rs.agent_path).read("card.json"))
    assert card["config"]["init_agent"] == str(bundled)
    assert card["config"]["exploration_initial_eps"] == pytest.approx(0.2)
    assert Path(rs.agent_path).parent == home / "agents" and bundled.read_bytes() == before
    planner.close()


def test_retrain_stop_saves_the_agent_so_far(home):
    rs = RetrainState(source="random", steps=200_000, runner="thread")
    assert rs.start(None), rs.error
    while rs.running and rs.episodes < 3:
        rs.poll()
        rs.join(0.2)
    rs.stop()
    rs.join(60)
    rs.poll()
    assert not rs.running and rs.status.startswith("stopped") and rs.timesteps < 200_000
    card = json.loads(zipfile.ZipFile(rs.agent_path).read("card.json"))
    assert card["stopped_early"] is True and card["env"]["mission"] is None


def test_retrain_process_reports_a_failure_in_the_child(home):
    from uam_studio.planning.agents.retrain import RetrainProcess

    blocker = home / "not_a_folder"
    blocker.parent.mkdir(parents=True, exist_ok=True)
    blocker.write_text("a file where the agents folder should be")
    proc = RetrainProcess(blocker / "agent.zip", steps=100, seed=0)
    proc.start()
    proc.join(180)
    episodes = proc.poll()
    assert proc.finished and proc.result is None and episodes
    assert proc.error.startswith(("FileExistsError", "NotADirectoryError")), proc.error


def test_stop_before_the_first_episode_ends_the_child_at_once_and_saves_nothing(home):
    """The child may still be importing torch (seconds on a busy machine): Stop does not wait for it."""
    from uam_studio.planning.agents.retrain import RetrainProcess

    path = home / "agents" / "early.zip"
    proc = RetrainProcess(path, steps=5000, seed=0)
    proc.start()
    t0 = time.monotonic()
    proc.stop()
    assert time.monotonic() - t0 < 6.0 and proc.finished and proc.result is None and proc.error is None
    assert not proc._proc.is_alive() and not path.exists()


def test_retrain_on_a_bad_map_is_a_message():
    planner = _state()
    assert planner.set_destinations([{"name": "Near", "x_km": 2.0, "y_km": 1.0, "priority": 1, "wind_kts": 0}])
    rs = RetrainState(source="map")
    assert not rs.start(planner.mission)
    assert rs.error.startswith("training (current map)") and "too close" in rs.error and not rs.running


def test_list_agents_skips_files_that_are_not_agents(home):
    d = home / "agents"
    d.mkdir(parents=True)
    (d / "junk.zip").write_bytes(b"not a zip")
    with zipfile.ZipFile(d / "other.zip", "w") as zf:
        zf.writestr("card.json", json.dumps({"model": "dynaformer"}))
    assert list_agents() == []


# ----------------------------------------------------------------------------- battery lab, health


@pytest.mark.parametrize("vary", ["altitude", "wind", "R0", "q_max"])
def test_battery_lab_families(vary):
    lab = BatteryLabState(vary=vary, legs=4)
    c = lab.curves()
    assert c["error"] == "" and len(c["setting"]) == 1 and len(c["family"]) >= 4
    for curve in c["family"] + c["setting"]:
        assert curve["current_a"].size == curve["time_s"].size <= BatteryLabState.MAX_POINTS + 1
        assert curve["voltage_time_s"].size == curve["voltage_v"].size > 0
        assert np.all(np.isfinite(curve["voltage_v"]))
        assert curve["eod_s"] is None or np.isfinite(curve["eod_s"])  # never NaN: "nan min" in the table
        # the flight ends at the cut-off: no current drawn after it, so no curve stretches the time axis
        assert curve["time_s"][-1] == curve["voltage_time_s"][-1]
        if curve["eod_s"] is not None:
            assert curve["time_s"][-1] <= curve["eod_s"] + 1.0
    assert c["t_end_s"] == max(float(cv["time_s"][-1]) for cv in c["family"] + c["setting"])
    values = [cv["value"][{"altitude": "altitude_m", "wind": "wind_kts", "R0": "r0", "q_max": "q_max"}[vary]]
              for cv in c["family"]]
    assert values == sorted(values)  # the legend's order: ascending numbers, not text


def test_battery_lab_curve_that_never_reaches_eod_has_its_lowest_voltage():
    c = BatteryLabState(vary="altitude", legs=3).curves()
    low = [cv for cv in c["family"] if cv["label"] == "altitude 500 m"][0]
    assert low["eod_s"] is None and 3.0 < low["min_voltage_v"] < 3.6


def test_battery_lab_in_the_background_keeps_the_newest_and_flags_busy():
    applied = []
    lab = BatteryLabState(background=True, dispatch=lambda cb: (applied.append(1), cb()))
    for r0 in (0.1, 0.2, 0.3):
        lab.r0 = r0
    deadline = time.monotonic() + 60
    while lab.busy and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not lab.busy and lab.result["setting"][0]["value"]["r0"] == 0.3


def test_battery_lab_r0_shortens_the_flight_and_short_legs_are_skipped():
    lab = BatteryLabState(vary="R0", legs=10)
    eods = [c["eod_s"] for c in lab.curves()["family"]]
    assert all(e is not None for e in eods) and eods == sorted(eods, reverse=True)
    lab = BatteryLabState(vary="altitude", distance_km=12.0, altitude_m=500.0)
    c = lab.curves()
    assert c["error"] == "" and c["skipped"] and "too short" in c["skipped"][0]
    lab.altitude_m = 3000.0
    assert "too short" in lab.curves()["error"]


def test_health_population_is_cached_and_pc1_tracks_r0():
    pop = population()
    assert pop is population() and len(pop) == 300
    assert abs(np.corrcoef(pop.pc1, pop.r0)[0, 1]) > 0.9


def test_plans_are_cached_across_sessions_and_copies_are_independent():
    from uam_studio.app.planner.plans import PlanRequest, compute_plan

    req = PlanRequest(mission_from_dict({**EXAMPLE_MISSION, "name": "Cache check"}), "greedy")
    first = compute_plan(req)
    again = compute_plan(req)
    assert first["error"] is None and not first["cached"] and again["cached"]
    assert again["plan"] == first["plan"] and again["health"] == first["health"]
    again["plan"]["route"].append("mutated")  # a session's copy never leaks into the cache
    assert compute_plan(req)["plan"]["route"] == first["plan"]["route"]
    other = PlanRequest(mission_from_dict({**EXAMPLE_MISSION, "name": "Cache check", "eod_v": 3.1}), "greedy")
    assert not compute_plan(other)["cached"]  # any input change is a new plan


def test_cached_dqn_plan_is_not_reused_for_another_agent_file(monkeypatch, tmp_path):
    import uam_studio.bundled as bundled
    from uam_studio.app.planner.plans import PlanRequest, compute_plan

    req = PlanRequest(mission_from_dict({**EXAMPLE_MISSION, "name": "Agent stamp"}), "dqn")
    assert compute_plan(req)["plan"]["route"]
    monkeypatch.setattr(bundled, "package_dir", lambda: tmp_path)  # the bundled agent is gone
    res = compute_plan(req)
    assert not res["cached"] and res["plan"] is None
    assert res["error"].startswith("agent: bundled agent dqn_single_charge.zip is not installed")


def test_planning_activity_keeps_training_paused_for_a_grace_period():
    from uam_studio.app.services import PlanningActivity

    act = PlanningActivity(grace_s=0.3)
    ev = act.event
    act.mark(1, True)
    act.mark(2, True)
    assert ev.is_set()
    act.mark(1, False)
    assert ev.is_set()  # session 2 still plans
    act.mark(2, False)
    assert ev.is_set()  # grace: the changes are still being sent and drawn
    time.sleep(0.6)
    assert not ev.is_set()
    act.mark(3, True)
    act.mark(3, False)
    act.mark(3, True)  # a new plan inside the grace period keeps it set
    time.sleep(0.6)
    assert ev.is_set()
    act.mark(3, False)
    time.sleep(0.6)
    assert not ev.is_set()


def test_warm_up_plans_what_a_new_session_shows_first():
    from uam_studio.app.planner.plans import compute_plan
    from uam_studio.app.serve import warm_up

    warm_up(compare="off")
    s = PlannerState(auto=False)
    res = compute_plan(s.request())
    assert res["cached"] and res["error"] is None and res["plan"]["route"]
    s.close()


def test_training_setup_init_agent_sets_fine_tuning(tmp_path):
    from uam_studio.errors import InputError
    from uam_studio.planning.agents.dqn.training import FINE_TUNE

    agent = ROOT / "pretrained" / "dqn_single_charge.zip"
    cfg, _ = training_setup(steps=10, init_agent=agent)
    assert cfg.init_agent == str(agent) and cfg.to_dict()["init_agent"] == str(agent)
    assert all(getattr(cfg, k) == v for k, v in FINE_TUNE.items())
    plain, _ = training_setup(steps=10)
    assert plain.init_agent is None and plain.exploration_initial_eps == 1.0
    with pytest.raises(InputError) as err:
        training_setup(steps=10, init_agent=tmp_path / "missing.zip")
    assert err.value.field == "init_agent" and "not found" in str(err.value)


# ----------------------------------------------------------------------------- verdict, band, comparison


def test_band_is_the_predictions_band_and_the_verdict_names_both_sources():
    s = _state()
    band = s.band
    assert band is not None and band["level"] == 0.9
    pred = np.asarray(s.plan["predicted"]["voltage_v"])
    lo, hi = np.asarray(band["low_v"]), np.asarray(band["high_v"])
    assert lo.shape == hi.shape == pred.shape and np.all(lo <= pred + 1e-3) and np.all(pred <= hi + 1e-3)
    v = s.verdict()
    assert v["level"] == "safe" and re.fullmatch(
        r"physics: safe by 0\.\d\d V; predicted: safe by 0\.\d\d V \(90%: \+0\.\d\d V to \+0\.\d\d V\)", v["text"]), v
    assert v["physics_margin_v"] == pytest.approx(s.plan["min_voltage_v"] - 3.0)
    s.close()


def test_verdict_disagrees_where_physics_is_safe_and_the_dynaformer_is_not():
    """R0 0.246 ohm with the bundled DQN agent: +0.006 V on physics, below EOD on the Dynaformer."""
    s = PlannerState(policy="dqn")
    assert s.apply(r0=0.246)
    v = s.verdict()
    assert s.plan["safe"] and v["physics_margin_v"] > 0 > v["predicted_margin_v"]
    assert v["level"] == "disagree" and "physics safe, Dynaformer below EOD" in v["headline"]
    assert "physics: safe by 0.006 V" in v["text"] and "predicted: below EOD by" in v["text"]
    s.close()


def test_failed_takeoff_has_its_voltage_trace_and_an_unsafe_verdict():
    s = _state()
    assert s.apply(r0=0.45)
    assert s.plan["route"] == [] and s.band is None
    t = s.takeoff
    assert t is not None and len(t["time_s"]) == len(t["voltage_v"]) > 5 and t["voltage_v"][-1] < 3.0
    v = s.verdict()
    assert v["level"] == "unsafe" and "cannot take off" in v["headline"] and f"{t['eod_s']:.0f} s" in v["text"]
    assert s.apply(r0=0.117215) and s.takeoff is None and s.band is not None
    s.close()


def test_comparison_inline_names_the_planners_and_the_gap_to_the_oracle():
    from uam_studio.app.planner.comparison import comparison_table

    s = PlannerState(compare="inline")  # the attention planner, as the served app starts
    rows = {r["key"]: r for r in comparison_table(s.comparison)}
    assert [r["label"] for r in comparison_table(s.comparison)] == \
        ["Attention (default)", "DQN (paper)", "Greedy", "Oracle (exact)"]
    assert all(r["status"] == "done" for r in rows.values())
    assert (rows["agent"]["priority"], rows["greedy"]["priority"], rows["oracle"]["priority"]) == (6, 6, 6)
    assert rows["agent"]["gap"] == "matches" and rows["greedy"]["gap"] == "matches"
    assert rows["paper"]["priority"] == 5 and rows["paper"]["gap"] == "-1 priority (-17%)"  # the paper's beside ours
    assert rows["agent"]["route"] == s.plan["route"]  # the same library call as the shown plan
    assert not s.comparison_pending()
    before = s.comparison
    assert s.apply(policy="greedy") and s.comparison is before  # same mission and agent: same rows
    assert s.apply(policy="dqn")  # the paper's DQN takes the agent row
    rows = {r["key"]: r for r in comparison_table(s.comparison)}
    assert "paper" not in rows  # the agent row is the paper's DQN already
    assert rows["agent"]["label"] == "DQN (paper)" and rows["agent"]["priority"] == 5
    assert rows["agent"]["gap"] == "-1 priority (-17%)" and rows["agent"]["route"] == s.plan["route"]
    assert s.set_destinations(_spread_rows(9)), s.error  # past 8: the DQN's row is its error
    rows = {r["key"]: r for r in comparison_table(s.comparison)}
    assert rows["agent"]["status"] == "error" and "at most 8" in rows["agent"]["error"]
    assert rows["oracle"]["label"] == "Oracle (reference)" and rows["oracle"]["exact"] is False
    assert rows["oracle"]["gap"] == "reference"
    from uam_studio.app.planner.summary import comparison_html

    assert "oracle: the reference solver's plan, not proven optimal" in comparison_html(s)
    assert rows["greedy"]["status"] == "done" and rows["greedy"]["gap"]
    s.close()


def test_comparison_marks_where_the_papers_dqn_cannot_run():
    from uam_studio.app.planner.comparison import comparison_table
    from uam_studio.app.planner.summary import comparison_html

    s = PlannerState(compare="inline")
    assert s.set_destinations(_spread_rows(9)), s.error
    rows = {r["key"]: r for r in comparison_table(s.comparison)}
    assert rows["paper"]["status"] == "unavailable" and rows["paper"]["gap"] == ""
    assert rows["paper"]["error"] == "the paper's DQN holds at most 8 destinations"
    assert not s.comparison_pending() and rows["agent"]["status"] == "done"
    html = comparison_html(s)
    assert "the paper&#x27;s DQN holds at most 8 destinations" in html and "color:#b71c1c" not in html
    s.close()


@pytest.mark.parametrize("policy, keys", [
    ("attention", ["agent", "paper", "greedy", "oracle"]),
    ("dqn", ["agent", "default", "greedy", "oracle"]),
    ("greedy", ["agent", "paper", "greedy", "oracle"]),
])
def test_comparison_always_shows_the_default_planner_and_the_papers_dqn(policy, keys):
    """Choosing the paper's DQN keeps the default attention planner's row: the two side by side."""
    from uam_studio.app.planner.comparison import comparison_table

    s = PlannerState(compare="inline", policy=policy)
    rows = comparison_table(s.comparison)
    assert [r["key"] for r in rows] == keys
    labels = [r["label"] for r in rows]
    assert "Attention (default)" in labels and "DQN (paper)" in labels, labels
    assert {r["status"] for r in rows} == {"done"}
    s.close()


def test_comparison_in_a_thread_waits_for_the_plan_to_settle_and_keeps_the_newest():
    from uam_studio.app.planner.comparison import comparison_runner

    s = PlannerState(compare="thread", policy="greedy")
    for r0 in (0.15, 0.16, 0.17):
        s.apply(r0=r0)
    assert s.comparison_pending()
    runner = comparison_runner("thread")
    deadline = time.monotonic() + 120
    while s.comparison_pending() and time.monotonic() < deadline:
        runner.wait_idle(1.0)
    assert not s.comparison_pending() and "r0=0.17;" in s.comparison["inputs"]
    assert {r["status"] for r in s.comparison["rows"].values()} == {"done"}
    s.close()


def test_comparison_in_a_child_process():
    from uam_studio.app.planner.comparison import ComparisonRunner, compare_row
    from uam_studio.app.planner.plans import PlanRequest

    runner = ComparisonRunner("process")
    mission = mission_from_dict({**EXAMPLE_MISSION, "name": "Child"})
    got = []
    runner.submit("t", [(PlanRequest(mission, "oracle"), got.append), (PlanRequest(mission, "dqn"), got.append)])
    assert runner.wait_idle(300)
    assert [r["status"] for r in got] == ["done", "done"] and got[0]["priority"] == 6
    assert {k: v for k, v in got[1].items() if k != "elapsed_s"} == \
        {k: v for k, v in compare_row(mission, "dqn").items() if k != "elapsed_s"}
    runner.submit("t", [(PlanRequest(mission, "bogus"), got.append)])
    assert runner.wait_idle(60) and got[-1]["status"] == "error" and "bogus" in got[-1]["error"]
    runner._proc.terminate()


def test_a_closed_comparison_runner_starts_no_process():
    """The server's last step closes the runners (``serve``): a task that comes after gets an error row,
    not kept for other sessions, and no comparison process is started while the server exits."""
    import multiprocessing

    from uam_studio.app.planner.comparison import ComparisonRunner, cached_row
    from uam_studio.app.planner.plans import PlanRequest

    before = {p.pid for p in multiprocessing.active_children()}  # an earlier test's child may be ending
    runner = ComparisonRunner("process")
    runner.close()
    runner.start()
    mission = mission_from_dict({**EXAMPLE_MISSION, "name": "Closed"})
    got = []
    runner.submit("t", [(PlanRequest(mission, "greedy"), got.append)])
    assert runner.wait_idle(30)
    assert [r["status"] for r in got] == ["error"] and "server is stopping" in got[0]["error"], got
    assert [p for p in multiprocessing.active_children() if p.pid not in before] == []
    assert cached_row(PlanRequest(mission, "greedy")) is None


def test_retrain_progress_text_and_oracle_reference():
    planner = _state()
    rs = RetrainState(source="map", compare="inline", runner="thread", steps=200)
    assert rs.progress_text() == "not started"
    rs.request_reference(planner.mission)
    ref = rs.reference
    assert ref["status"] == "done" and ref["reached"] == 3 and ref["cycles"] == 1 and "q_max 7600 C" in ref["cell"]
    assert rs.start(planner.mission), rs.error
    rs.join(120)
    rs.poll()
    text = rs.progress_text()
    assert text.startswith(f"{rs.timesteps} of 200 steps (100%)") and "elapsed" in text and "left" not in text
    assert rs.status.startswith("done: ") and rs.episodes > 0
    rs.model = "attention"  # the DQN run's status, counts and clock do not stay beside the other planner
    assert (rs.status, rs.episodes, rs.timesteps, rs.progress_text()) == ("", 0, 0, "not started")
    rs.source = "random"
    rs.request_reference(None)
    assert rs.reference is None
    planner.close()


def test_a_background_session_shows_a_known_first_plan_at_once_and_plans_a_new_one_in_the_pool():
    """Served (``background=True``), a session whose first plan is cached (the server's warm-up planned the
    example mission) is built with it: no busy state, nothing sent after the page. A first plan never seen is
    planned in the pool, busy until it lands, and equals the plan computed in place."""
    PlannerState().close()  # the example mission planned in place: now in the shared cache
    # a cell no other test plans: not in the shared cache yet
    unseen_mission = replace(mission_from_dict(EXAMPLE_MISSION), battery=Battery(7400.0, 0.0917))
    in_place = PlannerState(unseen_mission, auto=False)
    fresh = in_place.request()
    known = PlannerState(background=True)
    try:
        assert known.plan is not None and not known.busy and known.plan_count == 1
    finally:
        known.close()
    unseen = PlannerState(unseen_mission, background=True)
    try:
        assert unseen.request() == fresh
        assert unseen.busy and unseen.plan is None  # planning in the pool (tens of ms at least)
        assert unseen.wait_idle(120) and not unseen.busy and unseen.plan is not None
        assert unseen.plan == in_place.replan()["plan"]
    finally:
        unseen.close()
        in_place.close()
