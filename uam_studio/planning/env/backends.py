"""The environment's battery backends and the take-off observation it infers the health from.

:class:`BatteryBackend` (reset, fly a leg, recharge) with :class:`PhysicsBattery` (the
electrochemistry model, ground truth) and :class:`DynaformerBattery` (the learned model is the
battery, the paper's setting); :func:`observe_takeoff` / :func:`takeoff_context_current` (the 20 s
take-off observation), :func:`takeoff_health` (a predictor's health PCs from it) and
:func:`fallback_health` (health features without the Dynaformer).
"""

from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np

from uam_studio.battery import DEFAULT_CELL, EOD_RANGE, STATE_NAMES, BatteryState, full_charge, simulate
from uam_studio.battery.eod import first_below
from uam_studio.battery.parameters import PAPER_Q_RANGE, PAPER_R0_RANGE, Cell
from uam_studio.battery.solver import integrate_current
from uam_studio.errors import InputError
from uam_studio.flight import TAKEOFF_CONTEXT_S
from uam_studio.planning.legs import DT_S, fly_takeoff, takeoff_current
from uam_studio.planning.voltage_predictor import VoltagePredictor

CONTEXT_S = TAKEOFF_CONTEXT_S  # s of take-off observed to infer the health (uam_studio.flight.context)
HEALTH_CLIP = 5.0


# ----------------------------------------------------------------------------- health observation


@functools.cache
def takeoff_context_current() -> np.ndarray:
    """Per-cell current (A) of the first 20 s of a take-off (vertical take-off, then climb at 500 m).

    The first 20 s are the same for every leg flown at 500 m, and within 1 % for the other levels.
    """
    cur = np.array(takeoff_current()[:CONTEXT_S])
    cur.setflags(write=False)
    return cur


def observe_takeoff(q_max: float, r0: float) -> tuple[np.ndarray, np.ndarray]:
    """The 20 s observation of a take-off by a fresh cell (physics model): (current A, voltage V)."""
    return np.array(takeoff_context_current()), np.array(_takeoff_voltage(float(q_max), float(r0)))


def takeoff_health(predictor: Any, q_max: float, r0: float) -> tuple[float, float]:
    """A predictor's health (PC1, PC2) of a fresh cell (q_max C, r0 ohm) from its 20 s take-off
    observation (:func:`observe_takeoff`); ``predictor`` has ``health(context_current_a,
    context_voltage_v)`` (a :class:`~uam_studio.dynaformer.DynaformerPredictor`)."""
    pc = np.asarray(predictor.health(*observe_takeoff(q_max, r0)), dtype=float).reshape(-1)
    return float(pc[0]), float(pc[1])


@functools.lru_cache(maxsize=4096)
def _takeoff_voltage(q_max: float, r0: float) -> np.ndarray:
    # the planners' one take-off run (legs.fly_takeoff), down to the lowest cut-off, its first 20 s
    res = fly_takeoff(Cell("take-off check", DEFAULT_CELL, q_max, r0, EOD_RANGE[0]))
    v = np.array(res.voltage_v[:CONTEXT_S])
    v.setflags(write=False)
    return v


@functools.cache
def _fallback_calibration() -> tuple[float, ...]:
    """Constants of :func:`fallback_health`, fitted once on a 7 x 7 grid of simulated cells."""
    q, r = np.meshgrid(np.linspace(*PAPER_Q_RANGE, 7), np.linspace(*PAPER_R0_RANGE, 7))
    cur = takeoff_context_current()
    v = simulate(np.tile(cur, (q.size, 1)), DT_S, q.ravel(), r.ravel(), eod_v=EOD_RANGE[0]).voltage_v
    f1 = (v[:, 0] - v[:, -1]) / cur.mean()
    f2 = v[:, -6] - v[:, -1]
    coef = np.polyfit(f1, f2, 2)
    resid = f2 - np.polyval(coef, f1)
    return (float(f1.mean()), float(f1.std()), *map(float, coef), float(resid.std()))


def fallback_health(context_current_a: np.ndarray, context_voltage_v: np.ndarray) -> np.ndarray:
    """Two PC-like health features from the 20 s take-off observation alone (no Dynaformer).

    * ``h1``: standardised voltage drop over the window per ampere, ``(v[0] - v[-1]) / mean(i)``
      (rises with R0, like the Dynaformer's PC1);
    * ``h2``: standardised slope of the last 5 s, ``v[-6] - v[-1]``, minus its quadratic fit on
      ``h1``'s raw value (falls with q_max, like PC2: a smaller cell sags faster).

    Only observable quantities enter; the standardising constants are fitted once on a grid of
    simulated cells (q_max 5000-8000 C, R0 0.017-0.45 ohm), never on the episode's own cell.
    """
    i = np.asarray(context_current_a, dtype=float).reshape(-1)
    v = np.asarray(context_voltage_v, dtype=float).reshape(-1)
    m1, s1, c2, c1, c0, s2 = _fallback_calibration()
    f1 = (v[0] - v[-1]) / max(float(i.mean()), 1e-6)
    f2 = v[-6] - v[-1] if v.size >= 6 else 0.0
    h = np.array([(f1 - m1) / s1, (f2 - (c2 * f1 * f1 + c1 * f1 + c0)) / s2])
    return np.clip(np.nan_to_num(h), -HEALTH_CLIP, HEALTH_CLIP)


# ----------------------------------------------------------------------------- battery backends


@dataclass(frozen=True)
class LegOutcome:
    """What one leg did to the battery.

    ``voltage_v``: the leg's voltage samples (V), up to and including the first one below the
    cut-off if ``eod``; ``min_voltage_v`` and ``end_voltage_v`` (V) of those samples.
    """

    voltage_v: np.ndarray
    eod: bool
    min_voltage_v: float
    end_voltage_v: float


class BatteryBackend(ABC):
    """The environment's battery: reset once per episode, then fly legs; recharge at the vertiport."""

    name = "backend"

    @abstractmethod
    def reset(self, cell: Cell, context_current_a: np.ndarray | None = None,
              context_voltage_v: np.ndarray | None = None) -> None:
        """Start an episode with a fresh ``cell`` (its parameter set, health q_max C and R0 ohm, and
        cut-off V). The context is the episode's 20 s take-off observation (A, V)."""

    @abstractmethod
    def fly_leg(self, current_a: np.ndarray) -> LegOutcome:
        """Fly one leg with per-cell current ``current_a`` (A, 1 s samples) from the present state."""

    @abstractmethod
    def recharge(self) -> None:
        """Full charge (landing at the vertiport in multi-charge missions)."""


class PhysicsBattery(BatteryBackend):
    """Ground truth: the electrochemistry model, leg by leg from the previous leg's final state.

    Same solver and numbers as :func:`uam_studio.battery.simulate` (it calls the solver directly to
    skip the per-call input checks: the environment's currents are valid by construction).
    """

    name = "physics"

    def reset(self, cell: Cell, context_current_a=None, context_voltage_v=None) -> None:
        self.cell, self.eod_v = cell, float(cell.eod_v)
        self._q_total = np.array([cell.params.q_total(float(cell.q_max))])
        self._r0 = np.array([float(cell.r0)])
        self.recharge()

    def recharge(self) -> None:
        self.state = full_charge(self.cell.q_max, self.cell.params)

    def fly_leg(self, current_a: np.ndarray) -> LegOutcome:
        cur = np.asarray(current_a, dtype=float)[None, :]
        with np.errstate(all="ignore"):
            v, seq = integrate_current(cur, self.state, self._q_total, self._r0, DT_S, self.cell.params)
        v = v[0]
        k = int(first_below(v, self.eod_v))
        if k >= 0:
            v = np.nan_to_num(v[: k + 1], nan=0.0, posinf=0.0, neginf=0.0)
            return LegOutcome(v, True, float(v.min()), float(v[-1]))
        self.state = BatteryState(**{n: seq[n][:, -1].copy() for n in STATE_NAMES})
        return LegOutcome(v, False, float(v.min()), float(v[-1]))


class DynaformerBattery(BatteryBackend):
    """The paper's setting: the learned model is the battery.

    ``predictor.predict(context_current_a, context_voltage_v, current_a, dt_s=1.0)`` returns the
    voltage (V) for ``current_a``, the whole profile flown since the last (re)charge; the context is
    the episode's 20 s take-off observation. Each leg re-predicts the sortie so far plus the new leg;
    the leg ends in EOD at its first predicted sample below the cut-off (the earlier legs of the
    sortie were already flown and are not re-judged).
    """

    name = "dynaformer"

    def __init__(self, predictor: VoltagePredictor) -> None:
        if not isinstance(predictor, VoltagePredictor):
            raise InputError("predictor", "expected an object with predict(context_current_a, "
                                          "context_voltage_v, current_a, dt_s)")
        self.predictor = predictor
        self._sortie = np.zeros(0)

    def reset(self, cell: Cell, context_current_a=None, context_voltage_v=None) -> None:
        self.eod_v = float(cell.eod_v)
        self.context = (np.asarray(context_current_a, dtype=float), np.asarray(context_voltage_v, dtype=float))
        self.recharge()

    def recharge(self) -> None:
        self._sortie = np.zeros(0)

    def fly_leg(self, current_a: np.ndarray) -> LegOutcome:
        profile = np.concatenate([self._sortie, np.asarray(current_a, dtype=float)])
        pred = np.asarray(self.predictor.predict(*self.context, profile, dt_s=DT_S), dtype=float).reshape(-1)
        v = np.nan_to_num(pred[self._sortie.size: profile.size], nan=0.0, posinf=0.0, neginf=0.0)
        k = int(first_below(v, self.eod_v))
        if k >= 0:
            v = v[: k + 1]
            return LegOutcome(v, True, float(v.min()), float(v[-1]))
        self._sortie = profile
        return LegOutcome(v, False, float(v.min()), float(v[-1]))


__all__ = [
    "CONTEXT_S",
    "HEALTH_CLIP",
    "BatteryBackend",
    "DynaformerBattery",
    "LegOutcome",
    "PhysicsBattery",
    "fallback_health",
    "observe_takeoff",
    "takeoff_context_current",
    "takeoff_health",
]
