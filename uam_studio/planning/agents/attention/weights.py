"""The attention planner's weights file: where the bundled one is, and loading one (safely, cached).

The file is a tensors-only ``torch.save`` of ``{"format": FORMAT, "config", "state_dict", "card"}``,
read with ``weights_only=True``: nothing in it runs.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

from uam_studio.atomic_io import check_digest
from uam_studio.bundled import bundled_path
from uam_studio.errors import InputError
from uam_studio.planning.agents.attention import WEIGHTS_NAME
from uam_studio.planning.agents.attention.model import AttentionConfig, AttentionPolicy
from uam_studio.tensor_files import TensorFileError, load_tensors

__all__ = ["FORMAT", "bundled_weights_path", "load_policy", "load_policy_cached"]

FORMAT = "uam_studio.attention/1"


def bundled_weights_path() -> Path:
    """The bundled attention planner, ``attention_planner.pt`` (:func:`uam_studio.bundled.bundled_path`)."""
    return bundled_path(WEIGHTS_NAME)


def load_policy(path: str | os.PathLike[str] | None = None) -> tuple[AttentionPolicy, dict[str, Any]]:
    """The network and its model card from a weights file (default: the bundled one).

    The file is read with ``torch.load(weights_only=True)`` (:func:`uam_studio.tensor_files.load_tensors`):
    nothing in it runs. :raises InputError: (field ``agent``) a missing, refused or malformed file.
    """
    p = Path(path) if path is not None else bundled_weights_path()
    if not p.is_file():
        raise InputError("agent", f"{p}: no such file (the attention planner's weights)")
    check_digest(p, "agent")  # the SHA-256 written with it, where there is one
    try:
        data = load_tensors(p)
    except TensorFileError as err:
        raise InputError("agent", f"{p}: {err}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise InputError("agent", f"{p}: not an attention planner file (format {FORMAT!r} expected)")
    try:
        config = AttentionConfig(**{k: int(v) for k, v in data["config"].items()})
        net = AttentionPolicy(config)
        net.load_state_dict(data["state_dict"])
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        raise InputError("agent", f"{p}: weights do not fit the network ({' '.join(str(err).split())[:120]})") from None
    net.eval()
    card = data.get("card")
    return net, card if isinstance(card, dict) else {}


@functools.lru_cache(maxsize=4)
def _cached(path: str, mtime_ns: int) -> tuple[AttentionPolicy, dict[str, Any]]:
    return load_policy(path)


def load_policy_cached(path: str | os.PathLike[str] | None = None) -> AttentionPolicy:
    """:func:`load_policy`, cached by path and modification time (the app and the CLI plan often)."""
    p = Path(path) if path is not None else bundled_weights_path()
    try:
        mtime = p.stat().st_mtime_ns
    except OSError:
        mtime = -1
    return _cached(str(p), mtime)[0]
