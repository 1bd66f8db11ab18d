"""What the operator believes about the winds: the forecast plus a common shift that may change in
flight, estimated from the flown legs' measured durations by Bayesian online change-point detection.

The world's story of the weather (:class:`~uam_studio.planning.operations.world.World`): each node's
wind is its forecast plus that node's own error (std ``sigma_kt``, independent between nodes), and at
unknown times the weather changes: from then on every leg that takes off flies in a wind moved by the
same amount. So the residual (measured wind minus forecast) of the k-th leg flown is a level common to
the legs of its *segment* (between two changes) plus the node's own error. The belief is the posterior
over where the last change was (its run length: how many of the latest legs fly in the present weather),
kept exactly, leg by leg (Adams & MacKay 2007):

- before any change the level has a narrow prior (std ``SHIFT_PRIOR_KT``: the forecast is unbiased);
- after a change, a wide one (std ``EVENT_PRIOR_KT``): the new weather owes nothing to the old;
- a change happens before any later leg with probability ``HAZARD`` (none before the first leg).

Public API: :func:`wind_from_duration` (the wind, kt, under which a leg takes a measured time, s),
:class:`WindBelief` (observe a flown leg's wind; predict an unflown one's, with its std; what it
believes about a change) and :class:`WindChange`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from uam_studio.flight import leg_profile
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.legs import DT_S

__all__ = ["CHANGE_P", "EVENT_PRIOR_KT", "FALSE_ALARM_RATE", "HAZARD", "OBSERVED_WIND_SD_KT", "PERHAPS_P",
           "SHIFT_PRIOR_KT", "WindBelief", "WindChange", "wind_from_duration"]

SHIFT_PRIOR_KT = 5.0  # kt, prior std of the shift common to every leg before any change
EVENT_PRIOR_KT = 30.0  # kt, prior std of the common shift after a change
HAZARD = 0.1  # probability that the weather changes before a given leg (after the first)
CHANGE_P = 0.5  # the belief says "the wind changed" once the posterior probability of a change is this
PERHAPS_P = 0.2  # ... and "perhaps a change" from this probability on
FALSE_ALARM_RATE = 0.05  # on noise alone, at most this share of legs (after the first) ends believing a change
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


@dataclass(frozen=True)
class WindChange:
    """What the belief holds about a change of the weather: ``p`` (posterior probability that the weather
    changed during the flight), the most probable first leg flown in the new weather (``since_leg``:
    its index among the legs flown, 0-based; ``since_node``: where that leg went; None when no change is
    the most probable), and ``size_kt`` (kt, + headwind: the new common shift less the one before it,
    under that change)."""

    p: float
    since_leg: int | None
    since_node: str | None
    size_kt: float

    @property
    def detected(self) -> bool:
        """The posterior probability of a change is at least :data:`CHANGE_P`."""
        return self.p >= CHANGE_P and self.since_node is not None

    @property
    def worth_saying(self) -> bool:
        """The posterior probability of a change is at least :data:`PERHAPS_P`."""
        return self.p >= PERHAPS_P and self.since_node is not None

    def text(self) -> str:
        """One line, e.g. ``"the wind changed by about +22 kt since the Hayward leg (p 0.90)"``, ``"perhaps
        a change of about +14 kt since the Fremont leg (p 0.26)"`` or ``"no change of the wind believed (p
        0.03)"``."""
        since = f"{self.size_kt:+.0f} kt since the {self.since_node} leg (p {self.p:.2f})"
        if self.detected:
            return "the wind changed by about " + since
        if self.worth_saying:
            return "perhaps a change of about " + since
        return f"no change of the wind believed (p {self.p:.2f})"


def _segment(residuals: list[float], prior_kt: float, sigma_kt: float) -> tuple[float, float]:
    """Posterior mean and std (kt) of a segment's common level from its residuals (kt)."""
    prec = 1.0 / prior_kt ** 2 + len(residuals) / sigma_kt ** 2
    return (sum(residuals) / sigma_kt ** 2) / prec, math.sqrt(1.0 / prec)


def _log_normal(x: float, mean: float, var: float) -> float:
    return -0.5 * (math.log(2.0 * math.pi * var) + (x - mean) ** 2 / var)


class WindBelief:
    """Forecast winds plus a common shift that may change in flight; flown legs are known.

    Each flown leg's actual wind gives a residual against the forecast. The posterior over the run length
    (the number of latest legs flown since the last change; all of them: no change yet) is updated exactly
    at each leg (see the module docstring). The common shift now is the mixture of its segments' Gaussian
    posteriors. A node already flown to is predicted from its measured wind, moved by how much the shift
    has moved since.

    :param forecast: kt by node name (the mission's winds).
    :param sigma_kt: the forecast's stated error std per node (kt).
    :param hazard: probability of a change before each leg after the first, in [0, 1).
    """

    def __init__(self, forecast: dict[str, float], sigma_kt: float, hazard: float = HAZARD) -> None:
        self.forecast = dict(forecast)
        self.sigma = max(float(sigma_kt), 1.0)
        self.hazard = float(hazard)
        self.observed: dict[str, tuple[float, float]] = {}  # node -> (wind kt, shift when measured)
        self.residuals: list[float] = []
        self.nodes: list[str] = []  # the legs flown, by where they went
        self.log_w = np.zeros(1)  # log posterior of run length L = 0..n (index L); L = n: no change yet

    def _prior(self, length: int) -> float:
        """The prior std (kt) of the level of a segment of the last ``length`` legs."""
        return SHIFT_PRIOR_KT if length == len(self.residuals) else EVENT_PRIOR_KT

    def _segments(self) -> list[tuple[float, float, float]]:
        """(weight, mean kt, std kt) of the level now under each run length with any weight (after a leg
        is flown, run length 0 has none: the legs are never empty)."""
        w = np.exp(self.log_w - self.log_w.max())
        w /= w.sum()
        n = len(self.residuals)
        return [(float(w[length]), *_segment(self.residuals[n - length:], self._prior(length), self.sigma))
                for length in range(1, n + 1) if w[length] >= 1e-12]

    def observe(self, node: str, wind_kts: float) -> tuple[float, bool]:
        """Record the actual wind (kt) of a flown leg to ``node``; returns (residual to the forecast, kt;
        whether a change became believed with this leg)."""
        r = float(wind_kts) - self.forecast[node]
        before = self.change().detected
        n = len(self.residuals)
        s2 = self.sigma ** 2
        h = self.hazard if n > 0 else 0.0
        grow = np.full(n + 2, -np.inf)  # new log weights, run length 0..n+1 after this leg (0 stays -inf)
        new_segment = -np.inf
        for length in range(n + 1):
            if not np.isfinite(self.log_w[length]):
                continue
            mean, sd = _segment(self.residuals[n - length:], self._prior(length), self.sigma)
            if h < 1.0:
                grow[length + 1] = self.log_w[length] + math.log(1.0 - h) + _log_normal(r, mean, sd ** 2 + s2)
            if h > 0.0:
                new_segment = np.logaddexp(new_segment, self.log_w[length] + math.log(h)
                                           + _log_normal(r, 0.0, EVENT_PRIOR_KT ** 2 + s2))
        # run length 1 after this leg: the change came just before it (never at the first leg)
        if n > 0:
            grow[1] = np.logaddexp(grow[1], new_segment)
        self.log_w = grow - np.logaddexp.reduce(grow[np.isfinite(grow)])
        self.residuals.append(r)
        self.nodes.append(node)
        self.observed[node] = (float(wind_kts), self.shift()[0])
        return r, self.change().detected and not before

    def change_p(self) -> float:
        """Posterior probability that the weather changed during the flight."""
        n = len(self.residuals)
        if n < 2:
            return 0.0
        return float(1.0 - math.exp(self.log_w[n]))

    def change(self) -> WindChange:
        """What the belief holds about a change (:class:`WindChange`)."""
        n = len(self.residuals)
        p = self.change_p()
        if n < 2:
            return WindChange(p, None, None, 0.0)
        w = self.log_w[1:n]  # run lengths 1..n-1: a change before leg n - L
        best = int(np.argmax(w)) + 1
        since = n - best
        after, _ = _segment(self.residuals[since:], EVENT_PRIOR_KT, self.sigma)
        before, _ = _segment(self.residuals[:since], SHIFT_PRIOR_KT, self.sigma)
        return WindChange(p, since, self.nodes[since], after - before)

    def shift(self) -> tuple[float, float]:
        """Posterior mean and std (kt) of the wind shift common to the legs still to fly."""
        if not self.residuals:
            return 0.0, SHIFT_PRIOR_KT
        segs = self._segments()
        mean = sum(w * m for w, m, _ in segs)
        var = sum(w * (s ** 2 + m ** 2) for w, m, s in segs) - mean ** 2
        return mean, math.sqrt(max(var, 0.0))

    def predict(self, node: str) -> tuple[float, float]:
        """Predicted wind (kt) on a leg to ``node`` and its std (kt)."""
        mean, sd = self.shift()
        if node in self.observed:
            wind, shift_then = self.observed[node]
            return wind + mean - shift_then, math.sqrt(OBSERVED_WIND_SD_KT ** 2 + sd ** 2)
        return self.forecast[node] + mean, math.sqrt(sd ** 2 + self.sigma ** 2)
