"""What the operator believes about the winds: the forecast plus a shift common to every leg,
estimated from the flown legs' measured durations.

Public API: :func:`wind_from_duration` (the wind, kt, under which a leg takes a measured time, s) and
:class:`WindBelief` (observe a flown leg's wind; predict an unflown one's, with its std).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from uam_studio.flight import leg_profile
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.legs import DT_S

__all__ = ["EVENT_PRIOR_KT", "OBSERVED_WIND_SD_KT", "SHIFT_PRIOR_KT", "SURPRISE_Z", "WindBelief",
           "wind_from_duration"]

SHIFT_PRIOR_KT = 5.0  # kt, prior std of a wind shift common to every leg
EVENT_PRIOR_KT = 30.0  # kt, prior std of the shift after a surprise
SURPRISE_Z = 2.5  # a flown leg's wind this many std off its prediction is a surprise
OBSERVED_WIND_SD_KT = 1.0  # kt, std of a wind measured by flying its leg


@lru_cache(maxsize=4096)
def _duration_curve(distance_km: float, altitude_m: float, dwell_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Leg duration (s) over a 1 kt grid of winds (kt): monotone, for inverting a measured duration."""
    winds = np.arange(WIND_RANGE_KTS[0], WIND_RANGE_KTS[1] + 0.5, 1.0)
    dur = np.array([math.ceil(leg_profile(distance_km, altitude_m, float(w), DT_S, dwell_s).duration_s / DT_S - 1e-9)
                    for w in winds], dtype=float)
    return winds, dur


def wind_from_duration(distance_km: float, altitude_m: float, dwell_s: float, duration_s: float) -> float:
    """The wind (kt) under which a leg takes ``duration_s`` (s): the inverse of the leg's timing."""
    winds, dur = _duration_curve(round(distance_km, 6), float(altitude_m), float(dwell_s))
    return float(np.interp(duration_s, dur, winds))


class WindBelief:
    """Forecast winds plus an estimated shift common to every leg; flown legs are known.

    Each flown leg's actual wind gives a residual against the forecast. The common shift has a
    Gaussian prior (std ``SHIFT_PRIOR_KT``) and each residual is the shift plus the node's own forecast
    error (std ``sigma_kt``). A residual further than ``SURPRISE_Z`` std from its prediction is a
    surprise (the weather changed): the shift is then re-estimated from the residuals since, under a
    wide prior (``EVENT_PRIOR_KT``), and winds measured before it are moved by the change.

    :param forecast: kt by node name (the mission's winds).
    :param sigma_kt: the forecast's stated error std per node (kt).
    """

    def __init__(self, forecast: dict[str, float], sigma_kt: float) -> None:
        self.forecast = dict(forecast)
        self.sigma = max(float(sigma_kt), 1.0)
        self.observed: dict[str, tuple[float, float]] = {}  # node -> (wind kt, shift when measured)
        self.residuals: list[float] = []
        self.prior_kt = SHIFT_PRIOR_KT
        self.surprises = 0

    def observe(self, node: str, wind_kts: float) -> tuple[float, bool]:
        """Record the actual wind (kt) of a flown leg to ``node``; returns (residual to the forecast, kt;
        whether it was a surprise)."""
        r = float(wind_kts) - self.forecast[node]
        mean, sd = self.shift()
        surprise = abs(r - mean) > SURPRISE_Z * math.sqrt(sd ** 2 + self.sigma ** 2)
        if surprise:
            self.residuals = []
            self.prior_kt = EVENT_PRIOR_KT
            self.surprises += 1
        self.residuals.append(r)
        self.observed[node] = (float(wind_kts), self.shift()[0])
        return r, surprise

    def shift(self) -> tuple[float, float]:
        """Posterior mean and std (kt) of the wind shift common to all legs."""
        prec = 1.0 / self.prior_kt ** 2 + len(self.residuals) / self.sigma ** 2
        mean = (sum(self.residuals) / self.sigma ** 2) / prec
        return mean, math.sqrt(1.0 / prec)

    def predict(self, node: str) -> tuple[float, float]:
        """Predicted wind (kt) on a leg to ``node`` and its std (kt)."""
        mean, sd = self.shift()
        if node in self.observed:
            wind, shift_then = self.observed[node]
            return wind + mean - shift_then, math.sqrt(OBSERVED_WIND_SD_KT ** 2 + sd ** 2)
        return self.forecast[node] + mean, math.sqrt(sd ** 2 + self.sigma ** 2)
