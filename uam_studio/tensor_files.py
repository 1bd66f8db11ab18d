"""Reading torch files without running code: :func:`load_tensors` (``torch.load(weights_only=True)``)."""

from __future__ import annotations

import os
import pickle
import re
import warnings
from typing import IO, Any

import torch

__all__ = ["TensorFileError", "load_tensors"]


class TensorFileError(ValueError):
    """A torch file that :func:`load_tensors` refused; ``str(err)`` is one line, the reason."""


def _reason(exc: Exception) -> str:
    """One line saying why ``torch.load(weights_only=True)`` failed (torch's own text spans many lines
    and suggests ``weights_only=False``, which would run the file's code)."""
    text = " ".join(str(exc).split())
    if isinstance(exc, pickle.UnpicklingError):
        m = re.search(r"WeightsUnpickler error: (.*?)(?: Please use| Check the documentation|$)", text)
        detail = re.sub(r"\x1b\[[0-9;]*m", "", m.group(1) if m else "").strip().rstrip(".")
        return f"not plain tensor data ({detail[:80] or 'unsupported content'}); not loaded"
    return f"damaged, truncated or not a torch weights file ({type(exc).__name__}: {text[:60]})"


def load_tensors(source: str | os.PathLike[str] | IO[bytes], map_location: Any = "cpu") -> Any:
    """``torch.load(source, weights_only=True)``: only tensors, numbers, strings, ``None``, lists, tuples,
    dicts (and the like, see torch's allowlist) are rebuilt. A file holding anything else is refused by
    torch's restricted unpickler before any object in it is built, so nothing in it runs.

    :param source: a path or a binary file object
    :param map_location: where tensors go (``torch.load``'s argument)
    :raises TensorFileError: one-line reason, for a refused, corrupted or unreadable file
    """
    try:
        with warnings.catch_warnings():  # e.g. torch's note on pickle protocols: the error says enough
            warnings.simplefilter("ignore")
            return torch.load(source, map_location=map_location, weights_only=True)
    except Exception as exc:
        raise TensorFileError(_reason(exc)) from None
