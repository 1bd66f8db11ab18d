"""The DQN agent file: an SB3 zip with a model card inside, saved atomically and loaded without
unpickling (SB3's save_util, for our agents).

Public API: :func:`save_agent` (atomic, with a model card inside the zip), :func:`load_agent`,
:func:`load_card`, :func:`network_description`; :data:`CARD_NAME`, :data:`AGENT_ENTRIES`,
:data:`OPTIONAL_AGENT_ENTRIES`, :data:`NETWORK_KEY`.

Loading never unpickles: :func:`load_agent` checks the zip's entry names, reads SB3's ``data`` entry
as plain JSON (its ``":serialized:"`` values are never decoded), rebuilds the network from the model
card or the JSON's readable fields, and loads the weights with ``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from uam_studio.atomic_io import atomic_write_bytes, check_digest
from uam_studio.errors import InputError
from uam_studio.planning.agents.dqn.masked import MaskedDQN, MaskedDQNPolicy

__all__ = ["AGENT_ENTRIES", "CARD_NAME", "FORMAT", "MAX_ENTRY_BYTES", "NETWORK_KEY", "OPTIONAL_AGENT_ENTRIES",
           "load_agent", "load_card", "network_description", "save_agent"]

CARD_NAME = "card.json"
"""Name of the model card inside an agent zip."""
NETWORK_KEY = "network"
"""Model card entry describing the network (:func:`network_description`)."""
AGENT_ENTRIES = ("data", "policy.pth")
"""Zip entries every agent file has: SB3's settings (JSON) and the policy's weights (tensors only)."""
OPTIONAL_AGENT_ENTRIES = ("policy.optimizer.pth", "pytorch_variables.pth", "_stable_baselines3_version",
                          "system_info.txt", CARD_NAME)
"""Zip entries an agent file may also have (the rest of what SB3's ``save`` and :func:`save_agent`
write). :func:`load_agent` refuses a zip with any other entry."""
MAX_ENTRY_BYTES = 256 * 2**20  # uncompressed size of one zip entry, bytes
FORMAT = "uam_studio.dqn/1"


def save_agent(model: MaskedDQN, path: str | os.PathLike[str], card: dict[str, Any],
               card_file: str | os.PathLike[str] | None = None) -> None:
    """Save ``model`` and its model ``card`` (JSON-serialisable dict) as one SB3 zip, atomically.

    The SB3 zip is built in memory with the card added as ``card.json``, then written with
    :func:`uam_studio.atomic_io.atomic_write_bytes` (creating the folder): a kill never leaves a
    half-written agent, and its SHA-256 beside it (``<name>.sha256``, checked at load). The replay
    buffer is not saved. The card gets a ``network`` entry
    (:func:`network_description`: spaces and layer sizes), which :func:`load_agent` builds the network from.

    :param card_file: also write the card as this JSON file beside the agent, as a sidecar of the
        zip: the old one is deleted before the agent is replaced and the new one written after, so
        an existing card file always describes the agent beside it.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    card_json = json.dumps({"format": FORMAT, **card, NETWORK_KEY: network_description(model)}, indent=2,
                           sort_keys=True, default=str)
    buf = io.BytesIO()
    model.save(buf)
    with zipfile.ZipFile(buf, mode="a") as zf:
        zf.writestr(CARD_NAME, card_json)
    sidecars = {card_file: json.dumps(card, indent=2, default=str) + "\n"} if card_file is not None else None
    atomic_write_bytes(p, buf.getvalue(), sidecars=sidecars, digest=True)


def _read_agent_bytes(path: str | os.PathLike[str]) -> tuple[Path, bytes]:
    p = Path(path)
    if not p.is_file():
        raise InputError("agent", f"{p}: file not found")
    check_digest(p, "agent")  # the SHA-256 written with it, where there is one
    data = p.read_bytes()
    if not zipfile.is_zipfile(io.BytesIO(data)):
        raise InputError("agent", f"{p}: not a DQN agent file (not a zip archive)")
    return p, data


def load_card(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The model card saved with an agent by :func:`save_agent` (``{}`` for a plain SB3 zip).

    :raises InputError: (field ``agent``) for a missing or unreadable file
    """
    p, data = _read_agent_bytes(path)
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            if CARD_NAME not in zf.namelist():
                return {}
            card = json.loads(zf.read(CARD_NAME).decode())
    except Exception as exc:
        raise InputError("agent", f"{p}: unreadable model card ({type(exc).__name__})") from None
    if not isinstance(card, dict):
        raise InputError("agent", f"{p}: model card is not a JSON object")
    return card


def network_description(model: MaskedDQN) -> dict[str, Any]:
    """What :func:`load_agent` rebuilds ``model``'s network from, as plain JSON: the policy class name,
    ``net_arch`` (hidden layer widths), the observation space (flat ``Box``: shape, dtype, bounds) and
    the action space (``Discrete``: n, start)."""
    obs, act = model.observation_space, model.action_space
    return {
        "policy_class": type(model.policy).__name__,
        "net_arch": [int(w) for w in model.policy.net_arch],
        "observation_space": {"type": "Box", "shape": list(obs.shape or ()), "dtype": str(obs.dtype),
                              "low": obs.low.tolist(), "high": obs.high.tolist()},  # type: ignore[attr-defined]
        "action_space": {"type": "Discrete", "n": int(act.n), "start": int(act.start)},  # type: ignore[attr-defined]
    }


def _short(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (one line: repr escapes newlines)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


_SERIALIZED = ":serialized:"
# Keys of SB3's ``data`` JSON that SB3 stores pickled (as ":serialized:"). They are never decoded; any
# other pickled key refuses the file.
_SERIALIZED_KEYS = frozenset({
    "policy_class", "observation_space", "action_space", "_last_obs", "_last_episode_starts",
    "_last_original_obs", "ep_info_buffer", "ep_success_buffer", "replay_buffer_class", "train_freq",
    "lr_schedule", "exploration_schedule", "learning_rate", "action_noise",
})
_BOX_TYPES = ("Box", "<class 'gymnasium.spaces.box.Box'>")  # card, SB3 data
_DISCRETE_TYPES = ("Discrete", "<class 'gymnasium.spaces.discrete.Discrete'>")
# Plain settings of SB3's ``data`` JSON passed to MaskedDQN(...): kind and allowed range.
_SETTINGS: dict[str, tuple[type, float, float]] = {
    "learning_rate": (float, 0.0, 1e3), "buffer_size": (int, 1, 10**7), "learning_starts": (int, 0, 10**12),
    "batch_size": (int, 1, 10**6), "tau": (float, 0.0, 1.0), "gamma": (float, 0.0, 1.0),
    "gradient_steps": (int, -1, 10**6), "optimize_memory_usage": (bool, 0, 1), "n_steps": (int, 1, 1000),
    "target_update_interval": (int, 1, 10**12), "exploration_fraction": (float, 0.0, 1.0),
    "exploration_initial_eps": (float, 0.0, 1.0), "exploration_final_eps": (float, 0.0, 1.0),
    "max_grad_norm": (float, 0.0, 1e12), "double_dqn": (bool, 0, 1), "seed": (int, 0, 2**32 - 1),
    "random_warmup": (bool, 0, 1),
}
# Plain training counters of SB3's ``data`` JSON, set on the model after it is built.
_COUNTERS: dict[str, tuple[type, float, float]] = {
    "num_timesteps": (int, 0, 10**15), "_total_timesteps": (int, 0, 10**15),
    "_num_timesteps_at_start": (int, 0, 10**15), "_episode_num": (int, 0, 10**15), "_n_updates": (int, 0, 10**15),
    "_n_calls": (int, 0, 10**15), "exploration_rate": (float, 0.0, 1.0),
    "_current_progress_remaining": (float, -1e6, 1.0),  # below 0 when the last vec-env step overshoots
}


def _plain_values(p: Path, data: dict[str, Any], spec: dict[str, tuple[type, float, float]]) -> dict[str, Any]:
    """The keys of ``spec`` that ``data`` holds as plain JSON values (pickled or null ones are left out).

    :raises InputError: (field ``agent``) a plain value of the wrong type or out of its range
    """
    out: dict[str, Any] = {}
    for key, (kind, lo, hi) in spec.items():
        v = data.get(key)
        if v is None or (isinstance(v, dict) and _SERIALIZED in v):
            continue
        if kind is bool:
            ok = isinstance(v, bool)
        elif kind is int:
            ok = isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi
        else:
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and lo <= v <= hi  # NaN fails too
            v = float(v) if ok else v
        if not ok:
            raise InputError("agent", f"{p}: corrupted agent file (setting {key} = {_short(v)})")
        out[key] = v
    return out


def _int_field(v: Any, lo: int, hi: int) -> int | None:
    """``v`` (an int, or an int written as text by SB3) if it is in [lo, hi], else None."""
    if isinstance(v, bool) or not isinstance(v, (int, str)):
        return None
    try:
        i = int(v)
    except ValueError:
        return None
    return i if lo <= i <= hi else None


def _float_vector(v: Any, n: int, dtype: np.dtype) -> np.ndarray | None:
    """A 1-D array of ``n`` numbers from a JSON list or from numpy's text of one (as SB3 writes it), else None."""
    if isinstance(v, str):
        text = v.strip()
        if not (text.startswith("[") and text.endswith("]")) or "[" in text[1:-1] or "..." in text:
            return None  # not 1-D, or numpy's summary of a long array
        try:
            vals = [float(x) for x in text[1:-1].split()]
        except ValueError:
            return None
    elif isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        vals = [float(x) for x in v]
    else:
        return None
    return np.array(vals, dtype=dtype) if len(vals) == n else None


def _spaces(p: Path, obs: Any, act: Any) -> tuple[gym.spaces.Box, gym.spaces.Discrete]:
    """The observation (flat ``Box``) and action (``Discrete``) spaces from their plain description:
    the card's (:func:`network_description`) or the readable fields SB3 writes beside a pickled space.

    :raises InputError: (field ``agent``) a description that is missing or not a flat Box / Discrete
    """
    from gymnasium import spaces

    def bad(what: str) -> InputError:
        return InputError("agent", f"{p}: incompatible agent (cannot read its {what}; a masked DQN needs "
                                   "a flat Box observation space and a Discrete action space)")

    if not isinstance(obs, dict) or (obs.get("type") or obs.get(":type:")) not in _BOX_TYPES:
        raise bad("observation space")
    shape = obs.get("shape", obs.get("_shape"))
    dtype = obs.get("dtype")
    if not (isinstance(shape, list) and len(shape) == 1 and dtype in ("float32", "float64")):
        raise bad("observation space")
    n_obs = _int_field(shape[0], 1, 10**7)
    if n_obs is None:
        raise bad("observation space")
    low, high = (_float_vector(obs.get(k), n_obs, np.dtype(dtype)) for k in ("low", "high"))
    if low is None or high is None or not bool(np.all(low <= high)):
        raise bad("observation space")
    if not isinstance(act, dict) or (act.get("type") or act.get(":type:")) not in _DISCRETE_TYPES:
        raise bad("action space")
    n_act, start = _int_field(act.get("n"), 1, 10**6), _int_field(act.get("start", 0), -10**9, 10**9)
    if n_act is None or start is None:
        raise bad("action space")
    return spaces.Box(low, high, shape=(n_obs,), dtype=np.dtype(dtype)), spaces.Discrete(n_act, start=start)


# The policy's module as SB3 records it: today's, and uam_studio.planning.dqn (agents saved before the
# planning package was split into rooms, the bundled ones among them).
_OWN_POLICY_MODULES = (MaskedDQNPolicy.__module__, "uam_studio.planning.agents.dqn",
                       "uam_studio.planning.dqn")  # and its former homes


def _policy_class_name(pc: Any) -> str:
    """The class name in the readable fields SB3 writes beside a pickled policy class (its methods'
    reprs, ``<function Name.method at ...>``), prefixed by its module unless that is this package's
    :mod:`~uam_studio.planning.agents.dqn.masked`; ``"unknown"`` if there is none."""
    if not isinstance(pc, dict):
        return "unknown"
    names = [v[len("<function "):].split(".", 1)[0] for v in pc.values()
             if isinstance(v, str) and v.startswith("<function ") and "." in v]
    if not names:
        return "unknown"
    module = pc.get("__module__")
    return names[0] if module in _OWN_POLICY_MODULES else f"{module}.{names[0]}"


def _zip_entries(p: Path, zf: zipfile.ZipFile) -> set[str]:
    """The entry names of an agent zip, after checking them (nothing is decompressed here).

    :raises InputError: (field ``agent``) an entry that is not one of :data:`AGENT_ENTRIES` and
        :data:`OPTIONAL_AGENT_ENTRIES`, a duplicate or oversized entry, or a missing required one
    """
    infos = zf.infolist()
    names = [i.filename for i in infos]
    allowed = (*AGENT_ENTRIES, *OPTIONAL_AGENT_ENTRIES)
    extra = [n for n in names if n not in allowed]
    if extra:
        raise InputError("agent", f"{p}: refused: unexpected entry {_short(extra[0], 40)} in the agent zip "
                                  f"(allowed: {', '.join(allowed)}); nothing in it was loaded")
    if len(set(names)) != len(names):
        raise InputError("agent", f"{p}: refused: duplicate entries in the agent zip; nothing in it was loaded")
    big = [i.filename for i in infos if i.file_size > MAX_ENTRY_BYTES]
    if big:
        raise InputError("agent", f"{p}: refused: entry {big[0]!r} is over {MAX_ENTRY_BYTES // 2**20} MiB")
    missing = [n for n in AGENT_ENTRIES if n not in names]
    if missing:
        raise InputError("agent", f"{p}: not a DQN agent file (no {missing[0]!r} entry)")
    return set(names)


def _read_json_entry(p: Path, zf: zipfile.ZipFile, name: str) -> dict[str, Any]:
    """Entry ``name`` parsed as a JSON object (plain JSON: nothing in it is decoded further)."""
    try:
        obj = json.loads(zf.read(name))
    except Exception as exc:
        raise InputError("agent", f"{p}: corrupted agent file ({name}: {type(exc).__name__})") from None
    if not isinstance(obj, dict):
        raise InputError("agent", f"{p}: corrupted agent file ({name} is not a JSON object)")
    return obj


def _read_tensors_entry(p: Path, zf: zipfile.ZipFile, name: str) -> dict[str, Any]:
    """Entry ``name`` loaded with :func:`uam_studio.tensor_files.load_tensors` (``torch.load(weights_only=True)``:
    tensors, numbers, strings, containers only; anything else is refused before it is built)."""
    from uam_studio.tensor_files import TensorFileError, load_tensors

    try:
        raw = zf.read(name)
    except Exception as exc:
        raise InputError("agent", f"{p}: corrupted agent file ({name}: {type(exc).__name__})") from None
    try:
        obj = load_tensors(io.BytesIO(raw))
    except TensorFileError as err:
        raise InputError("agent", f"{p}: corrupted or unsafe agent file ({name}: {err})") from None
    if not isinstance(obj, dict):
        raise InputError("agent", f"{p}: corrupted agent file ({name} is not a state dict)")
    return obj


def load_agent(path: str | os.PathLike[str], env: gym.Env | None = None) -> MaskedDQN:
    """Load an agent saved by :func:`save_agent` (on CPU), without unpickling anything.

    The zip's entry names are checked first (exactly :data:`AGENT_ENTRIES`, plus any of
    :data:`OPTIONAL_AGENT_ENTRIES`). SB3's ``data`` entry and the card are read as plain JSON; the
    pickled (``":serialized:"``) values in ``data`` are never decoded, and a pickled value under a key
    SB3 does not pickle refuses the file. The network is rebuilt as a
    :class:`~uam_studio.planning.agents.dqn.masked.MaskedDQNPolicy` from the card's ``network`` entry
    (:func:`network_description`), or for files without one from the readable fields SB3 writes beside
    the pickled spaces and from ``policy_kwargs``; the training settings and counters come from the
    plain values of ``data``. The weights (``policy.pth``) and optimizer state (``policy.optimizer.pth``)
    are loaded with ``torch.load(weights_only=True)``; ``pytorch_variables.pth`` is not read (a DQN has
    no such variables).

    :param path: the agent zip
    :param env: optional env to check the agent against (same observation and action spaces)
    :raises InputError: (field ``agent``) for a missing, corrupted, unexpected or incompatible file
    """
    p, raw = _read_agent_bytes(path)
    try:
        zf = zipfile.ZipFile(io.BytesIO(raw))
    except Exception as exc:
        raise InputError("agent", f"{p}: corrupted agent file ({type(exc).__name__})") from None
    with zf:
        names = _zip_entries(p, zf)
        data = _read_json_entry(p, zf, "data")
        card = _read_json_entry(p, zf, CARD_NAME) if CARD_NAME in names else {}
        pickled = [k for k, v in data.items()
                   if isinstance(v, dict) and _SERIALIZED in v and k not in _SERIALIZED_KEYS]
        if pickled:
            raise InputError("agent", f"{p}: refused: unexpected pickled setting {_short(pickled[0], 40)} in "
                                      "the agent's data; nothing in it was loaded")
        network = card.get(NETWORK_KEY)
        network = network if isinstance(network, dict) else {}
        policy_name = network.get("policy_class") if network else _policy_class_name(data.get("policy_class"))
        if policy_name != MaskedDQNPolicy.__name__:
            raise InputError("agent", f"{p}: incompatible agent (policy {_short(policy_name, 40)}, "
                                      "expected MaskedDQNPolicy)")
        policy_kwargs = data.get("policy_kwargs", {})
        if not (isinstance(policy_kwargs, dict) and set(policy_kwargs) <= {"net_arch"}):
            raise InputError("agent", f"{p}: incompatible agent (policy settings other than net_arch)")
        net_arch = network.get("net_arch") if network else policy_kwargs.get("net_arch")
        if net_arch is not None and not (isinstance(net_arch, list) and len(net_arch) <= 16 and all(
                isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= 2**16 for w in net_arch)):
            raise InputError("agent", f"{p}: incompatible agent (net_arch {_short(net_arch)})")
        if network:
            obs_space, act_space = _spaces(p, network.get("observation_space"), network.get("action_space"))
        else:
            obs_space, act_space = _spaces(p, data.get("observation_space"), data.get("action_space"))
        settings = _plain_values(p, data, _SETTINGS)
        counters = _plain_values(p, data, _COUNTERS)
        config = card.get("config")
        train_freq = config.get("train_freq") if isinstance(config, dict) else None  # SB3 pickles its own
        if isinstance(train_freq, int) and not isinstance(train_freq, bool) and 1 <= train_freq <= 10**9:
            settings["train_freq"] = train_freq
        n_envs = _int_field(data.get("n_envs", 1), 1, 10**4)
        if n_envs is None:
            raise InputError("agent", f"{p}: corrupted agent file (setting n_envs = "
                                      f"{_short(data.get('n_envs'))})")
        weights = _read_tensors_entry(p, zf, "policy.pth")
        optimizer = (_read_tensors_entry(p, zf, "policy.optimizer.pth") if "policy.optimizer.pth" in names
                     else None)
    try:
        policy_kwargs = {"net_arch": list(net_arch)} if net_arch is not None else {}
        model = MaskedDQN(MaskedDQNPolicy, None, device="cpu", policy_kwargs=policy_kwargs,
                          _init_setup_model=False, **settings)
        model.observation_space, model.action_space, model.n_envs = obs_space, act_space, n_envs
        model._setup_model()
        model.policy.load_state_dict(weights)  # strict: same layers, same shapes
        if optimizer is not None:
            model.policy.optimizer.load_state_dict(optimizer)
    except Exception as exc:
        msg = " ".join(str(exc).split())[:100]
        raise InputError("agent", f"{p}: corrupted or incompatible agent file ({type(exc).__name__}: {msg})") \
            from None
    for key, value in counters.items():
        setattr(model, key, value)
    if env is not None and (env.observation_space != model.observation_space
                            or env.action_space != model.action_space):
        raise InputError("agent", f"{p}: incompatible with this environment (agent expects observations "
                                  f"{model.observation_space.shape} and {model.action_space}; env has "
                                  f"{env.observation_space.shape} and {env.action_space})")
    return model
