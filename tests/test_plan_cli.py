"""Tests for ``uam-studio plan``, ``uam-studio train dqn`` and :func:`uam_studio.planning.planner.plan_mission`.

Everything runs in-process through ``main()`` (one interpreter start-up for the whole file); the
DQN agent is trained once per module for 300 transitions (no gradient step: it only has to load
and roll out).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from uam_studio.cli import main
from uam_studio.errors import InputError
from uam_studio.planning.planner import MAX_POINTS, plan_mission

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "assets" / "example_mission.json"
KEYS = {"policy", "route", "altitudes_m", "charging_cycles", "reached", "reached_priority", "predicted",
        "physics", "safe", "min_voltage_v", "exact", "messages", "band"}


def _example() -> dict:
    return json.loads(EXAMPLE.read_text())


def _write(tmp: Path, name: str, d: dict) -> str:
    p = tmp / name
    p.write_text(json.dumps(d))
    return str(p)


def _plan_json(capsys, *args: str) -> dict:
    code = main(["plan", *args, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def _check_result(res: dict, mission: dict) -> None:
    """Keys, plain types, and consistency with the physics check."""
    assert set(res) == KEYS
    names = {"vertiport"} | {d["name"] for d in mission["destinations"]}
    assert isinstance(res["policy"], str)
    assert all(isinstance(n, str) and n in names for n in res["route"])
    assert len(res["altitudes_m"]) == len(res["route"])
    assert all(type(a) is float for a in res["altitudes_m"])
    assert type(res["charging_cycles"]) is int and type(res["reached_priority"]) is int
    assert set(res["reached"]) <= set(res["route"]) - {"vertiport"}
    prio = {d["name"]: d["priority"] for d in mission["destinations"]}
    assert res["reached_priority"] == sum(prio[n] for n in res["reached"])
    assert type(res["safe"]) is bool
    assert type(res["exact"]) is bool if res["policy"] == "oracle" else res["exact"] is None
    assert all(isinstance(m, str) for m in res["messages"])
    phys = res["physics"]
    assert set(phys) == {"time_s", "voltage_v", "eod_s", "leg_start_s"}
    starts = phys["leg_start_s"]  # one take-off time per leg flown, in order, inside the series
    assert len(starts) <= len(res["route"]) and starts == sorted(starts)
    assert all(type(x) is float and 0.0 <= x <= (phys["time_s"][-1] if phys["time_s"] else 0.0) for x in starts)
    if res["safe"]:
        assert len(starts) == len(res["route"])
    assert len(phys["time_s"]) == len(phys["voltage_v"]) <= MAX_POINTS
    assert all(type(x) is float for x in phys["voltage_v"])
    assert res["safe"] == (phys["eod_s"] is None)
    if res["route"]:
        assert res["min_voltage_v"] == pytest.approx(min(phys["voltage_v"]))
    else:
        assert res["min_voltage_v"] is None and phys["time_s"] == []
    if res["predicted"] is not None:
        assert set(res["predicted"]) == {"time_s", "voltage_v"}
        assert res["predicted"]["time_s"] == phys["time_s"]
        assert len(res["predicted"]["voltage_v"]) == len(phys["time_s"])
    if res["band"] is not None:  # computed in the pass that predicts: on the same samples, around it
        band = res["band"]
        assert res["predicted"] is not None and band["time_s"] == phys["time_s"] and band["level"] == 0.9
        assert all(lo <= hi for lo, hi in zip(band["low_v"], band["high_v"]))
        assert band["min_low_v"] <= min(band["low_v"]) + 1e-4
    json.dumps(dict(res), allow_nan=False)


@pytest.fixture(scope="module")
def agent(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dqn")
    assert main(["train", "dqn", "--steps", "300", "--out", str(out), "--seed", "1"]) == 0
    assert (out / "agent.zip").is_file()
    card = json.loads((out / "card.json").read_text())
    assert card["config"]["steps"] == 300 and card["scenario"] == "single_charge"
    assert card["final_stats"]["timesteps"] >= 300 and card["timing"]["wall_s"] >= 0
    return out / "agent.zip"


# --------------------------------------------------------------------------- plan


def test_plan_oracle_json(capsys):
    res = _plan_json(capsys, str(EXAMPLE), "--policy", "oracle")
    _check_result(res, _example())
    assert res["policy"] == "oracle" and res["safe"] is True and res["exact"] is True
    assert res["route"][-1] == "vertiport" and res["charging_cycles"] == 1
    assert len(res["reached"]) >= 1 and res["physics"]["eod_s"] is None


def test_plan_greedy_json_and_table(capsys):
    res = _plan_json(capsys, str(EXAMPLE), "--policy", "greedy", "--q-max", "7000")
    _check_result(res, _example())
    assert res["policy"] == "greedy" and res["safe"] and res["reached"]
    assert main(["plan", str(EXAMPLE), "--policy", "greedy"]) == 0
    out = capsys.readouterr().out
    assert "route: vertiport -> " in out and "safe: yes" in out and "charging cycles: 1" in out


def test_a_cell_that_cannot_take_off_is_not_called_safe(capsys):
    """The largest R0 of the box: nothing is flown, and the table says why, as the app's verdict does."""
    assert main(["plan", str(EXAMPLE), "--policy", "greedy", "--r0", "0.45"]) == 0
    out = capsys.readouterr().out
    assert "route: none" in out and "safe: NO, the cell cannot take off" in out and "safe: yes" not in out


@pytest.mark.parametrize("policy", ["oracle", "greedy", "dqn"])
def test_zero_destinations_is_a_message(capsys, tmp_path, policy):
    d = _example()
    d["destinations"] = []
    res = _plan_json(capsys, _write(tmp_path, "empty.json", d), "--policy", policy)
    _check_result(res, d)
    assert res["route"] == [] and res["safe"] and res["predicted"] is None
    assert any("no destinations" in m for m in res["messages"])


def test_missing_agent_exits_2_naming_agent(capsys):
    code = main(["plan", str(EXAMPLE), "--policy", "dqn", "--agent", "/nonexistent.zip"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert len(err.splitlines()) == 1 and err.startswith("error: agent")


def test_missing_bundled_agent_is_an_error_not_an_empty_plan(monkeypatch, tmp_path, capsys):
    import uam_studio.bundled as bundled
    from uam_studio.errors import InputError

    monkeypatch.setenv("UAM_STUDIO_HOME", str(tmp_path / "home"))
    monkeypatch.setattr(bundled, "package_dir", lambda: tmp_path)  # an install without the agents
    with pytest.raises(InputError, match=r"^agent: bundled agent dqn_single_charge.zip is not installed"):
        plan_mission(_example(), "dqn", predictor=False)
    with pytest.raises(InputError, match=r"^agent: bundled agent attention_planner.pt is not installed"):
        plan_mission(_example(), predictor=False)  # the default policy
    for argv, name in ((["plan", str(EXAMPLE)], "attention_planner.pt"),
                       (["plan", str(EXAMPLE), "--policy", "dqn"], "dqn_single_charge.zip")):
        code = main(argv)
        out, err = capsys.readouterr()
        assert code == 2 and out == ""
        assert len(err.splitlines()) == 1
        assert err.startswith(f"error: agent: bundled agent {name} is not installed")
    assert plan_mission(_example(), "greedy", predictor=False)["route"]  # the other policies still plan


def test_trained_agent_plans_and_is_physics_checked(capsys, agent):
    res = _plan_json(capsys, str(EXAMPLE), "--policy", "dqn", "--agent", str(agent))
    _check_result(res, _example())
    assert res["policy"] == "dqn" and res["route"]
    # a weaker cell: the agent's route may now fail; the physics check must say so consistently
    res = _plan_json(capsys, str(EXAMPLE), "--policy", "dqn", "--agent", str(agent), "--q-max", "5000", "--r0", "0.3")
    _check_result(res, _example())
    if not res["safe"]:
        assert any(m.startswith("unsafe: voltage falls below") for m in res["messages"])
    # policy rollout on top of the agent: a physics-checked, safe plan reaching at least as much
    base = _plan_json(capsys, str(EXAMPLE), "--policy", "dqn", "--agent", str(agent))
    res = _plan_json(capsys, str(EXAMPLE), "--policy", "dqn", "--agent", str(agent), "--lookahead", "4")
    _check_result(res, _example())
    assert res["safe"] and res["reached_priority"] - res["charging_cycles"] >= (
        base["reached_priority"] - base["charging_cycles"])


def test_train_into_pretrained_is_refused(capsys):
    target = ROOT / "pretrained" / "dqn_test_refused"
    code = main(["train", "dqn", "--steps", "10", "--out", str(target)])
    err = capsys.readouterr().err
    assert code == 2 and "pretrained" in err and len(err.splitlines()) == 1
    assert not target.exists()
    assert main(["train", "dqn", "--steps", "10", "--out", str(ROOT / "pretrained" / "x.zip")]) == 2
    assert main(["train", "dynaformer", "--alpha", "2"]) == 2
    assert main(["train", "dqn", "--n-train", "100"]) == 2
    capsys.readouterr()
    assert main(["train", "dqn", "--cell", "vtc6"]) == 2  # a Dynaformer option
    assert main(["train", "dynaformer", "--init-from", "a.zip", "--out", "unused_run"]) == 2  # before any data
    assert main(["train", "dqn", "--steps", "10", "--init-from", "missing.zip", "--out", "unused.zip"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and "--cell" in err[0], err
    assert err[1].startswith("error: init: ") and "a.zip: file not found" in err[1], err
    assert "init_agent" in err[2] and "not found" in err[2]
    assert not Path("unused.zip").exists() and not Path("unused_run").exists()


def test_plan_argument_errors(capsys):
    assert main(["plan", str(EXAMPLE), "--policy", "astar"]) == 2
    assert main(["plan", str(EXAMPLE), "--policy", "oracle", "--r0", "9"]) == 2
    assert main(["plan", str(EXAMPLE), "--policy", "oracle", "--agent", "a.zip"]) == 2
    assert main(["plan", str(EXAMPLE), "--policy", "greedy", "--lookahead", "3"]) == 2
    assert main(["plan", str(EXAMPLE), "--policy", "dqn", "--lookahead", "9"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 5 and "r0" in err[1] and "--agent" in err[2] and "--lookahead" in err[3]
    assert "lookahead" in err[4] and "[0, 8]" in err[4]


# --------------------------------------------------------------------------- library: hard missions


def _dest(name: str, x: float, y: float, priority: int = 1) -> dict:
    return {"name": name, "x_km": x, "y_km": y, "priority": priority, "wind_kts": 0.0}


def _nine() -> dict:
    d = _example()
    angles = np.linspace(0, 2 * np.pi, 9, endpoint=False)
    d["destinations"] = [_dest(f"D{k}", 20 * np.cos(a), 20 * np.sin(a)) for k, a in enumerate(angles)]
    return d


def test_nine_destinations_greedy_plans_them_all():
    d = _nine()
    res = plan_mission(d, "greedy", predictor=False)
    _check_result(res, d)
    assert res["safe"] and not any("not planned" in m for m in res["messages"])
    assert "D8" in res["route"] or any("D8" in m for m in res["messages"])  # planned with the others


def test_nine_destinations_dqn_is_an_error_naming_its_limit(agent, capsys, tmp_path):
    from uam_studio.errors import InputError

    with pytest.raises(InputError, match=r"^destinations: 9 destinations; the dqn policy plans at most 8 "
                                         r"\(allowed 1 to 8\)$"):
        plan_mission(_nine(), "dqn", agent_path=agent, predictor=False)
    code = main(["plan", _write(tmp_path, "nine.json", _nine()), "--policy", "dqn", "--agent", str(agent)])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and len(err.splitlines()) == 1 and "at most 8" in err


def _big(n: int, scenario: str) -> dict:
    from uam_studio.planning import held_out_missions, mission_to_dict

    return mission_to_dict(held_out_missions(1, 9292, n_dest=(n, n), scenario=scenario)[0])


def test_oracle_on_twenty_destinations_is_the_reference(capsys, tmp_path):
    d = _big(20, "multi_charge")
    res = _plan_json(capsys, _write(tmp_path, "twenty.json", d), "--policy", "oracle")
    _check_result(res, d)
    assert res["exact"] is False and res["safe"] and len(res["reached"]) >= 15
    assert any("reference solver" in m and "not proven optimal" in m for m in res["messages"])
    assert res["charging_cycles"] == res["route"].count("vertiport") >= 2


def test_twenty_one_destinations_in_a_file_exit_2(capsys, tmp_path):
    d = _big(20, "single_charge")
    d["destinations"].append(_dest("D21", 30.0, -41.0))
    code = main(["plan", _write(tmp_path, "many.json", d), "--policy", "oracle"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.splitlines() == ["error: destinations: 21 destinations; allowed 1 to 20"]


@pytest.mark.parametrize("policy", ["oracle", "greedy", "dqn"])
def test_unreachable_destinations_and_dead_cell(policy, agent):
    path = agent if policy == "dqn" else None
    d = _example()
    d["destinations"] = [_dest("Near", 2.0, 1.0)]
    res = plan_mission(d, policy, agent_path=path, predictor=False)
    _check_result(res, d)
    assert res["route"] == [] and any("cannot reach Near" in m for m in res["messages"])
    res = plan_mission(_example(), policy, r0=0.45, agent_path=path, predictor=False)
    _check_result(res, _example())
    assert res["route"] == [] and any("cannot finish takeoff" in m for m in res["messages"])


class _StubPredictor:
    """Stands in for the Dynaformer: records the calls, returns a voltage falling with the charge drawn."""

    def __init__(self) -> None:
        self.calls: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def predict(self, context_current_a, context_voltage_v, current_a, dt_s=1.0):
        self.calls.append((np.asarray(context_current_a), np.asarray(context_voltage_v), np.asarray(current_a)))
        return 4.1 - np.cumsum(current_a) * dt_s / 8000.0


def test_prediction_is_per_sortie_with_takeoff_context():
    from uam_studio.planning.env import takeoff_context_current

    d = _example()
    d["scenario"] = "multi_charge"
    stub = _StubPredictor()
    res = plan_mission(d, "greedy", predictor=stub)
    _check_result(res, d)
    assert res["charging_cycles"] >= 2 and len(stub.calls) == res["charging_cycles"]
    for ci, cv, cur in stub.calls:
        assert ci.shape == cv.shape == (20,)
        np.testing.assert_allclose(ci, takeoff_context_current())
        np.testing.assert_allclose(cur[:20], ci)  # each sortie starts with a take-off
        assert 3.5 < cv[-1] < cv[0] <= 4.3  # physics take-off voltage of this cell
    n = sum(c[2].size for c in stub.calls)
    assert n > MAX_POINTS and len(res["predicted"]["voltage_v"]) <= MAX_POINTS
    # the stub recharges each sortie: its lowest value (kept by the thinning) is the sortie's end
    lowest = min(4.1 - c[2].sum() / 8000.0 for c in stub.calls)
    assert min(res["predicted"]["voltage_v"]) == pytest.approx(lowest, abs=1e-4)


class _StubWithBand(_StubPredictor):
    """A predictor with a band: ``fail`` set, its band raises that exception."""

    def __init__(self, fail: Exception | None = None) -> None:
        super().__init__()
        self.fail = fail

    def voltage_band(self, ci, cv, cur, dt_s=1.0, level=0.9):
        if self.fail is not None:
            raise self.fail
        v = self.predict(ci, cv, cur, dt_s)
        return v - 0.05, v, v + 0.05


@pytest.mark.parametrize("fail", [None, KeyError("no such weights key"), ValueError("bad profile")])
def test_band_in_the_same_pass_and_a_failing_band_keeps_the_plan(fail):
    d = _example()
    res = plan_mission(d, "greedy", predictor=_StubWithBand(fail))
    _check_result(res, d)
    assert res["predicted"] is not None and res["safe"]
    if fail is None:
        assert res["band"]["low_v"] == pytest.approx([v - 0.05 for v in res["predicted"]["voltage_v"]], abs=2e-4)
        assert plan_mission(d, "greedy", predictor=_StubWithBand(), band_level=None)["band"] is None
    else:  # the band is an extra: the plan and its prediction stand, one line says why there is no band
        assert res["band"] is None
        assert any(m.startswith(f"Dynaformer band unavailable ({type(fail).__name__}") for m in res["messages"])
    with pytest.raises(InputError, match=r"^band_level: "):
        plan_mission(d, "greedy", predictor=_StubWithBand(), band_level=1.5)


@pytest.mark.parametrize("scenario", ["single_flight", "single_charge", "multi_charge"])
def test_bundled_agents_plan_any_map_safely(scenario):
    """The bundled agents load, plan maps they never saw (with the safety filter) and pass physics."""
    from uam_studio.planning import held_out_missions
    from uam_studio.planning.agents.dqn.rollout import bundled_agent_path, load_agent_cached

    path = bundled_agent_path(scenario)
    assert path.is_file(), f"missing bundled agent {path}"
    assert path.stat().st_size < 3_000_000
    _, card = load_agent_cached(path)
    assert card["scenario"] == scenario and card["env"]["obs_dim"] == 116
    for m in held_out_missions(3, 515, scenario=scenario):
        res = plan_mission(m, "dqn", predictor=False)
        assert res["safe"], (m.name, res["messages"])
        if scenario != "single_flight":
            assert res["reached"], (m.name, res["messages"])


def test_plan_mission_returns_a_typed_result_whose_dict_is_the_cli_json(capsys):
    from uam_studio.planning import plan_mission
    from uam_studio.planning.planner import PlanResult

    res = plan_mission(_example(), "greedy", predictor=False)
    assert isinstance(res, PlanResult)
    assert res.route == res["route"] and res.reached_priority == res["reached_priority"] == 6
    assert res.to_dict() == dict(res) and list(res) == list(res.to_dict())
    with pytest.raises(KeyError):
        res["nope"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.safe = False
    cli = _plan_json(capsys, str(EXAMPLE), "--policy", "greedy")  # with the Dynaformer, as plan_mission's default
    assert cli == json.loads(json.dumps(plan_mission(_example(), "greedy").to_dict()))
