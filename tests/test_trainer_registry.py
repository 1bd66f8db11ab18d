"""Adding a retrainable planner is one entry in the catalogue: the user's agents folder, the agent files' model
and their labels read its trainer (a fake planner, registered for the test only)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from uam_studio.errors import InputError
from uam_studio.planning import planners
from uam_studio.planning.agents.retrain import RetrainProcess, agent_model, list_agents
from uam_studio.planning.agents.trainer import AgentFile, trainer, trainers


class FakeTrainer:
    """A planner whose agents are ``*.fake`` files holding their card as JSON."""

    planner = "fake"
    unit = "epoch"
    settings = ("epochs",)
    trains_on_map = False

    def find(self, folder: Path) -> list[AgentFile]:
        return [AgentFile(p, p.stem, None, json.loads(p.read_text()), p.stat().st_mtime) for p in folder.glob("*.fake")]

    def describe(self, card, scenario):
        return ["fake", f"{card['epochs']} epochs"]

    def owns(self, path: Path) -> bool:
        return path.suffix == ".fake"

    def agent_name(self, path: Path) -> str:
        return path.stem

    def bundled_init(self, scenario: str) -> str:
        return ""

    def check(self, mission, setup):
        if setup.get("epochs", 0) < 1:
            raise InputError("epochs", "must be >= 1")
        return setup

    def job(self, values, mission, init_agent, source):
        raise NotImplementedError

    def run(self, *args):
        raise NotImplementedError


@pytest.fixture
def fake_planner(monkeypatch):
    entry = dataclasses.replace(planners.PLANNERS["greedy"], name="fake", label="Fake",
                                trainer=f"{__name__}:FakeTrainer", train_label="Fake")
    monkeypatch.setitem(planners.PLANNERS, "fake", entry)
    return entry


def test_a_new_trainer_is_found_by_the_agents_folder(fake_planner, tmp_path):
    (tmp_path / "mine.fake").write_text(json.dumps({"model": "fake", "epochs": 3, "stopped_early": True}))
    (tmp_path / "other.txt").write_text("not an agent")
    assert "fake" in trainers() and trainer("fake").unit == "epoch"
    [agent] = list_agents(tmp_path)
    assert agent.model == "fake" and agent.label == "mine (fake, 3 epochs, stopped early)"
    assert agent_model(tmp_path / "mine.fake") == "fake"
    with pytest.raises(InputError, match="epochs"):  # its own settings are checked in the parent
        RetrainProcess(tmp_path / "x.fake", kind="fake", epochs=0)


def test_a_planner_without_a_trainer_is_refused_by_name():
    with pytest.raises(InputError, match="kind.*allowed attention, dqn|allowed attention, dqn"):
        RetrainProcess("/tmp/x.zip", kind="greedy")
    with pytest.raises(InputError, match="agent_path"):
        agent_model("notes.txt")
