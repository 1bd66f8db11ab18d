"""Retraining the attention planner from the app: settings, live epochs, stop, fine-tuning, the Planner's use."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from uam_studio.app.planner.state import PlannerState
from uam_studio.app.retrain.state import EPOCH_COLUMNS, RetrainState
from uam_studio.app.services import agent_policy, registry
from uam_studio.errors import InputError
from uam_studio.planning.agents.attention.retrain import attention_setup
from uam_studio.planning.agents.retrain import list_agents

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def home(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("UAM_STUDIO_HOME", str(tmp_path / "home"))
    registry().refresh()
    yield tmp_path / "home"
    registry().refresh()


def _run(rs: RetrainState, mission, timeout_s: float = 180) -> list[dict[str, float]]:
    assert rs.start(mission), rs.error
    rows: list[dict[str, float]] = []
    rs.join(timeout_s)
    rows += rs.poll()
    assert not rs.running, rs.status
    return rows


def test_attention_run_in_a_child_process_streams_epochs_scores_the_map_and_plans(home):
    planner = PlannerState(policy="greedy")
    rs = RetrainState(model="attention", source="map", missions=12, epochs=3, seed=3, scenario="multi_charge")
    assert planner.mission.scenario == "single_charge"  # scored as the run's scenario, like its reference line
    assert rs.runner == "process"
    rows = _run(rs, planner.mission)
    assert rs.error == "" and rs.status.startswith("done: 3 epochs; saved attention-map-"), rs.status
    assert [r["epoch"] for r in rows] == [1.0, 2.0, 3.0] and list(rows[0]) == EPOCH_COLUMNS
    most = sum(d.priority for d in planner.mission.destinations)
    for r in rows:  # scored on the map under physics: an unsafe plan scores 0
        assert np.isfinite(r["loss"]) and 0.0 <= r["accuracy"] <= 1.0
        assert 0 <= r["priority"] <= most and 0 <= r["priority_net"] <= most
    assert rs.progress == 1.0 and rs.progress_text().startswith("12 of 12 missions solved by the oracle, 3 of 3 epochs")

    path = Path(rs.agent_path)
    assert path.name == "attention_planner.pt" and path.parent.parent == home / "agents"
    card = json.loads((path.parent / "card.json").read_text())
    assert card["model"] == "attention" and card["source"] == "app" and card["stopped_early"] is False
    assert card["watched_map"]["name"] == planner.mission.name and card["stats"]["epochs_done"] == 3
    assert card["watched_map"]["scenario"] == "multi_charge"
    assert card["config"]["oracle_missions"] == 12 and card["init_weights"] is None

    # the Planner lists it, plans with it as the attention planner, and compares it with the paper's DQN
    registry().refresh()
    value = f"agent:{path}"
    assert agent_policy(value) == ("attention", str(path))
    assert value in planner.policy_objects.values()
    label = planner.policy_label(value)
    assert label == f"Retrained: {path.parent.name} (attention, 3 epochs)"  # what it learned, from its card
    assert planner.apply(policy=value), planner.error
    assert planner.plan_error == "" and planner.plan["policy"] == "attention" and planner.plan["route"]
    assert "paper" in planner._compare_specs(planner.plan_request)
    planner.close()


def test_attention_fine_tuning_starts_from_the_bundled_planner_and_never_writes_it(home):
    bundled = ROOT / "pretrained" / "attention_planner.pt"
    before = bundled.read_bytes()
    rs = RetrainState(model="attention", source="random", missions=10, epochs=1, runner="thread",
                      start_from="bundled")
    rows = _run(rs, None)
    assert rs.error == "" and len(rows) == 1 and np.isnan(rows[0]["priority"])  # no map: no score
    assert rs.status.startswith("done: 1 epoch; saved")
    card = json.loads((Path(rs.agent_path).parent / "card.json").read_text())
    assert card["init_weights"] == str(bundled) and card["watched_map"] is None
    assert bundled.read_bytes() == before


def test_attention_stop_saves_the_network_so_far_or_says_nothing_was_saved(home):
    rs = RetrainState(model="attention", source="random", missions=10, epochs=500, runner="thread")
    assert rs.start(None), rs.error
    while rs.running and rs.episodes < 1:
        rs.poll()
        rs.join(0.2)
    rs.stop()
    rs.join(120)
    rs.poll()
    assert not rs.running and rs.status.startswith("stopped: ") and 1 <= rs.episodes < 500
    card = json.loads((Path(rs.agent_path).parent / "card.json").read_text())
    assert card["stopped_early"] is True and card["stats"]["epochs_done"] == rs.episodes

    early = RetrainState(model="attention", source="random", missions=5000, epochs=5, runner="thread")
    assert early.start(None)
    early.stop()  # while the oracle solves the training missions
    early.join(120)
    early.poll()
    assert early.error == "" and early.status == "stopped before the first epoch ended: nothing learned, nothing saved"
    assert not early.agent_path and [a.name for a in list_agents()] == [Path(rs.agent_path).parent.name]


@pytest.mark.parametrize("kw, field", [({"missions": 9}, "missions"), ({"epochs": 0}, "epochs"),
                                       ({"missions": 12.5}, "missions"), ({"seed": -1}, "seed")])
def test_attention_setup_names_the_field_out_of_range(kw, field):
    with pytest.raises(InputError) as err:
        attention_setup(**kw)
    assert err.value.field == field and "allowed integers" in str(err.value)


def test_list_agents_skips_attention_folders_that_are_not_agents(home):
    for name, card in (("no_card", None), ("other", {"model": "dynaformer"}), ("broken", "{not json")):
        d = home / "agents" / name
        d.mkdir(parents=True)
        (d / "attention_planner.pt").write_bytes(b"x")
        if card is not None:
            (d / "card.json").write_text(card if isinstance(card, str) else json.dumps(card))
    assert list_agents() == []
