"""Synthetic training data for the Dynaformer, from our own flight and battery models.

Deterministic by seed. Two profile families:

* flight-like: random missions of 1-6 legs (distance, continuous altitude, wind,
  optional dwell at 0 A), built with :func:`uam_studio.flight.leg_profile`;
* generic (the published Dynaformer's): constant and piecewise-constant currents,
  0.05-3 A with 1-6 switches.

Voltage targets come from :func:`uam_studio.battery.simulate` run to a 2.5 V
cut-off, below the 3.0 V EOD, so the model learns the knee around EOD. All
samples are on a 1 s grid (the model's native grid).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..atomic_io import atomic_save
from ..battery import PAPER_Q_RANGE, PAPER_R0_RANGE, simulate
from ..flight import leg_profile, min_leg_distance_km

GRID_DT_S = 1.0
TARGET_CUTOFF_V = 2.5  # V: targets are simulated down to here
TRAIN_Q_RANGE = PAPER_Q_RANGE  # C: the training cells fill the paper's health box
TRAIN_R_RANGE = PAPER_R0_RANGE  # ohm
EXTRA_Q_BANDS = ((4000.0, 5000.0), (8000.0, 9000.0))  # C
EXTRA_R_BAND = (0.45, 0.5)  # ohm


@dataclass
class DischargeSet:
    """Padded arrays of N discharges on the 1 s grid.

    current_a, voltage_v: [N, T] float32 (A, V); valid: [N, T] bool (target above
    the 2.5 V cut-off and inside the profile); length: [N] samples of profile;
    q_max (C), r0 (ohm): [N]; kind: [N] 0 = flight, 1 = generic.
    """

    current_a: np.ndarray
    voltage_v: np.ndarray
    valid: np.ndarray
    length: np.ndarray
    q_max: np.ndarray
    r0: np.ndarray
    kind: np.ndarray

    def __len__(self) -> int:
        return int(self.q_max.shape[0])

    def subset(self, idx) -> DischargeSet:
        return DischargeSet(*(getattr(self, f)[idx] for f in self.__dataclass_fields__))

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the arrays to ``path`` as compressed ``.npz``, atomically (the folder must exist)."""
        arrays = {f: getattr(self, f) for f in self.__dataclass_fields__}
        atomic_save(path, lambda f: np.savez_compressed(f, **arrays))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> DischargeSet:
        """Read a set written by :meth:`save`.

        :raises ValueError: a file that is not a complete, consistent set (truncated or corrupt
            zip, missing array, arrays of mismatched lengths), with the cause in the message.
        :raises OSError: a file that is missing or cannot be opened (FileNotFoundError, PermissionError,
            IsADirectoryError).
        """
        try:
            with np.load(path, allow_pickle=False) as z:
                ds = cls(**{f: z[f] for f in cls.__dataclass_fields__})
        except (FileNotFoundError, PermissionError, IsADirectoryError):
            raise
        except Exception as exc:  # zipfile.BadZipFile, zlib.error, KeyError, EOFError, ValueError, OSError
            raise ValueError(f"{path}: not a readable dataset cache ({type(exc).__name__}: "
                             f"{' '.join(str(exc).split())[:100]})") from None
        n, shape = len(ds), ds.current_a.shape
        if any(getattr(ds, f).shape[:1] != (n,) for f in cls.__dataclass_fields__) or \
                ds.voltage_v.shape != shape or ds.valid.shape != shape:
            raise ValueError(f"{path}: not a readable dataset cache (arrays of mismatched shapes)")
        return ds


def flight_profile(rng: np.random.Generator, max_len: int) -> np.ndarray:
    """Per-cell current (A) of a random 1-6 leg mission on the 1 s grid, at most max_len samples."""
    parts = []
    for _ in range(int(rng.integers(1, 7))):
        alt = float(rng.uniform(500.0, 3000.0))
        lo = max(min_leg_distance_km(alt) + 0.1, 8.0)
        dist = float(rng.uniform(lo, max(lo + 1.0, 65.0)))
        wind = float(rng.uniform(-39.0, 39.0))
        dwell = float(rng.uniform(0.0, 900.0)) if rng.random() < 0.5 else 0.0
        parts.append(leg_profile(dist, alt, wind, dt_s=GRID_DT_S, dwell_s=dwell).current_a)
        if sum(p.size for p in parts) >= max_len:
            break
    return np.concatenate(parts)[:max_len]


def generic_profile(rng: np.random.Generator, max_len: int) -> np.ndarray:
    """Constant or piecewise-constant current (A), 0.05-3 A, 0-6 switches."""
    n_switch = int(rng.integers(0, 7))
    levels = rng.uniform(0.05, 3.0, n_switch + 1)
    # Pick a length that usually reaches EOD for the mean level, capped at max_len.
    length = int(min(max_len, max(600.0, rng.uniform(0.6, 1.3) * 7000.0 / max(levels.mean(), 0.3))))
    cuts = np.sort(rng.integers(1, length, n_switch)) if n_switch else np.array([], int)
    out = np.empty(length)
    edges = np.concatenate([[0], cuts, [length]])
    for k in range(n_switch + 1):
        out[edges[k]:edges[k + 1]] = levels[k]
    return out


def sample_health(rng: np.random.Generator, n: int, band: str = "train"):
    """q_max (C) and r0 (ohm) for n cells: the training box, or the extrapolation band
    (q_max in [4000, 5000] or [8000, 9000], or r0 in [0.45, 0.5]: at least one outside)."""
    if band == "train":
        return rng.uniform(*TRAIN_Q_RANGE, n), rng.uniform(*TRAIN_R_RANGE, n)
    q = rng.uniform(4000.0, 9000.0, n)
    r = rng.uniform(0.017, 0.5, n)
    which = rng.integers(0, 3, n)  # 0: q outside, 1: r outside, 2: both
    lo_or_hi = rng.random(n) < 0.5
    q_out = np.where(lo_or_hi, rng.uniform(*EXTRA_Q_BANDS[0], n), rng.uniform(*EXTRA_Q_BANDS[1], n))
    q = np.where(which != 1, q_out, q)
    r = np.where(which != 0, rng.uniform(*EXTRA_R_BAND, n), r)
    return q, r


def make_dataset(n: int, seed: int, max_len: int = 10240, flight_fraction: float = 0.7,
                 band: str = "train", batch: int = 512) -> DischargeSet:
    """Generate n discharges (profiles, health, physics voltage), deterministic by seed."""
    rng = np.random.default_rng(seed)
    q, r = sample_health(rng, n, band)
    kind = (rng.random(n) >= flight_fraction).astype(np.int8)
    cur = np.zeros((n, max_len), np.float32)
    length = np.zeros(n, np.int64)
    for k in range(n):
        p = generic_profile(rng, max_len) if kind[k] else flight_profile(rng, max_len)
        cur[k, :p.size] = p
        length[k] = p.size
    volt = np.zeros((n, max_len), np.float32)
    valid = np.zeros((n, max_len), bool)
    for s in range(0, n, batch):
        e = min(n, s + batch)
        res = simulate(cur[s:e].astype(float), dt_s=GRID_DT_S, q_max=q[s:e], r0=r[s:e], eod_v=TARGET_CUTOFF_V)
        volt[s:e] = res.voltage_v
        valid[s:e] = res.valid & (np.arange(max_len)[None, :] < length[s:e, None])
    return DischargeSet(cur, volt, valid, length, q, r, kind)
