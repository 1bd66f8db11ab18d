"""Adding a retrainable planner is one entry in the catalogue: the user's agents folder, the agent files' model
and their labels, and ``uam-studio train`` read its trainer (a fake planner, registered for the test only)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from uam_studio.cli import main
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
    cli_title = "fake only"
    cli_shared = {"out": "default runs/fake", "steps": "laps"}

    def add_cli_arguments(self, group):
        return (group.add_argument("--laps", type=int, default=None, help="laps").dest,)

    def train_cli(self, args):
        if args.laps is not None and args.laps < 1:
            raise InputError("--laps", "must be >= 1")
        return f"fake ran {args.laps} laps, {args.steps} steps into {args.out}, seed {args.seed}"

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


def test_a_new_trainer_is_a_choice_of_the_train_command_with_its_own_options(fake_planner, capsys):
    assert main(["train", "fake", "--laps", "3", "--steps", "7", "--out", "runs/x", "--seed", "4"]) == 0
    assert capsys.readouterr().out.strip() == "fake ran 3 laps, 7 steps into runs/x, seed 4"
    assert main(["train", "fake", "--laps", "0"]) == 2
    assert capsys.readouterr().err.strip() == "error: --laps: must be >= 1"
    assert main(["train", "dqn", "--laps", "3"]) == 2  # its option is refused by the other models
    assert "--laps: not an option of 'train dqn' (only of 'train fake')" in capsys.readouterr().err
    assert main(["train", "fake", "--scenario", "single_flight"]) == 2  # and theirs by it
    assert "--scenario: not an option of 'train fake' (only of 'train dqn')" in capsys.readouterr().err
    assert main(["train", "fake", "--device", "cpu"]) == 2  # a shared option it does not read
    assert "(only of 'train dynaformer / attention')" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    assert "fake only:" in capsys.readouterr().out
