"""The risk levels the library declares, each with one name and one home.

A level is the standard-normal quantile (std) of a one-sided bound; a safety check that takes a quantity
``z`` std to its weak side declares the miss rate of that bound.

- :data:`HEALTH_Z`: the cautious cell of a health belief (q_max and R0 each 1.64 std to the weak side,
  one-sided 5%): the operator's safety check and the fleet's health-aware dispatcher.
- :data:`WIND_Z`: the operator's joint one-sided bound on the next leg's and the way home's winds (5%).
- :data:`DISPATCH_WIND_Z`: the fleet dispatcher's wind to the head side on each leg of a round trip (1%: one fifth
  of the default risk; tuned, ``benchmarks/RESULTS.md``, "A fleet's life").
- :data:`INTERVAL_Z`: the half-width of a two-sided 90% interval (the take-off belief's q_max interval).

A flight's **declared risk** (:data:`DEFAULT_RISK`, ``fly_mission(risk=)``, ``uam-studio fly --risk``) is the one
number its operator's cautions follow from (:func:`caution`): the health and the wind each ``risk_z(risk)`` std to
the weak side, and the weather reserve the same quantile of the envelope of in-flight weather changes
(:data:`WEATHER_CHANGE_SD_KT`). A fleet's dispatcher (``simulate_day(risk=)``, ``uam-studio fleet --risk``) takes
the health at the same quantile and each leg's wind at the quantile of one fifth of the risk: a dispatched round trip
is flown as dispatched, with no re-plan to correct its wind (at the default risk, the 1% bound it was tuned at). The
mapping is declared, not computed from a breach probability: how often flights at a declared risk breach is measured
by ``benchmarks/bench_risk.py``.
"""

import math
from dataclasses import dataclass
from statistics import NormalDist

from uam_studio.errors import InputError

__all__ = ["DEFAULT_RISK", "RISK_LEVELS", "DISPATCH_WIND_Z", "HEALTH_Z", "INTERVAL_Z", "ONE_PERCENT_Z", "RISK_RANGE",
           "WEATHER_CHANGE_SD_KT", "WEATHER_RESERVE_KT", "WIND_Z", "Caution", "caution", "check_risk", "risk_z"]

FIVE_PERCENT_Z = 1.64  # one-sided 5% (std)
ONE_PERCENT_Z = 2.33  # one-sided 1% (std)

# The declared risk a flight takes by default: the one-sided 5% of the bounds its operator has always flown with.
DEFAULT_RISK = 0.05
RISK_LEVELS = (0.01, 0.05, 0.1, 0.2)  # the declared risks shown side by side (the Fly tab, the price of safety)
RISK_RANGE = (1e-4, 0.5)  # a declared risk: at least 1e-4 (a reserve within the operator's 60 kt), below 0.5
# The envelope of in-flight weather changes the weather reserve is held against: a change of every leg's wind
# ~ N(0, this), so that the default risk's bound is the 25 kt reserve the operator flies with (RESULTS.md, "Weather
# that changes": 25 kt kept every +25 / -20 kt change safe). An assumption, declared here.
WEATHER_CHANGE_SD_KT = 25.0 / FIVE_PERCENT_Z
DISPATCH_RISK_SHARE = 5.0  # the fleet dispatcher bounds each leg's wind at the risk over this (module docstring)


def check_risk(risk: float) -> float:
    """``risk`` as a float if it is a finite number in [0.0001, 0.5); one line naming field ``risk`` otherwise."""
    allowed = "allowed a probability from 0.0001 to below 0.5 (e.g. 0.05)"
    if isinstance(risk, bool):
        raise InputError("risk", f"{risk!r}: {allowed}")
    try:
        value = float(risk)
    except (TypeError, ValueError):
        raise InputError("risk", f"{str(risk)[:40]!r}: {allowed}") from None
    if not math.isfinite(value) or not RISK_RANGE[0] <= value < RISK_RANGE[1]:
        raise InputError("risk", f"{risk!r}: {allowed}")
    return value


def risk_z(risk: float) -> float:
    """The one-sided standard-normal quantile (std) of a declared ``risk``, to 0.01 std (5%: 1.64, 1%: 2.33)."""
    return round(NormalDist().inv_cdf(1.0 - check_risk(risk)), 2)


@dataclass(frozen=True)
class Caution:
    """The cautions at a declared risk: the operator's ``health_z`` and ``wind_z`` (std to the weak side) and
    weather reserve ``reserve_kt`` (kt of headwind beyond its belief on the next leg and the way home); the fleet
    dispatcher's ``health_z`` and ``dispatch_wind_z`` (std of each leg's forecast error to the head side)."""

    risk: float
    health_z: float
    wind_z: float
    reserve_kt: float
    dispatch_wind_z: float


def caution(risk: float = DEFAULT_RISK) -> Caution:
    """The cautions that follow from a declared ``risk`` (module docstring)."""
    z = risk_z(risk)
    dispatch_z = round(NormalDist().inv_cdf(1.0 - float(risk) / DISPATCH_RISK_SHARE), 2)
    return Caution(float(risk), z, z, round(z * WEATHER_CHANGE_SD_KT, 6), dispatch_z)


HEALTH_Z = caution().health_z
WIND_Z = caution().wind_z
WEATHER_RESERVE_KT = caution().reserve_kt  # kt: 25.0 at the default risk
DISPATCH_WIND_Z = caution().dispatch_wind_z  # 2.33: the one-sided 1%
INTERVAL_Z = FIVE_PERCENT_Z  # each side of a 90% interval
