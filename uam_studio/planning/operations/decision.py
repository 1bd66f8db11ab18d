"""One decision of the operator, as the flight record keeps it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

__all__ = ["Decision"]


@dataclass(frozen=True)
class Decision:
    """One (re-)plan: when, where, what it knew, what it chose and why.

    ``time_s`` (s since the first take-off), ``node``, ``reason``, the health estimate
    (``q_max_c``, ``q_max_sd_c``, ``r0_ohm``, ``r0_sd_ohm``), the belief cell it planned with
    (``plan_q_max_c``, ``plan_r0_ohm``), the estimated common wind shift (``wind_shift_kts`` with
    ``wind_shift_sd_kts``), the planned remaining ``route`` and ``altitudes_m``, the next leg
    (``next_to``, ``next_altitude_m``; None: the flight ends), ``compute_s`` (s of wall time) and
    ``health_flags``, the flags of the health fits behind the estimate
    (:mod:`uam_studio.battery.fit_quality`: ``"misfit"``, ``"outside fleet range"``).
    """

    time_s: float
    node: str
    kind: str
    reason: str
    q_max_c: float
    q_max_sd_c: float
    r0_ohm: float
    r0_sd_ohm: float
    plan_q_max_c: float
    plan_r0_ohm: float
    wind_shift_kts: float
    wind_shift_sd_kts: float
    route: tuple[str, ...]
    altitudes_m: tuple[float, ...]
    next_to: str | None
    next_altitude_m: float | None
    compute_s: float = 0.0
    health_flags: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["route"], d["altitudes_m"] = list(self.route), list(self.altitudes_m)
        d["health_flags"] = list(self.health_flags)
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in d.items()}
