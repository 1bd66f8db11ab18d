"""Synthetic training data for the Dynaformer, from our own flight and battery models.

Deterministic by seed, per cell type (:mod:`uam_studio.dynaformer.cells`). Two profile families:

* flight-like: for the NASA cell, random missions of 1-6 legs (distance, continuous altitude,
  wind, optional dwell at 0 A), built with :func:`uam_studio.flight.leg_profile`; for the VTC6,
  random missions of the CMU eVTOL dataset's shape flown by power (:func:`power_mission_profile`),
  the current being what the cell draws (P / V);
* generic (the published Dynaformer's): constant and piecewise-constant currents with 0-6
  switches (0.05-3 A for the NASA cell, 0.5-18 A for the VTC6).

Voltage targets come from :func:`uam_studio.battery.simulate` (or its constant-power twin) on
the type's parameter set, run to a 2.5 V cut-off, below the 3.0 V EOD, so the model learns the knee
around EOD. All samples are on a 1 s grid (the model's native grid).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..atomic_io import atomic_save
from ..battery import PAPER_Q_RANGE, PAPER_R0_RANGE, simulate
from ..battery.simulate import simulate_constant_power
from ..flight import leg_profile, min_leg_distance_km
from ..flight.tables import WIND_RANGE_KTS
from .cells import NASA_TRAINING, DynaformerCell, dynaformer_cell

GRID_DT_S = 1.0
TARGET_CUTOFF_V = 2.5  # V: targets are simulated down to here
TRAIN_Q_RANGE = PAPER_Q_RANGE  # C: the NASA cell's training box is the paper's health box
TRAIN_R_RANGE = PAPER_R0_RANGE  # ohm


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
        wind = float(rng.uniform(*WIND_RANGE_KTS))
        dwell = float(rng.uniform(0.0, 900.0)) if rng.random() < 0.5 else 0.0
        parts.append(leg_profile(dist, alt, wind, dt_s=GRID_DT_S, dwell_s=dwell).current_a)
        if sum(p.size for p in parts) >= max_len:
            break
    return np.concatenate(parts)[:max_len]


# Take-off and landing power per cell (W) and time (s), cruise power (W) and time (s), rest (s) of a
# random mission of the CMU eVTOL dataset's shape (its protocol: 54 W, 16 W, 54 W per cell).
POWER_TAKEOFF_W, POWER_CRUISE_W = (40.0, 65.0), (8.0, 30.0)
POWER_TAKEOFF_S, POWER_CRUISE_S, POWER_REST_S = (45.0, 120.0), (100.0, 1500.0), (0.0, 900.0)


def power_mission_profile(rng: np.random.Generator, max_len: int) -> np.ndarray:
    """Per-cell power (W) of a random 1-4 leg mission of the CMU dataset's shape on the 1 s grid (take-off,
    cruise, landing, then a rest at 0 W with probability 0.5), at most max_len samples."""
    parts, total = [], 0
    for _ in range(int(rng.integers(1, 5))):
        for power, span in ((POWER_TAKEOFF_W, POWER_TAKEOFF_S), (POWER_CRUISE_W, POWER_CRUISE_S),
                            (POWER_TAKEOFF_W, POWER_TAKEOFF_S)):
            parts.append(np.full(int(rng.uniform(*span)), rng.uniform(*power)))
        if rng.random() < 0.5:
            parts.append(np.zeros(int(rng.uniform(*POWER_REST_S))))
        total = sum(p.size for p in parts)
        if total >= max_len:
            break
    return np.concatenate(parts)[:max_len]


def _generic_length(rng: np.random.Generator, max_len: int, kind: DynaformerCell, mean_a: float) -> int:
    """A generic load's length (s) that usually reaches EOD at its mean current ``mean_a`` (A; at least a tenth
    of the type's top current), at least 600 s, capped at ``max_len``."""
    charge_c, floor_a = 7000.0 * kind.u_ref_c / NASA_TRAINING.u_ref_c, kind.generic_a[1] / 10
    return int(min(max_len, max(600.0, rng.uniform(0.6, 1.3) * charge_c / max(mean_a, floor_a))))


def generic_profile(rng: np.random.Generator, max_len: int, kind: DynaformerCell = NASA_TRAINING) -> np.ndarray:
    """Constant or piecewise-constant current (A) in ``kind.generic_a`` (0.05-3 A for the NASA cell),
    0-6 switches; for a type with a ``square_wave_share``, that share of them a square wave instead
    (:func:`square_wave_profile`)."""
    if kind.square_wave_share and rng.random() < kind.square_wave_share:
        return square_wave_profile(rng, max_len, kind)
    n_switch = int(rng.integers(0, 7))
    levels = rng.uniform(*kind.generic_a, n_switch + 1)
    length = _generic_length(rng, max_len, kind, float(levels.mean()))
    cuts = np.sort(rng.integers(1, length, n_switch)) if n_switch else np.array([], int)
    out = np.empty(length)
    edges = np.concatenate([[0], cuts, [length]])
    for k in range(n_switch + 1):
        out[edges[k]:edges[k + 1]] = levels[k]
    return out


def square_wave_profile(rng: np.random.Generator, max_len: int, kind: DynaformerCell) -> np.ndarray:
    """A square wave (A): a level in [1 A, top of ``kind.generic_a``] for a half-period of 5-20 s, then 0 A as
    long (the NASA PCoE data set's 4 A square wave, logged about every 10 s, is 10 s on and 10 s off)."""
    level = rng.uniform(1.0, kind.generic_a[1])
    half = int(rng.integers(5, 21))
    length = _generic_length(rng, max_len, kind, level / 2.0)
    return np.where((np.arange(length) // half) % 2 == 0, level, 0.0)


def sample_health(rng: np.random.Generator, n: int, band: str = "train", kind: DynaformerCell = NASA_TRAINING):
    """q_max (C) and r0 (ohm) for n cells of type ``kind``: the training box, or the extrapolation band
    (NASA cell: q_max in [4000, 5000] or [8000, 9000], or r0 in [0.45, 0.5]: at least one outside)."""
    if band == "train":
        return rng.uniform(*kind.q_range, n), rng.uniform(*kind.r0_range, n)
    (q_lo, q_lo_top), (q_hi_bottom, q_hi) = kind.extra_q_bands
    q = rng.uniform(q_lo, q_hi, n)
    r = rng.uniform(kind.r0_range[0], kind.extra_r_band[1], n)
    which = rng.integers(0, 3, n)  # 0: q outside, 1: r outside, 2: both
    lo_or_hi = rng.random(n) < 0.5
    q_out = np.where(lo_or_hi, rng.uniform(q_lo, q_lo_top, n), rng.uniform(q_hi_bottom, q_hi, n))
    q = np.where(which != 1, q_out, q)
    r = np.where(which != 0, rng.uniform(*kind.extra_r_band, n), r)
    return q, r


def make_dataset(n: int, seed: int, max_len: int | None = None, flight_fraction: float | None = None,
                 band: str = "train", batch: int = 512, cell: str = "nasa18650") -> DischargeSet:
    """Generate n discharges (profiles, health, physics voltage) of the cell type ``cell``
    (:mod:`uam_studio.dynaformer.cells`), deterministic by seed; ``max_len`` samples (s), default the
    type's (10240 for the NASA cell); ``flight_fraction``: the share of flights, default the type's."""
    kind = dynaformer_cell(cell)
    flight_fraction = kind.flight_fraction if flight_fraction is None else flight_fraction
    max_len = kind.max_len if max_len is None else int(max_len)
    rng = np.random.default_rng(seed)
    q, r = sample_health(rng, n, band, kind)
    family = (rng.random(n) >= flight_fraction).astype(np.int8)
    by_power = kind.loads == "power"
    cur = np.zeros((n, max_len), np.float32)  # current (A), or power (W) for the flights of a power type
    length = np.zeros(n, np.int64)
    for k in range(n):
        if family[k]:
            p = generic_profile(rng, max_len, kind)
        else:
            p = power_mission_profile(rng, max_len) if by_power else flight_profile(rng, max_len)
        cur[k, :p.size] = p
        length[k] = p.size
    volt = np.zeros((n, max_len), np.float32)
    valid = np.zeros((n, max_len), bool)
    inside = np.arange(max_len)[None, :]
    for s in range(0, n, batch):
        rows = np.arange(s, min(n, s + batch))
        for power in ((False, True) if by_power else (False,)):
            sel = rows[(family[rows] == 0) == power] if by_power else rows
            if sel.size == 0:
                continue
            run = simulate_constant_power if power else simulate
            res = run(cur[sel].astype(float), GRID_DT_S, q[sel], r[sel], eod_v=TARGET_CUTOFF_V, cell=kind.params)
            if power:  # the current drawn; after the cut-off (P / V of a held voltage) the last one, held
                last = np.maximum(res.valid.sum(1) - 1, 0)
                held = np.where(res.valid, res.current_a, res.current_a[np.arange(sel.size), last][:, None])
                cur[sel] = np.where(inside < length[sel, None], held, 0.0)
            volt[sel] = res.voltage_v
            valid[sel] = res.valid & (inside < length[sel, None])
    return DischargeSet(cur, volt, valid, length, q, r, family)
