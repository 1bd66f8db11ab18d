"""Where the real data sets are looked for when no folder is given: beside a source checkout (a
``shared/data/<set>`` folder next to the repository, only when the package runs from one), and the samples
that ship inside the package (``uam_studio/data/samples/<set>``). One home for both data sets' loaders."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["CHECKOUT", "SAMPLES", "SAMPLE_NOTES", "beside_checkout", "in_checkout", "sample_note"]

CHECKOUT = Path(__file__).resolve().parents[3]
"""The repository root when the package runs from a source checkout (else the folder above the package)."""
SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
SAMPLE_NOTES = {
    "nasa_pcoe": "the bundled sample: 1 cell (B0005); for all 34, see `uam-studio data`",
    "cmu_evtol": "the bundled sample: the 1 Hz mission and 1 resampled life (VAH27); for all, see `uam-studio data`",
}
"""One line per data set, said wherever a command or view runs on its sample."""


def in_checkout() -> bool:
    """Whether the package runs from a source checkout (its repository's ``pyproject.toml`` beside it)."""
    return (CHECKOUT / "pyproject.toml").is_file()


def beside_checkout(name: str) -> Path:
    """Where data set ``name`` sits beside a source checkout (looked at only when :func:`in_checkout`)."""
    return CHECKOUT.parent / "shared" / "data" / name


def sample_note(folder: str | os.PathLike) -> str | None:
    """The data set's line of :data:`SAMPLE_NOTES` if ``folder`` is one of the bundled samples, else None."""
    here = Path(folder).resolve()
    return next((note for name, note in SAMPLE_NOTES.items() if here == (SAMPLES / name).resolve()), None)
