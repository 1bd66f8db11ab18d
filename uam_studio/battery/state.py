"""The eight named states of the electrochemistry model, batched over trajectories."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from uam_studio.battery.parameters import DEFAULT_CELL, Q_MAX_RANGE, CellParameters
from uam_studio.errors import InputError, check_range

STATE_NAMES = ("tb", "vo", "vsn", "vsp", "qnb", "qns", "qpb", "qps")


@dataclass(frozen=True)
class BatteryState:
    """Batched cell state; every field has shape [B].

    tb (K) cell temperature; vo, vsn, vsp (V) ohmic and surface overpotentials;
    qnb, qns, qpb, qps (C) bulk and surface charge of the negative and positive
    electrodes. Same states as progpy's BatteryElectroChemEOD (tb, Vo, Vsn, Vsp,
    qnB, qnS, qpB, qpS).
    """

    tb: np.ndarray
    vo: np.ndarray
    vsn: np.ndarray
    vsp: np.ndarray
    qnb: np.ndarray
    qns: np.ndarray
    qpb: np.ndarray
    qps: np.ndarray

    @property
    def batch_size(self) -> int:
        return int(np.shape(self.tb)[0])

    def __getitem__(self, index) -> BatteryState:
        """Select trajectories, e.g. ``state[3]`` or ``state[mask]`` (keeps a batch axis)."""
        return BatteryState(*(np.atleast_1d(getattr(self, f.name)[index]) for f in fields(self)))

    def as_array(self) -> np.ndarray:
        """Shape [B, 8] in the order of ``STATE_NAMES``."""
        return np.stack([getattr(self, n) for n in STATE_NAMES], axis=-1)

    @classmethod
    def from_array(cls, arr: np.ndarray) -> BatteryState:
        arr = np.atleast_2d(np.asarray(arr, dtype=float))
        return cls(*(arr[:, k].copy() for k in range(len(STATE_NAMES))))


def full_charge(q_max, cell: CellParameters = DEFAULT_CELL) -> BatteryState:
    """State of a rested, fully charged cell for each ``q_max`` (C), shape [B].

    This is also what "recharging" at the vertiport resets the cell to.

    :raises InputError: (field ``q_max``) for no cell, or a q_max outside :data:`Q_MAX_RANGE` (C).
    """
    q_max = np.atleast_1d(np.asarray(q_max, dtype=float))
    if q_max.size == 0:
        raise InputError("q_max", "is empty; give the capacity (C) of at least one cell")
    ok = (q_max >= Q_MAX_RANGE[0]) & (q_max <= Q_MAX_RANGE[1])  # False for NaN
    if not ok.all():
        check_range("q_max", float(q_max[~ok][0]), *Q_MAX_RANGE, " C")
    q_total = cell.q_total(q_max)
    f_s = cell.vol_s_fraction
    zeros = np.zeros_like(q_max)
    return BatteryState(
        tb=zeros + cell.t_ambient_k,
        vo=zeros.copy(),
        vsn=zeros.copy(),
        vsp=zeros.copy(),
        qnb=q_total * cell.xn_max * (1.0 - f_s),
        qns=q_total * cell.xn_max * f_s,
        qpb=q_total * cell.xp_min * (1.0 - f_s),
        qps=q_total * cell.xp_min * f_s,
    )


def rested_state(q_max, removed_c, cell: CellParameters = DEFAULT_CELL) -> BatteryState:
    """A rested cell (no overpotentials, ambient temperature) with ``removed_c`` (C, [B] or scalar)
    taken out of a full charge, spread over surface and bulk by volume."""
    full = full_charge(q_max, cell)
    removed = np.broadcast_to(np.asarray(removed_c, dtype=float), full.tb.shape)
    f_s = cell.vol_s_fraction
    return BatteryState(
        tb=full.tb, vo=full.vo, vsn=full.vsn, vsp=full.vsp,
        qnb=full.qnb - removed * (1.0 - f_s), qns=full.qns - removed * f_s,
        qpb=full.qpb + removed * (1.0 - f_s), qps=full.qps + removed * f_s,
    )
