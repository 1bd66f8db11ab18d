"""State of the Battery lab tab: one leg flown by one cell, and a family of curves varying one factor.

:class:`BatteryLabState` holds the leg (length, altitude, wind, legs flown back to back), the cell
(q_max, R0, cut-off) and the factor the family varies (:data:`VARY`), and its :attr:`~BatteryLabState.result`:
current and voltage curves from the library's flight and battery models
(:func:`uam_studio.flight.leg_profile`, :func:`uam_studio.battery.simulate`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import param

from uam_studio.app.services import APP_EOD_RANGE, APP_Q_RANGE, APP_R0_RANGE, LatestWorker, one_line
from uam_studio.battery import DEFAULT_Q_MAX, DEFAULT_R0
from uam_studio.battery.parameters import NASA_18650, NASA_IDENTIFIED, PAPER_Q_RANGE, PAPER_R0_RANGE, VTC6, Cell
from uam_studio.errors import InputError
from uam_studio.flight.tables import ALTITUDE_RANGE_M, WIND_RANGE_KTS
from uam_studio.planning.legs import ALTITUDES_M

__all__ = ["CELLS", "HEALTH_BOX", "NASA_ID_NAME", "VARY", "BatteryLabState", "family_values"]

VARY = {
    "altitude": ("altitude_m", ALTITUDES_M, "m"),  # the paper's four levels
    "wind": ("wind_kts", tuple(WIND_RANGE_KTS[1] * f for f in (-1.0, -1 / 3, 0.0, 1 / 3, 1.0)), "kt"),
    "R0": ("r0", (PAPER_R0_RANGE[0], 0.1, 0.2, 0.3, PAPER_R0_RANGE[1]), "ohm"),  # across the paper's range
    "q_max": ("q_max", (PAPER_Q_RANGE[0], 6000.0, 7000.0, PAPER_Q_RANGE[1]), "C"),
}
NASA_NAME, VTC6_NAME = "NASA 18650 (the paper's cell)", "Sony VTC6 (identified on real cells)"
NASA_ID_NAME = "NASA 18650 (identified on B0005)"
CELLS: dict[str, Cell] = {NASA_NAME: NASA_18650, NASA_ID_NAME: NASA_IDENTIFIED, VTC6_NAME: VTC6}
# Per cell: the sliders' (q_max C, R0 ohm) ranges and the health family's values. The VTC6's box spans
# the CMU cells' fade (3.16 to 2.43 Ah at C/5, about 77%) and resistances from new to well aged. The
# identified NASA cell's box holds its fleet range (parameters.NASA_ID_FLEET_*: the 2 A lives' fade) and
# resistances beyond it.
HEALTH_BOX = {NASA_NAME: (APP_Q_RANGE, APP_R0_RANGE),
              NASA_ID_NAME: ((4500.0, 7300.0), (0.005, 0.12)),
              VTC6_NAME: ((7000.0, 11500.0), (0.01, 0.1))}
_HEALTH_FAMILY = {VTC6_NAME: {"q_max": (8000.0, 9000.0, 10000.0, 11000.0), "R0": (0.015, 0.02, 0.04, 0.08)},
                  NASA_ID_NAME: {"q_max": (5000.0, 5700.0, 6300.0, 6960.0), "R0": (0.01, 0.03, 0.06, 0.1)}}


def family_values(vary: str, cell: str = NASA_NAME) -> tuple[str, tuple[float, ...], str]:
    """(state field, values, unit) of the family that varies ``vary`` for ``cell`` (a :data:`CELLS` name)."""
    key, values, unit = VARY[vary]
    return key, _HEALTH_FAMILY.get(cell, {}).get(vary, values), unit


class BatteryLabState(param.Parameterized):
    """One leg flown by one cell, plus a family of curves that vary one factor (the paper's figures).

    The cell is the paper's NASA 18650, the NASA 18650 identified on real discharges of it (B0005), or
    the VTC6 identified on the CMU eVTOL cells; all three draw the same
    per-cell current (the pack's current shared by its cells). A new cell sets q_max and R0 to its
    nominal health and their ranges to its :data:`HEALTH_BOX`.

    :meth:`curves` returns, for the chosen setting and each family member, the per-cell current and
    the voltage (physics model) of the leg, flown ``legs`` times back to back without recharging.
    Every input change recomputes :attr:`result` (:meth:`refresh`): at once, or (``background``) in
    the shared thread pool with :attr:`busy` set meanwhile and only the newest request kept.
    """

    cell: param.Selector[str] = param.Selector(default=NASA_NAME, objects=list(CELLS),
                                               doc="the cell's parameter set (:data:`CELLS`)")
    q_max = param.Number(default=DEFAULT_Q_MAX, bounds=APP_Q_RANGE, doc="q_max (C)")
    r0 = param.Number(default=DEFAULT_R0, bounds=APP_R0_RANGE, doc="R0 (ohm)")
    altitude_m = param.Number(default=1000.0, bounds=ALTITUDE_RANGE_M)
    wind_kts = param.Number(default=0.0, bounds=WIND_RANGE_KTS)
    distance_km = param.Number(default=55.6, bounds=(10.0, 150.0), doc="leg length (km); 30 nm = 55.6 km")
    legs = param.Integer(default=3, bounds=(1, 10), doc="legs flown back to back (no recharge)")
    eod_v = param.Number(default=3.0, bounds=APP_EOD_RANGE)
    vary: param.Selector[str] = param.Selector(default="altitude", objects=list(VARY))

    result = param.Dict(default=None, allow_None=True, doc=":meth:`curves` of the current inputs")
    busy = param.Boolean(default=False, doc="a newer result is being computed")

    INPUTS = ("cell", "q_max", "r0", "altitude_m", "wind_kts", "distance_km", "legs", "eod_v", "vary")
    MAX_POINTS = 1500  # samples per drawn series (every EOD time and minimum is computed at 1 s)

    def __init__(self, background: bool = False, dispatch: Callable[[Callable[[], None]], None] | None = None,
                 **params: Any) -> None:
        """
        :param background: compute in the shared thread pool (served app) instead of in place.
        :param dispatch: how a result computed in the pool is handed back to the session's thread.
        """
        super().__init__(**params)
        self.background = background
        self.dispatch = dispatch or (lambda cb: cb())
        self._worker: LatestWorker[None, dict[str, Any]] = LatestWorker(
            lambda _: self.curves(), self._apply, _lab_failed, dispatch=self.dispatch)
        self._set_cell(self.cell, params.get("q_max"), params.get("r0"))  # its box; its health unless given
        self.param.watch(self._on_cell, "cell")  # precedence 0: before refresh, the cell's bounds and health
        self.param.watch(lambda *_: self.refresh(), list(self.INPUTS), precedence=1)
        self.refresh()

    def _on_cell(self, event: param.parameterized.Event) -> None:
        """A new cell: its health box, and its nominal health (q_max C, R0 ohm)."""
        self._set_cell(event.new)

    def _set_cell(self, name: str, q_max: float | None = None, r0: float | None = None) -> None:
        """Cell ``name``'s health box, and (q_max C, R0 ohm): as given, else its nominal health."""
        (q_lo, q_hi), (r_lo, r_hi) = HEALTH_BOX[name]
        self.param.q_max.bounds, self.param.r0.bounds = (q_lo, q_hi), (r_lo, r_hi)
        cell = CELLS[name]
        with param.parameterized.discard_events(self):
            self.q_max = cell.q_max if q_max is None else q_max
            self.r0 = cell.r0 if r0 is None else r0

    def refresh(self) -> None:
        """Recompute :attr:`result` for the current inputs."""
        if not self.background:
            self.result = self.curves()
            return
        if not self.busy:
            self.busy = True
        self._worker.submit(None)  # curves() reads the inputs as they are when it runs

    def _apply(self, res: dict[str, Any], latest: bool) -> None:
        self.param.update(result=res, **({"busy": False} if latest else {}))

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until the result of the newest inputs is shown, at most ``timeout`` s (tests; in the
        background only, and not from the session's own thread when a dispatcher schedules on it)."""
        return self._worker.wait_idle(timeout)

    def _setting(self, **override: float) -> dict[str, float]:
        s = {k: float(getattr(self, k)) for k in ("q_max", "r0", "altitude_m", "wind_kts")}
        s.update(override)
        return s

    def curves(self) -> dict[str, Any]:
        """``{"setting": [curve], "family": [curve...], "factor", "unit", "error", "skipped", "t_end_s",
        "eod_v", "labels", "cell"}``.

        The family is in the factor's order (ascending); ``t_end_s`` is the end of the longest
        curve, one time range for every plot. Each curve is ``{"label", "value", "time_s",
        "current_a", "voltage_time_s", "voltage_v", "eod_s", "min_voltage_v"}``: the current and the
        voltage up to and including the first sample below the cut-off (the flight ends there), both
        thinned to at most :data:`MAX_POINTS` samples; ``eod_s`` is None where the cut-off is never
        reached and ``min_voltage_v`` the lowest voltage (every sample).
        """
        key, values, unit = family_values(self.vary, self.cell)
        labels = [f"{self.vary} {v:g} {unit}" for v in values]
        out: dict[str, Any] = {"factor": self.vary, "unit": unit, "setting": [], "family": [], "error": "",
                               "skipped": [], "t_end_s": 0.0, "eod_v": float(self.eod_v), "labels": labels,
                               "cell": self.cell}
        try:
            out["setting"] = [self._curve(self._setting(), "this setting")]
        except InputError as err:
            out["error"] = one_line(err)
            return out
        for v, label in zip(values, labels):
            try:
                out["family"].append(self._curve(self._setting(**{key: v}), label))
            except InputError as err:  # e.g. a leg too short for 3000 m
                out["skipped"].append(f"{label}: {one_line(err)}")
        out["t_end_s"] = max(float(c["time_s"][-1]) for c in out["setting"] + out["family"])
        return out

    def _curve(self, s: dict[str, float], label: str) -> dict[str, Any]:
        from uam_studio.battery import simulate
        from uam_studio.flight import leg_profile

        prof = leg_profile(float(self.distance_km), s["altitude_m"], s["wind_kts"])
        cur = np.tile(np.asarray(prof.current_a), int(self.legs))
        sim = simulate(cur, prof.dt_s, s["q_max"], s["r0"], eod_v=float(self.eod_v), cell=CELLS[self.cell].params)
        t = np.asarray(sim.time_s, dtype=float)
        v = np.asarray(sim.voltage_v, dtype=float)
        n = min(int(np.count_nonzero(sim.valid)) + 1, v.size)  # the first sample below the cut-off too
        eod = float(sim.eod_s)
        it = _thin_index(n, self.MAX_POINTS)  # the flight ends at the cut-off: its current too
        iv = _thin_index(n, self.MAX_POINTS, keep=int(np.argmin(v[:n])))
        return {"label": label, "value": s, "time_s": t[it], "current_a": cur[it],
                "voltage_time_s": t[iv], "voltage_v": v[iv], "eod_s": eod if math.isfinite(eod) else None,
                "min_voltage_v": float(v[:n].min())}


def _thin_index(n: int, limit: int, keep: int | None = None) -> np.ndarray:
    """At most about ``limit`` indices of ``n`` samples, evenly spread, with the first, the last and ``keep``."""
    if n <= limit:
        return np.arange(n)
    idx = np.linspace(0, n - 1, limit).round().astype(int)
    return np.unique(np.append(idx, np.asarray([] if keep is None else [keep], dtype=int)))


def _lab_failed(_request: None, err: BaseException) -> dict[str, Any]:
    """The result of curves that raised (:meth:`BatteryLabState.curves` reports input errors itself)."""
    return {"error": f"battery lab failed: {one_line(err)}"}
