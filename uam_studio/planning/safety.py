"""How safe a plan is, by source: the physics model and the Dynaformer, with the Dynaformer's band
(the plan's ``band``, computed by :func:`~uam_studio.planning.planner.plan_mission` in the pass that
predicts it).

- :func:`takeoff_attempt`: the physics model's take-off and climb to 500 m of a cell that falls
  below the cut-off before the end (the voltage trace of a cell that cannot take off).
- :func:`safety_verdict`: whether a plan stays above the cut-off on each model, as a level
  (``safe``, ``uncertain``, ``disagree``, ``unsafe``, ``none``), a headline and one line of margins.

A plan here is :func:`~uam_studio.planning.planner.plan_mission`'s result, a
:class:`~uam_studio.planning.planner.PlanResult` or its ``to_dict()``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from uam_studio.planning.legs import fly_takeoff
from uam_studio.planning.missions.mission import Mission

__all__ = ["safety_verdict", "takeoff_attempt"]

def takeoff_attempt(mission: Mission) -> dict[str, Any] | None:
    """The physics model's take-off and climb to 500 m for the mission's cell if it falls below the
    cut-off before the end (the cell cannot take off), else None.

    :return: ``{"time_s", "voltage_v", "eod_s"}`` (s, V, s): the samples up to the first one below
        the cut-off.
    """
    sim = fly_takeoff(mission.cell)
    if not bool(sim.eod_reached):
        return None
    n = min(int(np.count_nonzero(sim.valid)) + 1, sim.voltage_v.size)
    return {"time_s": [float(x) for x in sim.time_s[:n]], "voltage_v": [float(x) for x in sim.voltage_v[:n]],
            "eod_s": float(sim.eod_s)}


def _margin_words(margin: float) -> str:
    return f"safe by {_volts(margin)}" if margin >= 0 else f"below EOD by {_volts(-margin)}"


def _volts(x: float) -> str:
    """A voltage difference: 2 decimals, 3 under 0.1 V (so a margin of a few mV does not read 0.00)."""
    return f"{x:.2f} V" if abs(x) >= 0.1 else f"{x:.3f} V"


def _signed_volts(x: float) -> str:
    return f"{x:+.2f} V" if abs(x) >= 0.1 else f"{x:+.3f} V"


def safety_verdict(plan: Mapping[str, Any] | None, band: Mapping[str, Any] | None,
                   takeoff: Mapping[str, Any] | None, eod_v: float) -> dict[str, Any]:
    """Whether the plan stays above the cut-off, by source: the physics model and the Dynaformer.

    Levels: ``"safe"`` (both above, and the Dynaformer's band too), ``"uncertain"`` (both above, but
    the band reaches the cut-off), ``"disagree"`` (one above, one below), ``"unsafe"`` (both below,
    or the cell cannot take off), ``"none"`` (nothing is flown). Without a Dynaformer prediction the
    physics model decides alone.

    :param plan: the plan, or None.
    :param band: the plan's ``band`` (:class:`~uam_studio.planning.planner.PlanResult`), or None.
    :param takeoff: the cell's :func:`takeoff_attempt`, or None if it takes off.
    :param eod_v: the cut-off (V).
    :return: ``{"level", "headline", "text", "physics_margin_v", "predicted_margin_v",
        "band_margin_v"}`` (margins, V: lowest voltage minus ``eod_v``; band: (low, high) or None).
    """
    out: dict[str, Any] = {"level": "none", "headline": "Nothing is flown", "text": "",
                           "physics_margin_v": None, "predicted_margin_v": None, "band_margin_v": None}
    if takeoff is not None:
        out.update(level="unsafe", headline="Not safe: the cell cannot take off",
                   text=f"physics: below EOD ({eod_v:g} V) {takeoff['eod_s']:.0f} s into the take-off and climb")
        return out
    if not plan or not plan.get("route") or plan.get("min_voltage_v") is None:
        return out
    phys = float(plan["min_voltage_v"]) - eod_v
    phys_safe = bool(plan["safe"])
    out["physics_margin_v"] = phys
    parts = [f"physics: {_margin_words(phys)}"]
    pred = plan.get("predicted")
    pred_safe = None
    if pred and pred.get("voltage_v"):
        pm = min(pred["voltage_v"]) - eod_v
        pred_safe = pm >= 0
        out["predicted_margin_v"] = pm
        words = f"predicted: {_margin_words(pm)}"
        if band is not None:
            lo, hi = band["min_low_v"] - eod_v, band["min_high_v"] - eod_v
            out["band_margin_v"] = (lo, hi)
            words += f" ({100 * band['level']:.0f}%: {_signed_volts(lo)} to {_signed_volts(hi)})"
        parts.append(words)
    else:
        parts.append("predicted: - (no Dynaformer prediction)")
    out["text"] = "; ".join(parts)
    band_low_safe = out["band_margin_v"] is None or out["band_margin_v"][0] >= 0
    if pred_safe is None:
        out.update(level="safe" if phys_safe else "unsafe",
                   headline="Safe (physics model)" if phys_safe else "Not safe (physics model)")
    elif phys_safe and pred_safe:
        if band_low_safe:
            out.update(level="safe", headline="Safe: physics and Dynaformer agree")
        else:
            assert band is not None  # a band margin comes from a band
            out.update(level="uncertain", headline=f"Check: safe on both models, but the Dynaformer's "
                                                   f"{100 * band['level']:.0f}% band reaches EOD")
    elif not phys_safe and not pred_safe:
        out.update(level="unsafe", headline="Not safe: physics and Dynaformer agree")
    else:
        which = "physics safe, Dynaformer below EOD" if phys_safe else "Dynaformer safe, physics below EOD"
        out.update(level="disagree", headline=f"Models disagree: {which}")
    return out
