"""Model files never run code: DQN agent zips (``plan --agent``, ``train dqn --init-from``, the app's
agent folder) and Dynaformer training checkpoints (resume).

The payload is harmless: unpickling it calls ``pathlib.Path.touch`` on a marker file in ``tmp_path``.
It goes where SB3 keeps pickles (a ``":serialized:"`` value of the zip's ``data`` JSON, base64 of
cloudpickle, as SB3 writes them), into an extra zip entry, into ``policy.pth`` (``torch.save``) and
into a Dynaformer ``checkpoint.pt``. Every test checks that the marker is never created.
"""

from __future__ import annotations

import base64
import io
import json
import pathlib
import zipfile
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
import torch

from uam_studio.cli import main
from uam_studio.errors import InputError
from uam_studio.planning.agents.dqn.agent_file import (
    AGENT_ENTRIES,
    NETWORK_KEY,
    OPTIONAL_AGENT_ENTRIES,
    load_agent,
    load_card,
)
from uam_studio.planning.env import UAMPlanningEnv

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "assets" / "example_mission.json"
BUNDLED = ROOT / "pretrained" / "dqn_single_charge.zip"  # the example mission's scenario

pytestmark = pytest.mark.skipif(not BUNDLED.is_file(), reason="no bundled DQN agent")


class Touch:
    """Unpickling this creates ``marker`` (an empty file)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (pathlib.Path.touch, (pathlib.Path(self.marker),))


def _serialized(marker: Path) -> dict:
    """The payload as SB3 stores a pickled value in ``data``: base64 of cloudpickle."""
    return {":type:": "<class 'collections.deque'>",
            ":serialized:": base64.b64encode(cloudpickle.dumps(Touch(marker))).decode()}


def _torch_payload(marker: Path) -> bytes:
    buf = io.BytesIO()
    torch.save(Touch(marker), buf)
    return buf.getvalue()


def _tamper(dst: Path, src: Path = BUNDLED, data=None, replace: dict | None = None,
            extra: dict | None = None) -> Path:
    """A copy of the agent zip ``src``: ``data(dict)`` edits its ``data`` JSON, ``replace`` swaps entries'
    bytes, ``extra`` adds entries."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            raw = zin.read(name)
            if name == "data" and data is not None:
                d = json.loads(raw)
                data(d)
                raw = json.dumps(d).encode()
            zout.writestr(name, (replace or {}).get(name, raw))
        for name, raw in (extra or {}).items():
            zout.writestr(name, raw)
    return dst


def _add_pickled_key(marker: Path):
    def edit(d: dict) -> None:
        d["evil"] = _serialized(marker)
    return edit


def _replace_pickled_values(marker: Path):
    """Every ``":serialized:"`` value SB3 wrote (spaces, policy class, schedules, ...) becomes the payload."""
    def edit(d: dict) -> None:
        for v in d.values():
            if isinstance(v, dict) and ":serialized:" in v:
                v[":serialized:"] = _serialized(marker)[":serialized:"]
    return edit


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _refused(code: int, out: str, err: str, path: Path) -> None:
    """Exit 2 with one line on stderr naming ``path``, nothing on stdout."""
    assert code == 2, (out, err)
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(path) in lines[0], err


# ----------------------------------------------------------------------------- plan --agent


def test_plan_refuses_a_pickled_payload_in_the_agent_data(tmp_path, capsys):
    marker = tmp_path / "ran"
    bad = _tamper(tmp_path / "bad.zip", data=_add_pickled_key(marker))
    code, out, err = _run(capsys, "plan", str(EXAMPLE), "--policy", "dqn", "--agent", str(bad))
    assert not marker.exists()
    _refused(code, out, err, bad)
    assert "pickled setting 'evil'" in err


def test_plan_never_decodes_the_pickled_values_sb3_writes(tmp_path, capsys):
    """The payload in place of every pickled value: never decoded, so the agent plans as the bundled one."""
    marker = tmp_path / "ran"
    bad = _tamper(tmp_path / "bad.zip", data=_replace_pickled_values(marker))
    code, out, err = _run(capsys, "plan", str(EXAMPLE), "--policy", "dqn", "--agent", str(bad), "--json")
    assert not marker.exists()
    assert code == 0, err
    code, ref, err = _run(capsys, "plan", str(EXAMPLE), "--policy", "dqn", "--agent", str(BUNDLED), "--json")
    assert code == 0, err
    assert json.loads(out)["route"] == json.loads(ref)["route"] and json.loads(out)["route"]


@pytest.mark.parametrize("entry", ["payload.pkl", "evil.pth", "data/extra"])
def test_plan_refuses_an_extra_zip_entry(tmp_path, capsys, entry):
    marker = tmp_path / "ran"
    payload = _torch_payload(marker) if entry.endswith(".pth") else cloudpickle.dumps(Touch(marker))
    bad = _tamper(tmp_path / "bad.zip", extra={entry: payload})
    code, out, err = _run(capsys, "plan", str(EXAMPLE), "--policy", "dqn", "--agent", str(bad))
    assert not marker.exists()
    _refused(code, out, err, bad)
    assert f"unexpected entry {entry!r}" in err


def test_plan_refuses_a_pickled_policy_pth_and_decodes_nothing_before(tmp_path, capsys):
    """policy.pth holds a pickled object (refused by ``weights_only``) and ``data`` a pickled value:
    the file is rejected and neither payload ran."""
    in_pth, in_data = tmp_path / "ran_pth", tmp_path / "ran_data"
    bad = _tamper(tmp_path / "bad.zip", data=_replace_pickled_values(in_data),
                  replace={"policy.pth": _torch_payload(in_pth)})
    code, out, err = _run(capsys, "plan", str(EXAMPLE), "--policy", "dqn", "--agent", str(bad))
    assert not in_pth.exists() and not in_data.exists()
    _refused(code, out, err, bad)
    assert "policy.pth" in err


# ----------------------------------------------------------------------------- train dqn --init-from


def test_train_dqn_init_from_refuses_the_payload(tmp_path, capsys):
    marker = tmp_path / "ran"
    bad = _tamper(tmp_path / "bad.zip", data=_add_pickled_key(marker))
    out_dir = tmp_path / "run"
    code, out, err = _run(capsys, "train", "dqn", "--init-from", str(bad), "--steps", "10", "--out", str(out_dir))
    assert not marker.exists()
    _refused(code, out, err, bad)
    assert err.startswith("error: init_agent: ")
    assert not (out_dir / "agent.zip").exists()


# ----------------------------------------------------------------------------- the app's agent folder


def test_app_agent_folder_payload_is_an_error_not_a_run(tmp_path, monkeypatch):
    from uam_studio.app.planner.state import PlannerState
    from uam_studio.app.services import registry

    monkeypatch.setenv("UAM_STUDIO_HOME", str(tmp_path / "home"))
    agents = tmp_path / "home" / "agents"
    agents.mkdir(parents=True)
    marker = tmp_path / "ran"
    bad = _tamper(agents / "bad.zip", data=_add_pickled_key(marker),
                  extra={"payload.pkl": cloudpickle.dumps(Touch(marker))})
    try:
        registry().refresh()
        assert [a.path for a in registry().agents] == [bad]  # listed: its card is plain JSON
        s = PlannerState()
        assert s.apply(policy=f"agent:{bad}"), s.error
        assert not marker.exists()
        assert s.plan_error.startswith("agent: ") and str(bad) in s.plan_error and "\n" not in s.plan_error
        assert "unexpected entry 'payload.pkl'" in s.plan_error
        s.close()
    finally:
        monkeypatch.undo()
        registry().refresh()


# ----------------------------------------------------------------------------- the safe loader itself


def test_bundled_agents_load_with_their_own_weights_and_the_planning_spaces(tmp_path):
    """Files saved before cards described the network: spaces from SB3's readable fields, weights
    exactly those of policy.pth, so the Q-values are those of the file."""
    env = UAMPlanningEnv(scenario="single_charge", backend="physics")
    for path in sorted((ROOT / "pretrained").glob("dqn_*.zip")):
        assert NETWORK_KEY not in load_card(path)
        model = load_agent(path, env=env)
        with zipfile.ZipFile(path) as zf:
            assert set(zf.namelist()) <= {*AGENT_ENTRIES, *OPTIONAL_AGENT_ENTRIES}
            stored = torch.load(io.BytesIO(zf.read("policy.pth")), weights_only=True)
        ours = model.policy.state_dict()
        assert ours.keys() == stored.keys() and all(torch.equal(ours[k], stored[k]) for k in ours), path
        assert model.double_dqn and model.policy.net_arch == [256, 256]


def test_save_agent_describes_the_network_and_a_plain_sb3_zip_loads_too(tmp_path):
    from uam_studio.planning.agents.dqn.agent_file import save_agent

    model = load_agent(BUNDLED)
    path = tmp_path / "agent.zip"
    save_agent(model, path, {"model": "dqn", "scenario": "single_charge"})
    net = load_card(path)[NETWORK_KEY]
    assert net["policy_class"] == "MaskedDQNPolicy" and net["net_arch"] == [256, 256]
    assert net["action_space"] == {"type": "Discrete", "n": 36, "start": 0}
    assert len(net["observation_space"]["low"]) == 116
    plain = tmp_path / "plain.zip"  # SB3's own save: no card
    model.save(plain)
    obs = np.zeros((1, 116), dtype=np.float32)
    obs[0, -36:] = 1.0
    x = torch.as_tensor(obs)
    for p in (path, plain):
        again = load_agent(p)
        assert again.observation_space == model.observation_space and again.action_space == model.action_space
        with torch.no_grad():
            assert torch.equal(again.policy.q_net(x), model.policy.q_net(x))


def test_a_zip_without_weights_or_with_duplicates_is_refused(tmp_path):
    no_weights = tmp_path / "no_weights.zip"
    with zipfile.ZipFile(BUNDLED) as zin, zipfile.ZipFile(no_weights, "w") as zout:
        for name in zin.namelist():
            if name != "policy.pth":
                zout.writestr(name, zin.read(name))
    with pytest.raises(InputError, match="no 'policy.pth' entry"):
        load_agent(no_weights)
    dup = tmp_path / "dup.zip"
    with pytest.warns(UserWarning, match="Duplicate name"):
        _tamper(dup, extra={"data": b"{}"})
    with pytest.raises(InputError, match="duplicate"):
        load_agent(dup)


# ----------------------------------------------------------------------------- Dynaformer checkpoints


def _tiny_train(tmp_path: Path, steps: int, **kw):
    import uam_studio.dynaformer.train as train_mod
    from uam_studio.dynaformer.model import DynaformerConfig

    cfg = train_mod.TrainConfig(n_train=64, n_context=300, steps=steps, batch=8, max_len=512, checkpoint_every=3,
                                device="cpu", threads=1)
    tiny = DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32)
    return train_mod.train(cfg, tmp_path, model_cfg=tiny, **kw)


def _payload_checkpoint(run: Path, marker: Path) -> Path:
    run.mkdir(parents=True, exist_ok=True)
    ckpt = run / "checkpoint.pt"
    torch.save({"model": Touch(marker), "opt": {}, "sched": {}, "step": 3, "rng": {}, "train_s": 1.0}, ckpt)
    return ckpt


def test_dynaformer_resume_refuses_a_checkpoint_payload(tmp_path):
    marker = tmp_path / "ran"
    ckpt = _payload_checkpoint(tmp_path / "run", marker)
    with pytest.raises(InputError) as err:
        _tiny_train(tmp_path / "run", steps=6)
    assert not marker.exists()
    assert err.value.field == "checkpoint" and str(ckpt) in str(err.value) and "\n" not in str(err.value)


def test_train_dynaformer_cli_refuses_a_checkpoint_payload(tmp_path, capsys):
    marker = tmp_path / "ran"
    ckpt = _payload_checkpoint(tmp_path / "run", marker)
    code, out, err = _run(capsys, "train", "dynaformer", "--out", str(tmp_path / "run"), "--steps", "1",
                          "--n-train", "64", "--device", "cpu")
    assert not marker.exists()
    _refused(code, out, err, ckpt)
    assert err.startswith("error: checkpoint: ")


def test_dynaformer_resume_continues_from_the_checkpoint(tmp_path):
    """A checkpoint written by train loads under weights_only and the run goes on from its step."""
    import uam_studio.dynaformer.train as train_mod

    _tiny_train(tmp_path / "run", steps=3)
    ck = train_mod.load_checkpoint(tmp_path / "run" / "checkpoint.pt")
    assert ck["step"] == 3
    seen: list[int] = []
    _tiny_train(tmp_path / "run", steps=6, callback=lambda step, loss: seen.append(step))
    assert seen == [4, 5, 6]
    assert train_mod.load_checkpoint(tmp_path / "run" / "checkpoint.pt")["step"] == 6
