"""A pack's history, simulated: the logbook of a pack that has flown a mission before
(:func:`simulate_logbook`, ``uam-studio logbook new``).

The world's side: each earlier flight is flown by the operator (a new pack's, from the fleet prior) in a world of
its own seed, on the pack as it was then, and its sensors' readings (never the truth) go into the logbook. The
pack ages by the aging law (:data:`~uam_studio.battery.aging.NASA_AGING_LAW`, the paper's cell's) on its delivered
charge, so that after the logged flights it is the mission's cell: q_max and R0 of flight ``k`` are the mission's
times ``c(e_k) / c(e_now)`` and ``r(e_k) / r(e_now)``, ``e`` the equivalent full cycles (delivered charge,
:func:`~uam_studio.battery.health.logbook.delivered_charge_c`, over the logbook's ``q_nominal_c``).
"""

from __future__ import annotations

import numpy as np

from uam_studio.battery.aging import NASA_AGING_LAW, AgingLaw
from uam_studio.battery.health.logbook import Logbook, delivered_charge_c
from uam_studio.errors import check_range, check_seed
from uam_studio.planning.legs import DT_S
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.operations.defaults import (
    DEFAULT_FORECAST_SIGMA_KT,
    DEFAULT_SENSOR_NOISE_MA,
    DEFAULT_SENSOR_NOISE_MV,
    fit_noise_v,
)
from uam_studio.planning.operations.fly import fly_mission
from uam_studio.planning.operations.world import DEFAULT_WORLD

__all__ = ["MAX_LOGGED_FLIGHTS", "history_seed", "simulate_logbook"]

MAX_LOGGED_FLIGHTS = 200  # flights a simulated logbook may hold
HISTORY_STREAM = 7507  # the seed stream of a pack's earlier flights (apart from the flight's own worlds)


def history_seed(seed: int, k: int) -> int:
    """The world seed of earlier flight ``k`` of the pack seeded ``seed`` (never a flight's own seed stream)."""
    return int(np.random.SeedSequence([seed, HISTORY_STREAM, k]).generate_state(1)[0])


def simulate_logbook(mission: Mission, flights: int, seed: int = 0, age_efc: float | None = None,
                     forecast_sigma_kt: float = DEFAULT_FORECAST_SIGMA_KT,
                     sensor_noise_mv: float = DEFAULT_SENSOR_NOISE_MV,
                     sensor_noise_ma: float = DEFAULT_SENSOR_NOISE_MA, aging: AgingLaw = NASA_AGING_LAW,
                     policy: str = "attention", world: str = DEFAULT_WORLD, pack: int | None = None) -> Logbook:
    """The logbook of a pack that has flown ``mission`` ``flights`` times before (module docstring).

    :param mission: its ``battery`` is the pack now (after the logged flights); its winds the forecast.
    :param flights: earlier flights, 0-200 (0: an empty logbook, a new pack).
    :param seed: seeds the earlier flights' worlds (:func:`history_seed`).
    :param age_efc: the pack's equivalent full cycles now (0-2000); None: it was new at its first logged flight.
    :param forecast_sigma_kt: the forecast error std (kt) of the earlier flights' worlds.
    :param sensor_noise_mv: voltage sensor noise std (mV): the logbook holds what the sensors read.
    :param sensor_noise_ma: current sensor noise std (mA).
    :param aging: how the pack aged.
    :param policy: the planner that flew the earlier flights.
    :param world: the world the earlier flights flew in (:data:`~uam_studio.planning.operations.world.WORLDS`).
    :param pack: the pack's number (None: ``seed``): in the varied world, its own parameter set; fly the flight
        after the logbook with the same number (:func:`~uam_studio.planning.operations.fly.fly_mission`'s ``pack``).
    """
    n = int(check_range("flights", flights, 0, MAX_LOGGED_FLIGHTS))
    seed = check_seed("seed", seed)
    pack = check_seed("pack", seed if pack is None else pack)
    book = Logbook(noise_v=fit_noise_v(sensor_noise_mv), eod_v=mission.eod_v)
    if n == 0:
        return book

    def fly(m: Mission, k: int) -> list[tuple[np.ndarray, np.ndarray]]:
        rec = fly_mission(m, policy, history_seed(seed, k), forecast_sigma_kt, sensor_noise_mv, sensor_noise_ma,
                          references=False, world=world, pack=pack)
        return rec.flown_charges

    # the charge of one flight of this mission (on the pack as it is now): the clock of the earlier flights
    per_flight_c = sum(delivered_charge_c(c, DT_S) for c, _ in fly(mission, 0))
    before_c = n * per_flight_c
    unit_c = book.q_nominal_c  # the aging clock's unit: a full cycle
    now_efc = before_c / unit_c if age_efc is None else check_range("age_efc", age_efc, 0.0, 2000.0)
    book = Logbook(delivered_before_c=max(now_efc * unit_c - before_c, 0.0), noise_v=book.noise_v, eod_v=book.eod_v)
    q_now, r_now = mission.battery.q_max, mission.battery.r0
    c_now, r_ratio_now = float(aging.capacity_fraction(now_efc)), float(aging.resistance_ratio(now_efc))
    for k in range(n):
        efc = max(now_efc - (n - k) * per_flight_c / unit_c, 0.0)
        q_k = q_now * float(aging.capacity_fraction(efc)) / max(c_now, 1e-6)
        r_k = r_now * float(aging.resistance_ratio(efc)) / r_ratio_now
        book = book.extended(fly(mission.with_battery(q_k, r_k), k), DT_S)
    return book
