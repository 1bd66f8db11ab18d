"""The world of one flight: the true cell, the actual winds, scripted events and the sensors.

Two worlds (:data:`WORLDS`):

- ``"varied"`` (:data:`DEFAULT_WORLD`): the pack is not its model. Its parameter set is its own
  (:func:`~uam_studio.battery.pack_variation.pack_params`: diffusion, surface/bulk split, rate constants, time
  constants, open-circuit curve and heat drawn around the cell type's, by pack number), and each sensor has a slowly
  drifting offset beside its white noise (:data:`DRIFT_SD_MV`, :data:`DRIFT_SD_MA`, an Ornstein-Uhlenbeck process
  with time constant :data:`DRIFT_TAU_S`: assumptions, a calibrated pack sensor's offset of a few mV).
- ``"model"``: the pack is exactly the cell type's model at the mission's health, the sensors only white noise. For
  teaching: what the belief does when nothing but q_max and R0 is unknown.

Nothing in :mod:`uam_studio.planning.operations.operator` imports this module or holds a
:class:`World`: the flight loop (:mod:`~uam_studio.planning.operations.fly`) hands the operator
only the :class:`Readings` a leg produced and the clock.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from uam_studio.battery import BatteryState, full_charge
from uam_studio.battery.pack_variation import pack_params
from uam_studio.battery.simulate import simulate_cell
from uam_studio.errors import InputError, check_range, check_seed, short_repr
from uam_studio.flight import TAKEOFF_CONTEXT_S, leg_profile
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.legs import DT_S
from uam_studio.planning.missions.mission import VERTIPORT, Mission
from uam_studio.planning.operations.defaults import (
    DEFAULT_FORECAST_SIGMA_KT,
    DEFAULT_SENSOR_NOISE_MA,
    DEFAULT_SENSOR_NOISE_MV,
)

TAKEOFF_CHECK_S = TAKEOFF_CONTEXT_S  # s of take-off the operator reads before its first plan
MAX_SIGMA_KT = 60.0
MAX_NOISE_MV = 100.0
MAX_NOISE_MA = 1000.0
_EVENT = re.compile(r"^wind([+-]\d+(?:\.\d+)?)@(\d+(?:\.\d+)?)$", re.ASCII)  # ASCII digits only
MAX_EVENTS = 20  # scripted wind changes in one flight
WORLDS = ("varied", "model")  # the pack is not its model / the pack is its model (module docstring)
DEFAULT_WORLD = "varied"  # the default: an operator never flies its own model
DRIFT_SD_MV = 3.0  # mV: std of the voltage sensor's drifting offset (varied world)
DRIFT_SD_MA = 10.0  # mA: std of the current sensor's drifting offset (varied world)
DRIFT_TAU_S = 1800.0  # s: the offsets' correlation time
_DRIFT_SD = np.array([DRIFT_SD_MV * 1e-3, DRIFT_SD_MA * 1e-3])  # V, A: the offsets' std


def check_world(world: str) -> str:
    """``world`` if it is one of :data:`WORLDS`; one line naming field ``world`` otherwise."""
    if world not in WORLDS:
        raise InputError("world", f"{short_repr(world)}: allowed {', '.join(WORLDS)}")
    return world


@dataclass(frozen=True)
class WindEvent:
    """From ``start_s`` (s after the first take-off) on, the wind on every leg that takes off then
    or later is ``delta_kts`` (kt) stronger (negative: weaker; the result is clipped to the tables'
    -39..39 kt). A leg already in the air keeps the wind it took off in."""

    start_s: float
    delta_kts: float

    @property
    def text(self) -> str:
        """The event in the CLI's syntax, e.g. ``wind+30@1200``: each number as its shortest decimal that reads back
        exactly (:func:`parse_event` of it is this event: a record's events fly the same world again)."""
        def num(x: float, sign: bool = False) -> str:
            return np.format_float_positional(x, trim="-", sign=sign)

        return f"wind{num(self.delta_kts, True)}@{num(self.start_s)}"


def parse_event(text: str) -> WindEvent:
    """``"wind+30@1200"`` -> :class:`WindEvent` (30 kt more headwind from t = 1200 s).

    :raises InputError: (field ``event``) for anything else.
    """
    m = _EVENT.match(str(text).strip().replace(" ", ""))
    if m is None:
        raise InputError("event", f"{str(text)[:60]!r} is not an event; allowed: wind+KT@S or wind-KT@S, "
                                  "e.g. wind+30@1200 (30 kt more headwind from t = 1200 s)")
    delta = check_range("event", float(m.group(1)), -2 * WIND_RANGE_KTS[1], 2 * WIND_RANGE_KTS[1], " kt")
    start = check_range("event", float(m.group(2)), 0.0, 7 * 86_400.0, " s")
    return WindEvent(start, delta)


@dataclass(frozen=True)
class Readings:
    """What the sensors report during one stretch of flight, at 1 Hz.

    ``time_s`` (s since the first take-off, end of each sample), ``current_a`` (A, per cell) and
    ``voltage_v`` (V), both with sensor noise; ``landed`` is False for the take-off check (still
    in the air) and for a leg on which the cell fell below the cut-off.
    """

    time_s: np.ndarray
    current_a: np.ndarray
    voltage_v: np.ndarray
    landed: bool


@dataclass
class WorldLeg:
    """The truth of one flown leg (kept by the world for the record, never given to the operator)."""

    from_node: str
    to: str
    altitude_m: float
    wind_kts: float
    start_s: float
    end_s: float
    min_voltage_v: float
    breached: bool


class World:
    """The hidden truth of one flight.

    :param mission: the mission; its ``battery`` is the true cell and its winds are the forecast.
    :param forecast_sigma_kt: std (kt) of the forecast error drawn once per node (each destination's
        wind and the vertiport's return wind), in [0, 60].
    :param sensor_noise_mv: std of the voltage sensor (mV), in [0, 100].
    :param sensor_noise_ma: std of the current sensor (mA), in [0, 1000].
    :param events: scripted :class:`WindEvent` s.
    :param seed: seeds the forecast errors and the sensor noise (and the sensors' drift).
    :param world: ``"varied"`` (default) or ``"model"`` (module docstring).
    :param pack: the pack's number: seeds its own parameter set in the varied world (None: ``seed``). The same pack
        flies with the same parameters in every world that names it (its logbook's flights and this one).
    """

    def __init__(self, mission: Mission, forecast_sigma_kt: float = DEFAULT_FORECAST_SIGMA_KT,
                 sensor_noise_mv: float = DEFAULT_SENSOR_NOISE_MV, sensor_noise_ma: float = DEFAULT_SENSOR_NOISE_MA,
                 events: Sequence[WindEvent] = (), seed: int = 0, world: str = DEFAULT_WORLD,
                 pack: int | None = None) -> None:
        self.mission = mission
        self.forecast_sigma_kt = check_range("forecast_sigma_kt", forecast_sigma_kt, 0.0, MAX_SIGMA_KT, " kt")
        self.sensor_noise_mv = check_range("sensor_noise_mv", sensor_noise_mv, 0.0, MAX_NOISE_MV, " mV")
        self.sensor_noise_ma = check_range("sensor_noise_ma", sensor_noise_ma, 0.0, MAX_NOISE_MA, " mA")
        events = tuple(events)
        if len(events) > MAX_EVENTS:
            raise InputError("event", f"{len(events)} events; at most {MAX_EVENTS} allowed in one flight")
        bad = [e for e in events if not isinstance(e, WindEvent)]
        if bad:
            raise InputError("event", f"expected WindEvent items (parse_event('wind+30@1200') makes one), "
                                      f"got {short_repr(bad[0])}")
        self.events = tuple(sorted(events, key=lambda e: e.start_s))
        seed = check_seed("seed", seed)
        rng = np.random.default_rng([seed, 0x5EED])
        lo, hi = WIND_RANGE_KTS
        errors = rng.normal(0.0, self.forecast_sigma_kt, size=len(mission.node_names))
        self.base_winds = {name: float(np.clip(mission.node(name).wind_kts + e, lo, hi))
                           for name, e in zip(mission.node_names, errors)}
        self._noise = np.random.default_rng([seed, 0x5E45])
        self.world = check_world(world)
        self.pack = check_seed("pack", seed if pack is None else pack)
        self.cell = mission.cell  # the true cell: parameter set, q_max (C), R0 (ohm), cut-off (V)
        self._drift: np.ndarray | None = None  # the sensors' offsets now (V, A); None: no drift
        if self.world == "varied":
            self.cell = dataclasses.replace(self.cell, params=pack_params(self.cell.params, self.pack))
            self._drift_rng = np.random.default_rng([seed, 0xD21F])
            self._drift = self._drift_rng.normal(0.0, 1.0, 2) * _DRIFT_SD
        self.time_s = 0.0
        self.node = VERTIPORT
        self.state: BatteryState = full_charge(self.cell.q_max, self.cell.params)
        self.legs: list[WorldLeg] = []
        self.breached = False
        self._checked_s = 0  # samples of the current leg already flown by the take-off check
        self._takeoff_current: np.ndarray | None = None
        self.last_true_voltage_v = np.zeros(0)  # noise-free voltage (V) of the last stretch flown
        self.last_true_current_a = np.zeros(0)  # and its current (A)

    # ------------------------------------------------------------------ truth
    def change_kts(self, t_s: float) -> float:
        """The scripted events' change of every leg's wind (kt, + headwind) for a leg taking off at ``t_s`` (s)."""
        return sum(e.delta_kts for e in self.events if e.start_s <= t_s)

    def wind(self, to: str, t_s: float) -> float:
        """Actual wind (kt) on a leg to ``to`` that takes off at ``t_s`` (s)."""
        return float(np.clip(self.base_winds[to] + self.change_kts(t_s), *WIND_RANGE_KTS))

    def _offsets(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The sensors' drifting offsets (V, A) over the next ``n`` samples (zeros in the model world)."""
        if self._drift is None or n == 0:
            return np.zeros(n), np.zeros(n)
        a = float(np.exp(-DT_S / DRIFT_TAU_S))
        sd = _DRIFT_SD * np.sqrt(1.0 - a * a)
        kick = self._drift_rng.normal(0.0, 1.0, (2, n)) * sd[:, None]
        out = np.stack([lfilter([1.0], [1.0, -a], kick[k], zi=[a * self._drift[k]])[0] for k in range(2)])
        self._drift = out[:, -1].copy()
        return out[0], out[1]

    def _sense(self, current: np.ndarray, voltage: np.ndarray, t0: float, landed: bool) -> Readings:
        n = current.size
        off_v, off_a = self._offsets(n)
        cur = current + self._noise.normal(0.0, self.sensor_noise_ma * 1e-3, n) + off_a
        volt = voltage + self._noise.normal(0.0, self.sensor_noise_mv * 1e-3, n) + off_v
        return Readings(t0 + DT_S * np.arange(1, n + 1), cur, volt, landed)

    def _fly(self, current: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, bool]:
        res = simulate_cell(current, self.cell, DT_S, initial_state=self.state)
        k = current.size if not res.eod_reached else int(np.argmax(~res.valid)) + 1
        self.state = res.final_state
        self.last_true_voltage_v = np.asarray(res.voltage_v[:k], dtype=float)
        self.last_true_current_a = np.asarray(current[:k], dtype=float)
        return current[:k], self.last_true_voltage_v, float(res.min_voltage_v), bool(res.eod_reached)

    # ------------------------------------------------------------------ the flight
    def takeoff_check(self, profile_current: np.ndarray) -> Readings:
        """Fly the first ``TAKEOFF_CHECK_S`` s of a take-off (every leg's first 15.5 s are the same
        vertical take-off) and return the readings; the next :meth:`fly_leg` continues that leg."""
        if self.time_s != 0.0 or self.legs:
            raise InputError("takeoff_check", "only before the first leg")
        cur = np.asarray(profile_current[:TAKEOFF_CHECK_S], dtype=float)
        flown, volt, _, breached = self._fly(cur)
        self._checked_s = flown.size
        self._takeoff_current = cur
        self.breached = breached
        r = self._sense(flown, volt, 0.0, landed=False)
        self.time_s = DT_S * flown.size
        return r

    def fly_leg(self, to: str, altitude_m: float) -> Readings:
        """Fly from the current node to ``to`` at ``altitude_m`` (m) in the actual wind; return the readings.

        Arriving at the vertiport recharges the cell. After a breach nothing more is flown.
        """
        if self.breached:
            raise InputError("fly_leg", "the aircraft was lost at the cut-off; nothing more can be flown")
        start = self.time_s - DT_S * self._checked_s
        wind = self.wind(to, start)
        m = self.mission
        prof = leg_profile(m.distance_km(self.node, to), altitude_m, wind, DT_S,
                           getattr(m.node(to), "dwell_s", 0.0))
        cur = np.asarray(prof.current_a, dtype=float)
        if self._checked_s and self._takeoff_current is not None:
            cur = np.concatenate([self._takeoff_current[: self._checked_s], cur[self._checked_s:]])
        rest = cur[self._checked_s:]
        t0 = self.time_s
        flown, volt, vmin, breached = self._fly(rest)
        self.legs.append(WorldLeg(self.node, to, float(altitude_m), wind, start, t0 + DT_S * flown.size,
                                  vmin, breached))
        self._checked_s = 0
        self.time_s = t0 + DT_S * flown.size
        self.breached = breached
        if not breached:
            self.node = to
            if to == VERTIPORT:
                self.state = full_charge(self.cell.q_max, self.cell.params)
        return self._sense(flown, volt, t0, landed=not breached)


def actual_winds_mission(mission: Mission, winds: dict[str, float]) -> Mission:
    """A copy of ``mission`` whose winds are ``winds`` (kt by node name): the hindsight oracle's map."""
    dests = tuple(dataclasses.replace(d, wind_kts=winds[d.name]) for d in mission.destinations)
    vp = dataclasses.replace(mission.vertiport, wind_kts=winds[VERTIPORT])
    return dataclasses.replace(mission, vertiport=vp, destinations=dests)


__all__ = [
    "DEFAULT_FORECAST_SIGMA_KT", "DEFAULT_SENSOR_NOISE_MA", "DEFAULT_SENSOR_NOISE_MV", "DEFAULT_WORLD", "DRIFT_SD_MA",
    "DRIFT_SD_MV", "DRIFT_TAU_S", "TAKEOFF_CHECK_S", "WORLDS", "check_world",
    "Readings", "World", "WindEvent", "WorldLeg", "actual_winds_mission", "parse_event",
]
