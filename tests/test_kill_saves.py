"""Saves that never strand a user: atomic writes, sidecars, stale temp files, kills at random moments.

The kill tests start one child process per kind of save (``python -c``) that imports the library
and builds what it saves once, then, for each kill, forks a process that calls the library's save
function in a loop; the test SIGKILLs that process after a seeded random delay. After each kill,
every final name is absent or loadable with the project's own loader, and every sidecar describes
the file beside it. After all kills the next run in the same folder works and leaves no temp file.
"""

from __future__ import annotations

import json
import os
import random
import selectors
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.atomic_io import (
    STALE_AGE_S,
    atomic_save,
    atomic_write_bytes,
    atomic_write_text,
    read_sha256sums,
    remove_stale_temps,
    temp_path,
)
from uam_studio.errors import InputError

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "assets" / "example_mission.json"

KILLS_PER_KIND = 6
DS_N, DS_LEN = 512, 4096  # dataset kind: 512 discharges of up to 4096 s (a 5.6 MB cache, 0.4 s to save)
DQN_STEPS = 64  # a multiple of the 4 training envs


def _temps(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


# --------------------------------------------------------------------------- the helper itself


def test_atomic_writes_replace_and_leave_no_temp(tmp_path):
    p = tmp_path / "a.bin"
    atomic_write_bytes(p, b"one")
    atomic_write_text(p, "two \u00e9")
    assert p.read_text(encoding="utf-8") == "two \u00e9"
    atomic_save(p, lambda f: np.save(f, np.arange(3)))
    assert np.load(p).tolist() == [0, 1, 2]
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a.bin"]
    os.chmod(p, 0o600)
    atomic_write_bytes(p, b"three")
    assert p.stat().st_mode & 0o777 == 0o600  # an existing file's permission bits are kept
    tmp = temp_path(p)
    assert tmp.parent == tmp_path and tmp.name.startswith(".a.bin.uam-") and tmp.name.endswith(".tmp")


def test_a_failing_writer_keeps_the_old_file_and_removes_its_temp(tmp_path):
    p, side = tmp_path / "w.pt", tmp_path / "meta.json"
    atomic_write_bytes(p, b"old", sidecars={side: "old meta"})

    def boom(f):
        f.write(b"partial")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_save(p, boom, sidecars={side: "new meta"})
    assert p.read_bytes() == b"old" and side.read_text() == "old meta"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["meta.json", "w.pt"]
    with pytest.raises(ValueError, match="its own sidecar"):
        atomic_write_bytes(p, b"x", sidecars={p: "x"})


def test_sidecars_are_deleted_before_the_main_file_is_replaced(tmp_path, monkeypatch):
    """A kill between the replaces leaves no sidecar that describes another main file."""
    p, side = tmp_path / "agent.zip", tmp_path / "card.json"
    atomic_write_bytes(p, b"agent 1", sidecars={side: "card 1"})
    seen: list[tuple[str, bool]] = []
    real_replace = os.replace

    def spy(src, dst):
        seen.append((Path(dst).name, side.exists()))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", spy)
    atomic_write_bytes(p, b"agent 2", sidecars={side: "card 2"})
    assert seen == [("agent.zip", False), ("card.json", False)]
    assert p.read_bytes() == b"agent 2" and side.read_text() == "card 2"


def test_remove_stale_temps_keeps_live_writers_and_young_unknown_files(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    own = temp_path(tmp_path / "a.zip")  # this process is alive: an in-flight write
    gone = Path(str(temp_path(tmp_path / "b.zip")).replace(f"-{os.getpid()}-", f"-{dead.pid}-"))
    legacy_young = tmp_path / ".m.json.abcd1234.tmp"  # tempfile.mkstemp's pattern (older versions)
    legacy_old = tmp_path / ".n.json.wxyz_789.tmp"
    other = tmp_path / ".notes.tmp"  # not a temp file name of ours
    for f in (own, gone, legacy_young, legacy_old, other):
        f.write_bytes(b"x")
    old = time.time() - STALE_AGE_S - 10
    os.utime(legacy_old, (old, old))
    assert remove_stale_temps(tmp_path, names=["m.json"]) == []
    assert sorted(remove_stale_temps(tmp_path)) == sorted([gone, legacy_old])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([own.name, legacy_young.name, other.name])
    os.utime(own, (old, old))
    assert remove_stale_temps(tmp_path) == [own]
    assert remove_stale_temps(tmp_path / "missing") == []


# --------------------------------------------------------------------------- old leftovers


def test_a_truncated_dataset_cache_is_regenerated(tmp_path, capsys):
    """A cache cut short (a kill under an older version) is regenerated on the next run,
    resume or not, with a one-line warning naming the file; never a BadZipFile traceback."""
    from uam_studio.dynaformer.data import DischargeSet, make_dataset
    from uam_studio.dynaformer.model import DynaformerConfig
    from uam_studio.dynaformer.train import TrainConfig, train

    run = tmp_path / "run"
    run.mkdir()
    cfg = TrainConfig(n_train=64, n_context=256, steps=2, batch=8, max_len=256, checkpoint_every=2, device="cpu",
                      threads=1)
    cache = run / "train_data_seed0_n64.npz"
    make_dataset(64, seed=0, max_len=256).save(cache)
    cache.write_bytes(cache.read_bytes()[: cache.stat().st_size // 2])
    with pytest.raises(ValueError, match="not a readable dataset cache"):
        DischargeSet.load(cache)
    model_cfg = DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32)
    for resume in (False, True):
        train(cfg, run, resume=resume, model_cfg=model_cfg)
        assert len(DischargeSet.load(cache)) == 64
        cache.write_bytes(b"")
    warnings = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("warning:")]
    assert len(warnings) == 2 and all(str(cache) in w and "regenerating" in w for w in warnings)


# --------------------------------------------------------------------------- kill tests

_CHILD = r"""
import json, os, signal, sys, time
from pathlib import Path

os.environ["TQDM_DISABLE"] = "1"
import torch

torch.set_num_threads(1)
kind, folder = sys.argv[1], Path(sys.argv[2])
DS_N, DS_LEN, DQN_STEPS = map(int, sys.argv[3:6])
if kind == "dataset":
    from uam_studio.dynaformer.data import make_dataset

    ds = make_dataset(DS_N, seed=0, max_len=DS_LEN)

    def save(i):
        ds.save(folder / f"train_data_seed0_n{DS_N}.npz")
elif kind == "dynaformer":
    from uam_studio.dynaformer.model import DynaformerConfig
    from uam_studio.dynaformer.train import TrainConfig, train

    def save(i, run=folder):  # a whole tiny training run: dataset caches, checkpoints, weights + train_meta.json
        cfg = TrainConfig(n_train=64, n_context=512, steps=4 + i % 4, batch=8, max_len=512, checkpoint_every=2,
                          device="cpu", threads=1)
        train(cfg, run, resume=False,
              model_cfg=DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32))

    save(0, run=folder.parent / "warm-up")  # first-call costs are paid here, not in each victim
elif kind == "dqn":
    from uam_studio.planning.agents.retrain import training_setup
    from uam_studio.planning.agents.dqn.agent_file import save_agent
    from uam_studio.planning.agents.dqn.training import train_dqn

    cfg, env_fn = training_setup("single_charge", steps=DQN_STEPS, seed=0)
    model = train_dqn(cfg, env_fn)  # the default (256, 256) network: a 0.9 MB agent

    def save(i):
        save_agent(model, folder / "agent.zip", {"model": "dqn", "run": f"{os.getpid()}-{i}"},
                   card_file=folder / "card.json")
elif kind == "mission":
    from uam_studio.planning import load_mission, save_mission

    mission = load_mission(sys.argv[6])

    def save(i):
        save_mission(mission.with_battery(q_max=5000.0 + i % 3000), folder / "m.json")
print("ready", flush=True)
for line in sys.stdin:
    delay = float(line)
    pid = os.fork()
    if pid == 0:  # the victim: save in a loop until killed
        try:
            i = 0
            while True:
                save(i)
                i += 1
        finally:
            os._exit(1)
    time.sleep(delay)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    print("killed", flush=True)
"""

_DELAY_S = {"dataset": (0.0, 1.0), "dynaformer": (0.0, 1.2), "dqn": (0.0, 0.15), "mission": (0.0, 0.05)}


def _expect(proc: subprocess.Popen, word: str, timeout_s: float, err: Path) -> None:
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    if not sel.select(timeout_s):
        pytest.fail(f"no {word!r} from the child in {timeout_s} s; stderr:\n{err.read_text()[-3000:]}")
    line = proc.stdout.readline().strip()
    if line != word:
        pytest.fail(f"child said {line!r}, expected {word!r}; stderr:\n{err.read_text()[-3000:]}")


def _check_dataset(folder: Path) -> None:
    from uam_studio.dynaformer.data import DischargeSet

    for p in folder.glob("*.npz"):
        assert len(DischargeSet.load(p)) > 0


def _check_dynaformer(folder: Path) -> None:
    import torch

    from uam_studio.dynaformer.artifact import load_artifact

    _check_dataset(folder)
    weights, meta = folder / "dynaformer.pt", folder / "train_meta.json"
    if weights.exists():
        _, _, stored = load_artifact(weights)
        if meta.exists():  # describes these weights, never an earlier run's
            assert json.loads(meta.read_text()) == json.loads(json.dumps(stored))
    else:
        assert not meta.exists()
    ckpt = folder / "checkpoint.pt"
    if ckpt.exists():
        assert set(torch.load(ckpt, map_location="cpu", weights_only=False)) >= {"model", "opt", "sched", "step"}


def _check_dqn(folder: Path) -> None:
    from uam_studio.planning.agents.dqn.agent_file import load_agent, load_card

    agent, card = folder / "agent.zip", folder / "card.json"
    if agent.exists():
        load_agent(agent)
        if card.exists():  # describes this agent, never the previous one
            inside = load_card(agent)
            assert all(inside.get(k) == v for k, v in json.loads(card.read_text()).items())
    else:
        assert not card.exists()


def _check_mission(folder: Path) -> None:
    from uam_studio.planning import load_mission

    if (folder / "m.json").exists():
        load_mission(folder / "m.json")


def _next_dynaformer_run(folder: Path, n_train: int, max_len: int) -> None:
    from uam_studio.dynaformer.model import DynaformerConfig
    from uam_studio.dynaformer.train import TrainConfig, train

    cfg = TrainConfig(n_train=n_train, n_context=512, steps=8, batch=8, max_len=max_len, checkpoint_every=2,
                      device="cpu", threads=1)
    train(cfg, folder, resume=True, model_cfg=DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1,
                                                               ff_dim=32))
    assert (folder / "dynaformer.pt").is_file() and (folder / "train_meta.json").is_file()


def _next_run(kind: str, folder: Path) -> None:
    if kind == "dataset":
        from uam_studio.dynaformer.data import DischargeSet

        cache = folder / f"train_data_seed0_n{DS_N}.npz"
        before = cache.stat().st_mtime_ns if cache.exists() else None
        _next_dynaformer_run(folder, DS_N, DS_LEN)
        assert len(DischargeSet.load(cache)) == DS_N
        if before is not None:
            assert cache.stat().st_mtime_ns == before  # the cache left by the kills was used as is
    elif kind == "dynaformer":
        _next_dynaformer_run(folder, 64, 512)
        _check_dynaformer(folder)
    elif kind == "dqn":
        from uam_studio.cli import main

        assert main(["train", "dqn", "--steps", str(DQN_STEPS), "--out", str(folder), "--seed", "1"]) == 0
        _check_dqn(folder)
        assert json.loads((folder / "card.json").read_text())["source"] == "cli"
    else:
        from uam_studio.planning import load_mission, save_mission

        save_mission(load_mission(EXAMPLE), folder / "m.json")
        _check_mission(folder)


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork and SIGKILL (POSIX)")
@pytest.mark.parametrize("kind", ["dataset", "dynaformer", "dqn", "mission"])
def test_kills_at_random_moments_never_strand_the_folder(kind, tmp_path, monkeypatch):
    monkeypatch.setenv("TQDM_DISABLE", "1")
    folder = tmp_path / "run"
    folder.mkdir()
    err = tmp_path / "child.err"
    rng = random.Random(f"kill-{kind}")
    check = {"dataset": _check_dataset, "dynaformer": _check_dynaformer, "dqn": _check_dqn,
             "mission": _check_mission}[kind]
    temps_seen = 0
    with open(err, "wb") as err_f:  # noqa: PTH123 - the child's stderr, read on failure
        proc = subprocess.Popen([sys.executable, "-c", _CHILD, kind, str(folder), str(DS_N), str(DS_LEN),
                                 str(DQN_STEPS), str(EXAMPLE)], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=err_f, text=True, cwd=tmp_path)
        try:
            _expect(proc, "ready", 60.0, err)
            for _ in range(KILLS_PER_KIND):
                proc.stdin.write(f"{rng.uniform(*_DELAY_S[kind]):.4f}\n")
                proc.stdin.flush()
                _expect(proc, "killed", 30.0, err)
                temps_seen += bool(_temps(folder))
                check(folder)
        finally:
            proc.stdin.close()
            proc.wait(timeout=30)
    if kind == "dataset":  # the save is most of the loop: most kills land in it
        assert temps_seen > 0
    _next_run(kind, folder)
    assert _temps(folder) == []


class _Killed(BaseException):
    """Stands in for SIGKILL at an injected moment (nothing in the library catches a BaseException)."""


def _check_attention(folder: Path) -> None:
    import torch

    weights, card = folder / "attention_planner.pt", folder / "card.json"
    if weights.exists():
        stored = torch.load(weights, map_location="cpu", weights_only=True)["card"]
        if card.exists():  # describes these weights, never an earlier run's
            assert json.loads(card.read_text()) == stored
    else:
        assert not card.exists()


def _train_attention(folder: Path, seed: int) -> None:
    from uam_studio.planning.agents.attention.model import AttentionConfig
    from uam_studio.planning.agents.attention.train import AttentionTrainConfig, train_attention

    cfg = AttentionTrainConfig(oracle_missions=4, oracle_dest=(2, 3), search_missions=0, epochs=1, workers=1,
                               seed=seed, network=AttentionConfig(d_model=16, heads=2, layers=1, ff=16))
    train_attention(cfg, folder, log=lambda s: None)


def _train_dqn(folder: Path, seed: int) -> None:
    from uam_studio.cli import main

    assert main(["train", "dqn", "--steps", str(DQN_STEPS), "--out", str(folder), "--seed", str(seed)]) == 0


def _train_dynaformer(folder: Path, seed: int) -> None:
    _next_dynaformer_run(folder, 64, 512 + 64 * seed)  # another max_len: a new run, other weights


@pytest.mark.parametrize("kind, weights, card", [
    ("attention", "attention_planner.pt", "card.json"),
    ("dqn", "agent.zip", "card.json"),
    ("dynaformer", "dynaformer.pt", "train_meta.json"),
])
def test_a_kill_between_the_weights_and_the_card_leaves_no_card_of_other_weights(kind, weights, card, tmp_path,
                                                                                 monkeypatch):
    """Every trainer's second run dies (injected) right after its weights replace the first run's and
    before its card is written: the card on disk never describes weights other than those beside it."""
    monkeypatch.setenv("TQDM_DISABLE", "1")
    train = {"attention": _train_attention, "dqn": _train_dqn, "dynaformer": _train_dynaformer}[kind]
    check = {"attention": _check_attention, "dqn": _check_dqn, "dynaformer": _check_dynaformer}[kind]
    folder = tmp_path / "run"
    train(folder, 1)
    first = (folder / weights).read_bytes()
    assert (folder / card).is_file()
    check(folder)
    real_replace = os.replace

    def dies_before_the_card(src, dst):
        if Path(dst).name == card and Path(dst).parent == folder:
            raise _Killed
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", dies_before_the_card)
    with pytest.raises(_Killed):
        train(folder, 2)
    monkeypatch.undo()
    assert (folder / weights).read_bytes() != first  # the kill came after the new weights were in place
    assert not (folder / card).exists()  # the first run's card went before those weights replaced its own
    check(folder)
    train(folder, 3)  # the next run writes both again
    assert (folder / card).is_file()
    check(folder)


@pytest.mark.parametrize("kind, weights", [("attention", "attention_planner.pt"), ("dqn", "agent.zip"),
                                           ("dynaformer", "dynaformer.pt")])
def test_every_trainer_writes_the_weights_sha256_and_a_changed_byte_is_refused(kind, weights, tmp_path, monkeypatch):
    """Each trainer writes ``<weights>.sha256`` with its weights; a loader refuses the weights once a
    byte changes, in one line naming the file, before reading them."""
    import hashlib

    from uam_studio.dynaformer import load_predictor
    from uam_studio.planning.agents.attention.decode import load_policy
    from uam_studio.planning.agents.dqn.agent_file import load_agent

    monkeypatch.setenv("TQDM_DISABLE", "1")
    {"attention": _train_attention, "dqn": _train_dqn, "dynaformer": _train_dynaformer}[kind](tmp_path, 1)
    path = tmp_path / weights
    digest = (tmp_path / f"{weights}.sha256").read_text().split()
    assert digest == [hashlib.sha256(path.read_bytes()).hexdigest(), weights]
    load = {"attention": load_policy, "dqn": load_agent, "dynaformer": load_predictor}[kind]
    load(path)
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(InputError) as err:
        load(path)
    assert str(err.value).startswith(("agent: ", "weights: ")) and str(path) in str(err.value)
    assert "SHA-256" in str(err.value) and "\n" not in str(err.value)


@settings(max_examples=50, deadline=None)
@given(files=st.dictionaries(st.from_regex(r"[A-Za-z0-9_.\-]{1,30}", fullmatch=True),
                             st.binary(min_size=32, max_size=32).map(bytes.hex), max_size=6),
       binary=st.booleans())
def test_sha256sums_read_back_what_sha256sum_writes(files, binary):
    """The manifest and sidecar format: ``<digest>  <name>`` (``*<name>`` in binary mode), upper or
    lower case hex, blank lines between; a sidecar with a digest alone names no file."""
    text = "\n\n".join(f"{d.upper() if binary else d}  {'*' if binary else ''}{n}" for n, d in files.items())
    assert read_sha256sums(text) == files
    assert read_sha256sums("  ABCD \n") == {"": "abcd"}
