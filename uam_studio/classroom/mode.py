"""Fast mode for the classroom notebooks.

Every notebook reads the mode once, at the top::

    from uam_studio.classroom import fast_mode, pick
    FAST = fast_mode()
    steps = pick(fast=3_000, full=60_000)

``UAM_FAST=1`` (also ``true``, ``yes``, ``on``) selects fast mode: small sweeps and short
training runs, so that each notebook runs within 2 minutes on 2 CPU cores (this is what CI
runs; the measured times are in ``benchmarks/RESULTS.md``, "The test suite in minutes"). Unset, empty or
``0``/``false``/``no``/``off`` selects full mode, which reproduces the paper-like figures and takes longer.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TypeVar

from uam_studio.errors import InputError

FAST_ENV_VAR = "UAM_FAST"
_TRUE = ("1", "true", "yes", "on")
_FALSE = ("", "0", "false", "no", "off")

T = TypeVar("T")


def fast_mode() -> bool:
    """True if the environment variable ``UAM_FAST`` selects fast mode.

    :raises InputError: (field ``UAM_FAST``) for a value that is neither true nor false, so a typo
        never silently starts a long full-mode run.
    """
    raw = os.environ.get(FAST_ENV_VAR, "").strip().lower()
    if raw in _TRUE:
        return True
    if raw in _FALSE:
        return False
    raise InputError(FAST_ENV_VAR, f"{raw!r} is not a switch; allowed: 1/true/yes/on or 0/false/no/off (or unset)")


def pick(fast: T, full: T) -> T:
    """``fast`` in fast mode, ``full`` otherwise (see :func:`fast_mode`)."""
    return fast if fast_mode() else full


REPO_ROOT = Path(__file__).resolve().parents[2]
"""The checkout the package runs from in an editable install (``pip install -e .``): it holds
``assets/``, which is not package data (the bundled models are: :mod:`uam_studio.bundled`)."""


def asset_path(name: str) -> Path:
    """Path of a file in the repository's ``assets/`` folder (e.g. ``"example_mission.json"``),
    whatever the notebook's working directory.

    :raises InputError: (field ``asset``) the file is not there, e.g. in a plain (non-editable)
        install, which ships no ``assets/``.
    """
    path = REPO_ROOT / "assets" / name
    if not path.is_file():
        raise InputError("asset", f"{name} is not in {path.parent}; the classroom assets come with the "
                                  "repository checkout (pip install -e .), not with the installed package")
    return path
