"""The real data sets the project reads, where each was found, and how to get the full set.

Two sets (:data:`DATASETS`): NASA PCoE's battery lives (``nasa``) and the CMU eVTOL cells (``cmu``). Each is
looked for, in order, at a folder given (``--data``), at its environment variable, beside a source checkout,
and in the sample that ships with the package (:func:`locate`). :func:`describe` says where it was found, how
many cells it holds and whether the files listed in the folder's ``SHA256SUMS`` (if any) hold.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from uam_studio.atomic_io import read_sha256sums, sha256_file
from uam_studio.battery.real import cmu_data, nasa_data

__all__ = ["DATASETS", "DataSet", "describe", "locate"]


@dataclass(frozen=True)
class DataSet:
    """One real data set: its key, title, environment variable, bundled sample folder, the glob of its
    cell files, its citation and where and how to get the full set."""

    key: str
    title: str
    env: str
    sample: Path
    cells_glob: str
    cite: str
    source: str
    steps: str


DATASETS = {
    "nasa": DataSet(
        "nasa", "NASA PCoE Li-ion battery lives (18650, 2 Ah; the paper's own cell type)", nasa_data.DATA_ENV,
        nasa_data.SAMPLE, nasa_data.CELL_GLOB,
        "B. Saha and K. Goebel (2007), \"Battery Data Set\", NASA Prognostics Data Repository, NASA Ames; public",
        "NASA's Prognostics Center of Excellence data set repository (search 'PCoE Battery Data Set'): "
        "zip files of BXXXX.mat, one per cell, 34 cells",
        "unzip them into one folder SRC, then: uam-studio data import nasa SRC --out DIR; "
        f"export {nasa_data.DATA_ENV}=DIR (or pass --data DIR)"),
    "cmu": DataSet(
        "cmu", "CMU eVTOL battery dataset (Sony-Murata US18650VTC6, 3 Ah)", cmu_data.DATA_ENV, cmu_data.SAMPLE,
        cmu_data.CELL_GLOB, "A. Bills et al. (2023), Scientific Data 10, 344; CC BY 4.0",
        f"Carnegie Mellon University's KiltHub repository, DOI {cmu_data.DATASET_DOI} (raw files); this project "
        f"reads the 1 Hz mission {cmu_data.MISSION_FILE} and four lives resampled into MATLAB files "
        f"({', '.join(cmu_data.LIFE_FILES)}), whose sources the sample's PROVENANCE.md names",
        f"put those files in one folder DIR, then: export {cmu_data.DATA_ENV}=DIR (or pass --data DIR)"),
}


def locate(key: str, path: str | os.PathLike | None = None) -> tuple[Path | None, str]:
    """(folder, how it was found: '--data', '$VAR', 'beside the checkout' or 'bundled sample') of data set
    ``key``; (None, why) where there is none."""
    ds = DATASETS[key]
    try:
        folder = nasa_data.nasa_folder(path) if key == "nasa" else cmu_data.data_folder(path)
    except (nasa_data.NasaDataError, ValueError) as err:
        return None, str(err)
    if path is not None:
        return folder, "--data"
    if os.environ.get(ds.env):
        return folder, f"${ds.env}"
    if folder.resolve() == ds.sample.resolve():
        return folder, "bundled sample"
    return folder, "beside the checkout"


def describe(key: str, path: str | os.PathLike | None = None) -> dict:
    """Where data set ``key`` was found (``folder``, ``how``), its ``cells`` (count of cell files) and
    ``checksums``: 'ok (n files)', 'none listed' or the first file whose SHA-256 differs or is missing."""
    ds = DATASETS[key]
    folder, how = locate(key, path)
    out = {"key": key, "title": ds.title, "folder": None if folder is None else str(folder), "how": how,
           "cells": 0, "checksums": "-", "cite": ds.cite, "source": ds.source, "steps": ds.steps}
    if folder is None or not folder.is_dir():
        return out
    out["cells"] = len(list(folder.glob(ds.cells_glob)))
    sums = folder / "SHA256SUMS"
    if not sums.is_file():
        out["checksums"] = "none listed"
        return out
    listed = read_sha256sums(sums.read_text())
    bad = [n for n, h in listed.items() if not (folder / n).is_file() or sha256_file(folder / n) != h]
    out["checksums"] = f"ok ({len(listed)} files)" if not bad else f"MISMATCH: {bad[0]}"
    return out
