"""Saving and loading Dynaformer weights (+ PCA) as one self-describing file, atomically, and where the
bundled weights of each cell type are."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from ..atomic_io import atomic_save, check_digest
from ..bundled import bundled_path
from ..errors import InputError
from .cells import dynaformer_cell
from .model import Dynaformer, DynaformerConfig

FORMAT = "uam_studio.dynaformer/3"  # 3: config names its health estimator (take-off or transformer)
OLD_FORMATS = ("uam_studio.dynaformer/2",)  # 2: patch encoder + health head (always "transformer")


class WeightsError(InputError):
    """A weights file that is missing, corrupted or incompatible."""

    def __init__(self, path, why: str) -> None:
        super().__init__("weights", f"{path}: {why}")


def atomic_torch_save(obj: Any, path: str | os.PathLike[str], *,
                      sidecars: Mapping[str | os.PathLike[str], bytes | str] | None = None) -> None:
    """``torch.save(obj)`` to ``path`` atomically (:func:`uam_studio.atomic_io.atomic_save`), creating
    its folder; ``sidecars``: files describing ``path``, written with it (see there), and its SHA-256
    (``<name>.sha256``, checked by :func:`load_artifact`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_save(path, lambda f: torch.save(obj, f), sidecars=sidecars, digest=True)


def save_artifact(path: str | os.PathLike[str], model: Dynaformer, pca: dict, meta: dict, *,
                  sidecars: Mapping[str | os.PathLike[str], bytes | str] | None = None) -> None:
    """Write the weights file ``path`` (format :data:`FORMAT`: config, weights, PCA, ``meta``) atomically.

    :param sidecars: files describing the weights (e.g. ``train_meta.json``): written with them, so
        a sidecar that exists always describes the weights beside it.
    """
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    atomic_torch_save({"format": FORMAT, "config": model.cfg.to_dict(), "state_dict": state,
                       "pca": {k: torch.as_tensor(v) for k, v in pca.items()}, "meta": meta}, path,
                      sidecars=sidecars)


def load_artifact(path) -> tuple[Dynaformer, dict, dict]:
    """Return (model in eval mode, pca dict of tensors, meta). Raises WeightsError."""
    path = Path(path)
    if not path.is_file():
        raise WeightsError(path, "file not found")
    check_digest(path, "weights")  # the SHA-256 written with it, where there is one
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
    bad = [k for k, v in [*blob["state_dict"].items(), *pca.items()]
           if torch.is_tensor(v) and v.is_floating_point() and not bool(torch.isfinite(v).all())]
    if bad:
        raise WeightsError(path, f"{len(bad)} tensors hold NaN or inf values (first: {bad[0]})")
    model.eval()
    return model, pca, dict(blob.get("meta", {}))


def bundled_weights_path(cell: str = "nasa18650") -> Path:
    """The bundled weights for the cell type ``cell``: for the NASA cell ``$UAM_STUDIO_DYNAFORMER`` if
    set, else ``dynaformer.pt`` in the user folder's ``pretrained/`` or in the package data
    (:func:`uam_studio.bundled.bundled_path`); for the VTC6 ``dynaformer_vtc6.pt`` there."""
    return bundled_path(dynaformer_cell(cell).weights_file)
