"""One decision of the operator, as the flight record keeps it, and what a flown leg told it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

__all__ = ["Decision", "LegObservation"]


@dataclass(frozen=True, kw_only=True)
class Decision:
    """One (re-)plan: when, where, what it knew, what it chose and why.

    ``time_s`` (s since the first take-off), ``node``, ``reason``, the health estimate
    (``q_max_c``, ``q_max_sd_c``, ``r0_ohm``, ``r0_sd_ohm``), the belief cell it planned with
    (``plan_q_max_c``, ``plan_r0_ohm``), the estimated common wind shift (``wind_shift_kts`` with
    ``wind_shift_sd_kts``), the planned remaining ``route`` and ``altitudes_m``, the next leg
    (``next_to``, ``next_altitude_m``; None: the flight ends), ``compute_s`` (s of wall time) and
    ``health_flags``, the flags of the health fits behind the estimate
    (:mod:`uam_studio.battery.health.quality`: ``"misfit"``, ``"outside fleet range"``), and what the
    leg just flown told about the wind: ``leg_wind_kts`` (kt, read off its measured duration),
    ``leg_wind_vs_forecast_kts`` (kt, that wind minus the forecast) and ``wind_surprise`` (with this
    leg the belief came to hold that the weather changed); None before the first leg. What it believes
    about a change of the weather: ``wind_change_p`` (its probability) and ``wind_change`` (one line,
    e.g. "the wind changed by about +22 kt since the Hayward leg (p 0.90)" or "perhaps a change of ...
    (p 0.26)"; "" below p 0.2); ``reserve_kt`` (kt), the weather reserve its safety check kept.
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
    leg_wind_kts: float | None = None
    leg_wind_vs_forecast_kts: float | None = None
    wind_surprise: bool = False
    wind_change_p: float = 0.0
    wind_change: str = ""
    reserve_kt: float = 0.0

    @property
    def leg_wind_text(self) -> str:
        """What the leg just flown told about the wind, e.g. ``"+14 (flew in +9)"`` (kt, against the
        forecast, then the wind read off the leg), ``", a change"`` added where the belief of a change
        began with it; ``"-"``
        before the first leg."""
        if self.leg_wind_kts is None or self.leg_wind_vs_forecast_kts is None:
            return "-"
        text = f"{self.leg_wind_vs_forecast_kts:+.0f} (flew in {self.leg_wind_kts:+.0f})"
        return text + ", a change" if self.wind_surprise else text

    def row(self) -> dict[str, Any]:
        """The decision as one row of a log table (the Fly tab, notebook 09): time (s), place, the
        health estimate with its std, the fit's flags, the leg's wind against the forecast and the
        estimated common shift (kt), the next leg and the reason."""
        return {"t (s)": round(self.time_s), "at": self.node,
                "q_max (C)": f"{self.q_max_c:.0f} ± {self.q_max_sd_c:.0f}", "R0 (ohm)": f"{self.r0_ohm:.3f}",
                "fit flags": ", ".join(self.health_flags) or "-",
                "leg wind vs forecast (kt)": self.leg_wind_text,
                "common shift (kt)": f"{self.wind_shift_kts:+.1f} ± {self.wind_shift_sd_kts:.1f}",
                "wind changed (p)": f"{self.wind_change_p:.2f}",
                "next": self.next_to or "-", "reason": self.reason}

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["route"], d["altitudes_m"] = list(self.route), list(self.altitudes_m)
        d["health_flags"] = list(self.health_flags)
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in d.items()}


@dataclass(frozen=True)
class LegObservation:
    """What the last leg flown told the operator about the wind, until its next decision reads it:
    the wind the leg's duration implies (kt, + headwind), its residual against the forecast (kt),
    whether the belief came to hold a change of the weather with it, and the same as one line of text."""

    wind_kt: float
    residual_kt: float
    surprise: bool
    note: str
