"""Saving and loading Dynaformer weights (+ PCA) as one self-describing file, atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import torch

from ..errors import InputError
from .model import Dynaformer, DynaformerConfig

FORMAT = "uam_studio.dynaformer/3"  # 3: config names its health estimator (take-off or transformer)
OLD_FORMATS = ("uam_studio.dynaformer/2",)  # 2: patch encoder + health head (always "transformer")


class WeightsError(InputError):
    """A weights file that is missing, corrupted or incompatible."""

    def __init__(self, path, why: str) -> None:
        super().__init__("weights", f"{path}: {why}")


def atomic_torch_save(obj, path) -> None:
    """torch.save to a temp file in the same folder, then os.replace: never a half-written file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        torch.save(obj, tmp)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_artifact(path, model: Dynaformer, pca: dict, meta: dict) -> None:
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    atomic_torch_save({"format": FORMAT, "config": model.cfg.to_dict(), "state_dict": state,
                       "pca": {k: torch.as_tensor(v) for k, v in pca.items()}, "meta": meta}, path)


def load_artifact(path) -> tuple[Dynaformer, dict, dict]:
    """Return (model in eval mode, pca dict of tensors, meta). Raises WeightsError."""
    path = Path(path)
    if not path.is_file():
        raise WeightsError(path, "file not found")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # corrupted or not a torch file
        raise WeightsError(path, f"not a readable weights file ({type(exc).__name__})") from None
    if not isinstance(blob, dict) or blob.get("format") not in (FORMAT, *OLD_FORMATS):
        raise WeightsError(path, f"incompatible format (expected {FORMAT})")
    try:
        config = dict(blob["config"])
        if blob["format"] in OLD_FORMATS:
            config.setdefault("health", "transformer")
        cfg = DynaformerConfig(**config)
        model = Dynaformer(cfg)
        model.load_state_dict(blob["state_dict"])
        pca = {k: v.float() for k, v in blob["pca"].items()}
        if pca["components"].shape != (2, 2):
            raise ValueError("PCA shape")
    except Exception as exc:
        raise WeightsError(path, f"incompatible weights ({type(exc).__name__}: {str(exc)[:80]})") from None
    model.eval()
    return model, pca, dict(blob.get("meta", {}))
