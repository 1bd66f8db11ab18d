"""Synthetic NASA-format cell lives with a known truth: the physics cell discharged at a constant load,
its q_max fading with noise and recovering after rests, sampled every 10 s with 2 mV of sensor noise."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np

from uam_studio.battery.real.nasa_data import COLUMNS, LOADED_A, NasaCell, NasaDischarge, load_nasa_cell
from uam_studio.battery.simulate import simulate

SAMPLE_S = 10


def synthetic_rows(seed: int, n: int = 40, load_a: float = 2.0, ambient_c: float = 24.0) -> list[list[float]]:
    """Rows (in :data:`COLUMNS` order) of a life of ``n`` discharges at ``load_a`` (A)."""
    rng = np.random.default_rng(seed)
    q0, r0 = rng.uniform(6500, 7600), rng.uniform(0.09, 0.14)
    rows, uid = [], 1000 * seed
    q = q0
    for k in range(n):
        q = q * (1 - rng.uniform(0.001, 0.004)) + (q0 * 0.02 if rng.random() < 0.1 else 0.0)
        q = min(q, q0) * (1 + rng.normal(0, 0.002))
        r = r0 * (1 + 0.004 * k)
        res = simulate(np.full(9000, load_a), 1.0, q, r, 2.7)
        v = res.voltage_v[res.valid][::SAMPLE_S]
        volts = np.r_[4.19, v] + rng.normal(0, 0.002, v.size + 1)
        amps = np.r_[0.0, np.full(v.size, load_a)]
        uid += int(rng.integers(2, 4))
        for s, (vv, ii) in enumerate(zip(volts, amps)):
            rows.append([k, uid, ambient_c, SAMPLE_S * s, round(float(vv), 5), -ii, ambient_c, -ii, 0.0])
    return rows


def write_cell(path: Path, rows: list[list[float]]) -> Path:
    """Write rows as a NASA-format ``BXXXX.csv.gz``."""
    with gzip.open(path, "wt") as fh:
        fh.write(",".join(COLUMNS) + "\n")
        for r in rows:
            fh.write(",".join(str(x) for x in r) + "\n")
    return path


def synthetic_cell(tmp: Path, seed: int, **kw) -> NasaCell:
    """A synthetic life written to ``tmp`` and loaded back."""
    return load_nasa_cell(write_cell(tmp / f"B{9000 + seed:04d}.csv.gz", synthetic_rows(seed, **kw)))


__all__ = ["LOADED_A", "NasaDischarge", "synthetic_cell", "synthetic_rows", "write_cell"]
