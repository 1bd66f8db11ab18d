"""The DQN environment's observation: its layout (:data:`FEATURE_NAMES`, :data:`OBS_DIM`) and how it is built
from the episode's state (:func:`static_features` once per episode, :func:`observe` per step). The layout is
the trained agents' input: changing it retires every bundled DQN."""

from __future__ import annotations

import numpy as np

from uam_studio.battery.parameters import DEFAULT_EOD_V
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.legs import N_ACTIONS, N_MAX, N_TARGETS, VERTIPORT_SLOT, LegTable
from uam_studio.planning.missions.scenario import SCENARIOS

FEATURE_BOUND = 10.0

# ----------------------------------------------------------------------------- observation layout

_SLOT_FEATURES = ("present", "dx", "dy", "dist", "priority", "visited", "wind")
FEATURE_NAMES: tuple[str, ...] = (
    ("health_pc1", "health_pc2", "voltage", "x", "y", "n_reached", "charge_used")
    + tuple(f"slot{k}_{f}" for k in range(N_MAX) for f in _SLOT_FEATURES)
    + ("vertiport_dx", "vertiport_dy", "vertiport_dist", "vertiport_wind")
    + tuple(f"scenario_{s}" for s in SCENARIOS)
    + ("eod_v",)
    + tuple(f"slot{k}_round_trip_charge" for k in range(N_MAX))
    + ("home_charge",)
)
N_FEATURES = len(FEATURE_NAMES)  # 80
OBS_DIM = N_FEATURES + N_ACTIONS  # 116
_SLOT0 = 7
_VP = _SLOT0 + 7 * N_MAX
_SCEN = _VP + 4
_EOD = _SCEN + 3
_TRIP = _EOD + 1  # per-slot round-trip charge, then the charge to get home
_SLOT_IDX = _SLOT0 + 7 * np.arange(N_MAX)  # start of each slot's block

V_CENTER, V_SCALE = 3.6, 0.5
POS_SCALE_KM = 100.0
CHARGE_SCALE_C = 8000.0
WIND_SCALE_KT = WIND_RANGE_KTS[1]


def static_features(legs: LegTable, health: np.ndarray, scenario: str, eod_v: float) -> tuple[np.ndarray, np.ndarray]:
    """The episode's fixed features [N_FEATURES] (health, slots present, priorities, winds, scenario, EOD
    cut-off in V) and the relative positions per node the aircraft can be at, [from, to, (dx, dy, dist)]
    in units of :data:`POS_SCALE_KM`."""
    base = np.zeros(N_FEATURES)
    base[0:2] = health
    present = legs.present[:N_MAX]
    base[_SLOT_IDX] = present
    base[_SLOT_IDX + 4] = legs.priority[:N_MAX] / 3.0
    base[_SLOT_IDX + 6] = legs.wind[:N_MAX] / WIND_SCALE_KT
    base[_VP + 3] = legs.wind[VERTIPORT_SLOT] / WIND_SCALE_KT
    base[_SCEN + SCENARIOS.index(scenario)] = 1.0
    base[_EOD] = (eod_v - DEFAULT_EOD_V) / 0.5
    rel = np.zeros((N_TARGETS, N_TARGETS, 3))
    rel[:, :, 0] = (legs.pos[None, :, 0] - legs.pos[:, None, 0]) / POS_SCALE_KM
    rel[:, :, 1] = (legs.pos[None, :, 1] - legs.pos[:, None, 1]) / POS_SCALE_KM
    rel[:, :, 2] = legs.dist / POS_SCALE_KM
    rel[:, :N_MAX] *= legs.present[None, :N_MAX, None]
    return base, rel


def observe(base: np.ndarray, rel_all: np.ndarray, legs: LegTable, node: int, voltage_v: float, n_reached: int,
            charge_c: float, visited: np.ndarray, servable: np.ndarray, mask: np.ndarray,
            out: np.ndarray) -> np.ndarray:
    """The observation [OBS_DIM] at ``node`` (features clipped to +-FEATURE_BOUND, then the action mask),
    written into ``out`` and returned as a copy: the cell's last voltage (V), its position, the
    destinations reached, the charge used (C), each slot's relative position and visited flag, and the
    cheapest charge (C) of each unvisited servable slot's round trip and of the way home."""
    f = base.copy()
    f[2] = (voltage_v - V_CENTER) / V_SCALE
    f[3:5] = (legs.pos[node] - legs.pos[VERTIPORT_SLOT]) / POS_SCALE_KM
    f[5] = n_reached / N_MAX
    f[6] = charge_c / CHARGE_SCALE_C
    rel = rel_all[node]
    f[_SLOT_IDX + 1] = rel[:N_MAX, 0]
    f[_SLOT_IDX + 2] = rel[:N_MAX, 1]
    f[_SLOT_IDX + 3] = rel[:N_MAX, 2]
    f[_SLOT_IDX + 5] = visited
    f[_VP:_VP + 3] = rel[VERTIPORT_SLOT]
    vp = VERTIPORT_SLOT
    for k in np.flatnonzero(servable & ~visited):
        trip = legs.cheapest_charge(node, int(k)) + legs.cheapest_charge(int(k), vp) if k != node else 0.0
        f[_TRIP + k] = trip / CHARGE_SCALE_C if np.isfinite(trip) else FEATURE_BOUND
    f[_TRIP + N_MAX] = 0.0 if node == vp else legs.cheapest_charge(node, vp) / CHARGE_SCALE_C
    np.clip(f, -FEATURE_BOUND, FEATURE_BOUND, out=f)
    out[:N_FEATURES] = f
    out[N_FEATURES:] = mask
    return out.copy()
