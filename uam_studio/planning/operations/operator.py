"""The operator: what the aircraft knows, and how it decides in flight.

It sees the mission with its *forecast* winds, the stated accuracy of that forecast, and the
sensor readings; never the true cell nor the actual winds. At each decision point (after the
take-off check and at every arrival) it

1. estimates the health (q_max, R0) with its uncertainty
   (:class:`~uam_studio.battery.health.belief.HealthBelief`: the fit of **all** readings
   since the last full charge, combined by precision with the fits of earlier charges and with the
   pack's logbook, or the fleet prior for a new pack, on which a 20 s take-off says much about R0 and
   little about q_max, which the flight then sharpens);
2. estimates the wind (:class:`~uam_studio.planning.operations.wind_belief.WindBelief`): the actual
   wind of each flown leg follows from its measured duration (cruise time = distance / ground speed);
   the shift common to all legs, which may change in flight, is estimated from those residuals by
   Bayesian online change-point detection, and every unflown leg is predicted as forecast + shift;
3. plans the rest from its present node and estimated battery state on its *expected* belief
   (median health, predicted winds), with the attention planner (``planner="attention"``, the
   default: :func:`~uam_studio.planning.agents.attention.decode.continue_route`) or exactly
   (``planner="oracle"``: :func:`~uam_studio.planning.solvers.oracle.feasible_sorties`), allowing
   only first legs after which the aircraft can still get home on its *cautious* belief: the cell
   ``health_z`` std to the weak side, and the two legs' winds at a joint one-sided ``wind_z`` bound of
   their forecast errors and a change of the weather common to both (the weather reserve ``reserve_kt`` is
   that change's ``wind_z`` quantile) (:meth:`Operator._safe_moves`). The search asks every later move of
   the plan to pass the same check at its own take-off, on the expected cell, with each leg's wind at its
   share of the joint bound for two like legs: ``wind_z`` / sqrt 2 std and the reserve, in quadrature.
   A plan that the next take-offs would cut short is not chosen. A new pack's take-off plan is searched
   without it (its cell is still the fleet prior: 20 s of readings say little of q_max); a pack with a
   logbook is checked from the take-off on;
4. flies that first leg only, and re-plans on arrival. Its margins: its uncertainty and the weather reserve; the
   belief's model-error term widens its intervals, not its checks (RESULTS.md, "A world unlike the model").
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, cast

import numpy as np

from uam_studio.battery import BatteryState, full_charge, simulate
from uam_studio.battery.health import SOURCE_LOGBOOK, BelievedHealth, HealthBelief, Logbook
from uam_studio.battery.simulate import simulate_cell
from uam_studio.errors import InputError, check_range
from uam_studio.flight import leg_profile
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import ALTITUDES_M, DT_S, N_MAX, N_TARGETS, VERTIPORT_SLOT, LegTable
from uam_studio.planning.missions.mission import VERTIPORT, Battery, Destination, Mission, check_destination_count
from uam_studio.planning.missions.scenario import check_scenario
from uam_studio.planning.operations.decision import Decision, LegObservation
from uam_studio.planning.operations.defaults import DEFAULT_FORECAST_SIGMA_KT, WEATHER_RESERVE_KT, fit_noise_v
from uam_studio.planning.operations.wind_belief import WindBelief, wind_from_duration
from uam_studio.planning.planners import IN_FLIGHT_PLANNERS, PLANNERS
from uam_studio.planning.solvers.oracle import (
    Sortie,
    best_single_sortie,
    feasible_sorties,
    mask_priority,
    sortie_cover_table,
)
from uam_studio.planning.solvers.setup import safest_level
from uam_studio.risk import HEALTH_Z, WIND_Z

PLAN_WIND_Z = 0.5  # std of a leg's predicted wind the expected belief takes
RESERVE_RANGE_KT = (0.0, 60.0)  # kt, allowed weather reserves
Q_PLAN_RANGE = (2000.0, 12000.0)  # C, belief cell bounds
R0_PLAN_RANGE = (0.005, 1.5)  # ohm


class Operator:
    """Decides the flight from the forecast and the readings (see the module docstring).

    :param mission: the mission as the operator knows it: forecast winds and the cut-off. Its ``battery`` is never
        read (the operator's cell is its estimate); the flight loop hands it a mission whose battery is a placeholder.
    :param scenario: overrides ``mission.scenario``.
    :param forecast_sigma_kt: the forecast's stated error std (kt).
    :param sensor_noise_mv: the voltage sensor's stated noise std (mV), or None to estimate it.
    :param health_z: margin on the health estimate (std).
    :param wind_z: margin on each unflown leg's wind (std).
    :param planner: ``"attention"`` (the learned planner, default) or ``"oracle"`` (exact search).
    :param reserve_kt: the weather reserve (kt, 0-60): the ``wind_z`` quantile of a change of the weather that every
        take-off's check holds beside the forecast's error (:meth:`_safe_moves`).
    :param logbook: the pack's logbook (its earlier flights, as measured); None or empty: a new pack.
    """

    check_at_takeoff = False  # the take-off's plan asks the later take-offs' check too (:meth:`_later_check`)

    def __init__(self, mission: Mission, scenario: str | None = None,
                 forecast_sigma_kt: float = DEFAULT_FORECAST_SIGMA_KT,
                 sensor_noise_mv: float | None = None, health_z: float = HEALTH_Z, wind_z: float = WIND_Z,
                 plan_wind_z: float = PLAN_WIND_Z, planner: str = "attention",
                 reserve_kt: float = WEATHER_RESERVE_KT, logbook: Logbook | None = None) -> None:
        if planner not in IN_FLIGHT_PLANNERS:
            raise InputError("policy", f"{planner!r} is not an in-flight policy; allowed: "
                                       f"{', '.join(IN_FLIGHT_PLANNERS)}")
        self.planner = planner
        check_scenario(scenario := scenario or mission.scenario)
        # the exact search of planner "oracle": 8 at most
        check_destination_count(len(mission.destinations), N_MAX, "fly")
        self.forecast_mission, self.scenario, self.eod_v = mission, scenario, mission.eod_v
        self.health_z = check_range("health_z", health_z, 0.0, 5.0)
        self.wind_z = check_range("wind_z", wind_z, 0.0, 5.0)
        self.plan_wind_z = check_range("plan_wind_z", plan_wind_z, 0.0, 5.0)
        self.reserve_kt = check_range("reserve_kt", reserve_kt, *RESERVE_RANGE_KT)
        self.noise_v = None if sensor_noise_mv is None else fit_noise_v(sensor_noise_mv)
        self.health_belief = HealthBelief(self.noise_v, self.eod_v, logbook=logbook, dt_s=DT_S)  # the paper's box
        self.winds = WindBelief({n: mission.node(n).wind_kts for n in mission.node_names}, forecast_sigma_kt)
        self.names = tuple(d.name for d in mission.destinations)
        self.node, self.time_s, self.sorties = VERTIPORT, 0.0, 0
        self.visited: list[str] = []
        self.decisions: list[Decision] = []
        self._last_route: tuple[str, ...] | None = None
        self._leg_start_s = 0.0
        self._leg: tuple[str, str, float] | None = None
        self._observed: LegObservation | None = None  # the last leg's wind, not yet read by a decision

    # ------------------------------------------------------------------ sensing
    def observe(self, time_s: np.ndarray, current_a: np.ndarray, voltage_v: np.ndarray) -> None:
        """Take readings (s, A, V) at 1 Hz."""
        if len(time_s):
            self.health_belief.observe(current_a, voltage_v)
            self.time_s = float(time_s[-1])

    def arrived(self, to: str) -> str:
        """The aircraft landed at ``to`` (the leg it was sent on); returns what the leg told about the wind."""
        if self._leg is None or self._leg[1] != to:
            raise InputError("arrived", f"{to!r} is not where the operator sent the aircraft")
        frm, _, alt = self._leg
        m = self.forecast_mission
        duration = self.time_s - self._leg_start_s
        dwell = cast(Destination, m.node(to)).dwell_s if to != VERTIPORT else 0.0
        wind = wind_from_duration(m.distance_km(frm, to), alt, dwell, duration)
        resid, surprise = self.winds.observe(to, wind)
        self.node = to
        self._leg = None
        if to == VERTIPORT:
            self.sorties += 1
            self.health_belief.recharged()
        else:
            self.visited.append(to)
        note = f"wind to {to} {wind:+.0f} kt ({resid:+.0f} kt against the forecast)"
        change = self.winds.change()
        if change.worth_saying:
            note += "; " + change.text()
        self._observed = LegObservation(wind, resid, surprise, note)
        return note

    @property
    def last_observation(self) -> str:
        """What the last leg flown told about the wind ("" once a decision has read it)."""
        return self._observed.note if self._observed is not None else ""

    def health(self) -> BelievedHealth:
        """What it believes of its cell's health, from all readings and the fleet prior."""
        return self.health_belief.health()

    # ------------------------------------------------------------------ planning
    def _belief(self, health: BelievedHealth, health_z: float, wind_z: float, extra_kt: float = 0.0
                ) -> tuple[Mission, float, float]:
        """The mission as believed, ``z`` std to the cautious side: less q_max, more R0, more headwind: each leg's
        predicted wind + the root of the sum of squares of ``wind_z`` std and ``extra_kt`` (kt; the weather
        reserve's share, independent of the forecast's error)."""
        q_plan = float(np.clip(health.cautious_q_max_c(health_z), *Q_PLAN_RANGE))
        r_plan = float(np.clip(health.cautious_r0_ohm(health_z), *R0_PLAN_RANGE))
        lo, hi = WIND_RANGE_KTS
        m = self.forecast_mission

        def w(node: str) -> float:
            mean, sd = self.winds.predict(node)
            return float(np.clip(mean + math.hypot(wind_z * sd, extra_kt), lo, hi))

        dests = tuple(dataclasses.replace(d, wind_kts=w(d.name)) for d in m.destinations)
        vp = dataclasses.replace(m.vertiport, wind_kts=w(VERTIPORT))
        belief = dataclasses.replace(m, vertiport=vp, destinations=dests, battery=Battery(q_plan, r_plan))
        return belief, q_plan, r_plan

    def _episode(self, belief: Mission) -> Episode:
        """The episode of a believed mission (:meth:`_belief`): its legs, cell, cut-off (V) and scenario."""
        return Episode.of(LegTable(belief), self.scenario)

    def _state(self, q_plan: float, r_plan: float) -> BatteryState:
        """Battery state of a believed cell after the readings since the last full charge."""
        cur, _ = self.health_belief.segment.arrays()
        if cur.size == 0:
            return full_charge(q_plan)
        return simulate(np.clip(cur, -50, 50), DT_S, q_plan, r_plan, 2.5).final_state

    def leg_current(self, frm: str, to: str, altitude_m: float, wind_kts: float) -> np.ndarray:
        """The per-cell current (A, 1 s samples) of the leg ``frm`` -> ``to`` at ``altitude_m`` (m) in ``wind_kts``."""
        m = self.forecast_mission
        dwell = cast(Destination, m.node(to)).dwell_s if to != VERTIPORT else 0.0
        wind = float(np.clip(wind_kts, *WIND_RANGE_KTS))
        return np.asarray(leg_profile(m.distance_km(frm, to), altitude_m, wind, DT_S, dwell).current_a)

    def _safe_moves(self, episode: Episode, here: int, state: np.ndarray, visited: int) -> np.ndarray:
        """bool [N_TARGETS, N_ALTITUDES]: next legs after which the aircraft can still get home.

        Both legs are flown on the cautious belief's episode (its cell) from ``state``, their winds at the point of a
        joint one-sided ``wind_z`` bound: each leg's wind error is an independent Gaussian (std from
        :meth:`WindBelief.predict`) plus a change of the weather common to both, N(0, ``reserve_kt / wind_z``) (the
        reserve is its ``wind_z`` quantile); each leg's charge grows with its wind in proportion to its length d, so
        the bound puts each leg's wind at ``mean + wind_z * (Sigma d)_leg / sqrt(d' Sigma d)``. A wind already
        measured has a small std: the margin then goes to the unknown one and to the change.
        """
        legs = episode.legs
        n_alt = len(ALTITUDES_M)
        safe = np.zeros((N_TARGETS, n_alt), dtype=bool)
        frm = self.names[here] if here != VERTIPORT_SLOT else VERTIPORT
        home_mean, home_sd = self.winds.predict(VERTIPORT)
        done = np.array([bool(visited >> k & 1) for k in range(legs.slots)])
        # the episode's open moves among every unvisited destination (a sortie may pass one that is too
        # close to the vertiport to fly to directly, as the exact search does)
        open_moves = episode.moves(here, done, among=legs.present[:legs.slots])[0]
        firsts, returns = [], []
        change_sd = self.reserve_kt / self.wind_z if self.wind_z > 0 else 0.0  # the common change's std
        flat = 0.0 if self.wind_z > 0 else self.reserve_kt
        for j in np.flatnonzero(open_moves[:legs.slots].any(axis=1)):
            to = self.names[j]
            mean, sd = self.winds.predict(to)
            d1, d2 = legs.dist[here, j], legs.dist[j, VERTIPORT_SLOT]
            common = change_sd ** 2 * (d1 + d2)
            norm = math.sqrt((sd * d1) ** 2 + (home_sd * d2) ** 2 + common * (d1 + d2)) or 1.0
            w1 = mean + self.wind_z * (sd ** 2 * d1 + common) / norm + flat
            w2 = home_mean + self.wind_z * (home_sd ** 2 * d2 + common) / norm + flat
            rets = [(b, self.leg_current(to, VERTIPORT, ALTITUDES_M[b], w2))
                    for b in range(n_alt) if legs.feasible[j, VERTIPORT_SLOT, b]]  # the same after each altitude
            for a in np.flatnonzero(open_moves[j]):
                firsts.append((int(j), int(a), self.leg_current(frm, to, ALTITUDES_M[a], w1)))
                returns.append(rets)
        if open_moves[VERTIPORT_SLOT].any():
            w = home_mean + self.wind_z * math.hypot(home_sd, change_sd) + flat
            for a in np.flatnonzero(open_moves[VERTIPORT_SLOT]):
                firsts.append((VERTIPORT_SLOT, int(a), self.leg_current(frm, VERTIPORT, ALTITUDES_M[a], w)))
                returns.append([])
        if not firsts:
            return safe
        ok, x_end, _ = episode.fly_currents([c for _, _, c in firsts], state)
        back = [(k, c) for k, rets in enumerate(returns) if ok[k] for _, c in rets]
        home_ok = np.zeros(len(firsts), dtype=bool)
        if back:
            ok2, _, _ = episode.fly_currents([c for _, c in back], x_end[[k for k, _ in back]])
            for (k, _), good in zip(back, ok2):
                home_ok[k] |= bool(good)
        for k, (tgt, lvl, _) in enumerate(firsts):
            safe[tgt, lvl] = ok[k] and (tgt == VERTIPORT_SLOT or home_ok[k])
        return safe

    def _later_check(self, health: BelievedHealth) -> Episode | None:
        """The mission under the check every later take-off of a plan must pass (the plan search's ``checked``):
        each leg at its predicted wind + its share of the joint bound for two like legs (``wind_z`` / sqrt 2
        std and the reserve in quadrature), on the expected cell. None at take-off for a new pack (unless
        ``check_at_takeoff``): its cell is the fleet prior then, not the cell the later checks fly; a pack with a
        logbook is checked at once."""
        if not (self.decisions or self.check_at_takeoff or self.health_belief.source == SOURCE_LOGBOOK):
            return None
        return self._episode(self._belief(health, 0.0, self.wind_z / math.sqrt(2.0), self.reserve_kt)[0])

    def abort(self, reason: str) -> Decision:
        """The flight ends before any plan (the take-off check fell below the cut-off): a decision of kind
        ``"abort"`` with the belief so far (the fleet prior where the readings are too short to fit)."""
        try:
            est = self.health()
        except InputError:
            est = self.health_belief.prior_health()
        shift, shift_sd = self.winds.shift()
        d = Decision(time_s=self.time_s, node=self.node, kind="abort", reason=reason,
                     **cast(dict[str, Any], est.in_units()),  # its four floats (the others could be any type)
                     plan_q_max_c=est.q_max_c, plan_r0_ohm=est.r0_ohm, wind_shift_kts=shift,
                     wind_shift_sd_kts=shift_sd, route=(), altitudes_m=(), next_to=None, next_altitude_m=None,
                     health_flags=self.health_belief.flags(), reserve_kt=self.reserve_kt)
        self.decisions.append(d)
        return d

    def decide(self) -> Decision:
        """Re-plan from here; the returned decision's ``next_to`` / ``next_altitude_m`` is the next leg.

        The plan is searched on the expected belief (median health, predicted winds); its first leg must
        be one after which the aircraft can still get home on the cautious belief (``health_z``,
        ``wind_z``). Only that first leg is committed: the rest is re-planned at the next arrival.
        """
        t0 = time.perf_counter()
        health = self.health()
        q, r = health.q_max_c, health.r0_ohm
        expected, q_exp, r_exp = self._belief(health, 0.0, self.plan_wind_z)
        cautious, q_plan, r_plan = self._belief(health, self.health_z, 0.0)
        slot = {n: k for k, n in enumerate(self.names)}
        here = VERTIPORT_SLOT if self.node == VERTIPORT else slot[self.node]
        visited = 0
        for n in self.visited:
            visited |= 1 << slot[n]
        moves = self._safe_moves(self._episode(cautious), here, self._state(q_plan, r_plan).as_array()[0], visited)
        state = self._state(q_exp, r_exp).as_array()[0]
        plan = self._plan_learned if PLANNERS[self.planner].learned else self._plan
        believed = self._episode(expected)
        route, alts, why = plan(believed, here, state, visited, moves, self._later_check(health))
        if route is None:
            route, alts, why = self._best_effort_home(believed, here, state)
        shift, shift_sd = self.winds.shift()
        kind = "plan" if not self.decisions else "replan"
        learned = [self.last_observation] if self.last_observation else []
        prev = self.decisions[-1] if self.decisions else None
        if prev is not None and abs(q - prev.q_max_c) > max(2 * prev.q_max_sd_c, 0.03 * prev.q_max_c):
            learned.append(f"q_max estimate {prev.q_max_c:.0f} -> {q:.0f} C "
                           f"({'weaker' if q < prev.q_max_c else 'stronger'} battery than thought)")
        if prev is not None and abs(r - prev.r0_ohm) > max(2 * prev.r0_sd_ohm, 0.01):
            learned.append(f"R0 estimate {prev.r0_ohm:.3f} -> {r:.3f} ohm")
        seen = f" ({self.last_observation})" if self.last_observation else ""
        if not route or why.startswith("no way home"):
            reason = why + seen
        elif self._last_route is not None and tuple(route) == self._last_route:
            reason = "plan unchanged" + seen
        elif self._last_route is None:
            reason = why + seen
        else:
            reason = "plan changed: " + "; ".join(learned + [why])
        seen_leg, self._observed = self._observed, None
        leg_wind, leg_resid, surprise = ((seen_leg.wind_kt, seen_leg.residual_kt, seen_leg.surprise)
                                         if seen_leg is not None else (None, None, False))
        nxt = route[0] if route else None
        change = self.winds.change()
        d = Decision(time_s=self.time_s, node=self.node, kind=kind, reason=reason, **health.in_units(),
                     plan_q_max_c=q_plan, plan_r0_ohm=r_plan, wind_shift_kts=shift, wind_shift_sd_kts=shift_sd,
                     route=tuple(route), altitudes_m=tuple(alts), next_to=nxt,
                     next_altitude_m=alts[0] if route else None, compute_s=time.perf_counter() - t0,
                     health_flags=self.health_belief.flags(), leg_wind_kts=leg_wind,
                     leg_wind_vs_forecast_kts=leg_resid, wind_surprise=surprise, wind_change_p=change.p,
                     wind_change=change.text() if change.worth_saying else "", reserve_kt=self.reserve_kt)
        self._last_route = tuple(route[1:])
        self.decisions.append(d)
        if nxt is not None:
            self._leg = (self.node, nxt, float(alts[0]))
            self._leg_start_s = self.time_s
        return d

    def start_leg_at(self, time_s: float) -> None:
        """The clock (s) at which the leg just decided took off (the first leg: 0, before the check)."""
        self._leg_start_s = float(time_s)

    def _plan(self, episode: Episode, here: int, state: np.ndarray, visited: int, moves: np.ndarray,
              checked: Episode | None = None) -> tuple[list[str] | None, list[float], str]:
        """The best plan of ``episode`` (the expected belief) whose first leg is in ``moves`` and whose
        every later move to a destination passes the take-off check on ``checked`` (the legs under the
        check's winds); None: only the way home is left and it is not safe on the cautious belief."""
        n = len(self.names)
        legs, rules = episode.legs, episode.rules

        def names(s: Sortie) -> tuple[list[str], list[float]]:
            return [self.names[k] for k in s.nodes] + [VERTIPORT], [ALTITUDES_M[a] for a in s.alts]

        if rules.one_leg:
            if here != VERTIPORT_SLOT or visited:
                return [], [], "single flight done"
            levels = [a for a in range(len(ALTITUDES_M)) if moves[0, a]] or \
                [a for a in range(len(ALTITUDES_M)) if legs.feasible[VERTIPORT_SLOT, 0, a]]
            if not levels:
                return [], [], f"{self.names[0]} cannot be reached at any level"
            level, _, vmin = safest_level(episode, VERTIPORT_SLOT, 0, levels, state)
            return [self.names[0]], [ALTITUDES_M[level]], f"highest expected minimum voltage ({vmin.max():.3f} V)"

        if here == VERTIPORT_SLOT and rules.one_sortie and self.sorties >= 1:
            return [], [], "back home: the charge is used"
        unvisited_ok = np.array([k < n and not visited >> k & 1 for k in range(N_MAX)])
        if here == VERTIPORT_SLOT:
            start = None
        else:
            start = (here, state, visited)
        cont = feasible_sorties(episode, allowed=unvisited_ok, start=start, first_moves=moves, reserve=checked)
        if here == VERTIPORT_SLOT:
            cont = {m: s for m, s in cont.items() if m}
            if not cont:
                return [], [], "no unvisited destination can be reached safely"
        elif not cont:
            return None, [], ""
        best: Sortie | None  # the sortie flown next (None below: no cover found yet)
        if rules.one_sortie:
            best = best_single_sortie(cont, legs)
            route, alts = names(best)
            return route, alts, f"expected priority {mask_priority(legs, best.mask)} this charge"
        # multi charge: this sortie's rest, then the fewest fresh sorties for what is left
        fresh = feasible_sorties(episode, allowed=unvisited_ok, reserve=checked)
        fresh = {m: s for m, s in fresh.items() if m}
        universe = 0
        for m in list(fresh) + [m & ~visited for m in cont]:
            universe |= m
        table = sortie_cover_table(fresh, universe)
        best_key, best = None, None
        for m, s in cont.items():
            rest = universe & ~(m & ~visited)
            if rest not in table:
                continue
            key = (table[rest][0], table[rest][1] + s.time_s, -s.min_voltage_v)
            if best_key is None or key < best_key:
                best_key, best = key, s
        if best is None:
            best = max(cont.values(), key=lambda s: (bin(s.mask).count("1"), -s.time_s))
            route, alts = names(best)
            return route, alts, "the rest cannot all be covered; visiting what this charge reaches"
        assert best_key is not None  # set with best
        route, alts = names(best)
        rest = universe & ~(best.mask & ~visited)
        while rest:  # the later sorties of the plan, as the cover table has them
            later = fresh[table[rest][2]]
            more, more_alts = names(later)
            route, alts = route + more, alts + more_alts
            rest ^= later.mask
        return route, alts, f"expected {best_key[0]} more charges after this one"

    def _plan_learned(self, episode: Episode, here: int, state: np.ndarray, visited: int, moves: np.ndarray,
                      checked: Episode | None = None) -> tuple[list[str] | None, list[float], str]:
        """:meth:`_plan` with the attention planner continued from here (the same contract)."""
        from uam_studio.planning.agents.attention.decode import continue_route  # torch, at first use

        n = len(self.names)
        legs, rules = episode.legs, episode.rules
        if rules.one_leg or (here == VERTIPORT_SLOT and rules.one_sortie and self.sorties >= 1):
            return self._plan(episode, here, state, visited, moves, checked)
        done = np.array([bool(visited >> k & 1) for k in range(n)])
        res = continue_route(episode, here, state, done, self.sorties, moves, reserve=checked)
        if res is None:
            return ([], [], "no unvisited destination can be reached safely") if here == VERTIPORT_SLOT else \
                (None, [], "")
        nodes, levels = res
        route = [VERTIPORT if k == legs.home else self.names[k] for k in nodes]
        alts = [ALTITUDES_M[a] for a in levels]
        if rules.one_sortie:
            prio = int(sum(legs.priority[k] for k in nodes if k != legs.home))
            return route, alts, f"expected priority {prio} more this charge"
        return route, alts, f"expected {max(0, route.count(VERTIPORT) - 1)} more charges after this one"

    def _best_effort_home(self, episode: Episode, here: int, state: np.ndarray
                          ) -> tuple[list[str], list[float], str]:
        """Home when no way is cautiously safe: the safest level on ``episode``, else the one that gets furthest."""
        legs = episode.legs
        levels = [a for a in range(len(ALTITUDES_M)) if legs.feasible[here, VERTIPORT_SLOT, a]] or [0]
        best, best_key = levels[0], None
        for a in levels:
            cur = legs.current(here, VERTIPORT_SLOT, a)
            res = simulate_cell(cur, episode.cell, DT_S, initial_state=BatteryState.from_array(state[None, :]))
            key = (0.0, float(res.min_voltage_v)) if not res.eod_reached else (-1.0 + float(res.eod_s) / cur.size, 0.0)
            if best_key is None or key > best_key:
                best, best_key = a, key
        return [VERTIPORT], [ALTITUDES_M[best]], (
            "no way home is safe on the cautious belief: going home at the level most likely to make it "
            f"({ALTITUDES_M[best]:g} m)")


__all__ = ["HEALTH_Z", "IN_FLIGHT_PLANNERS", "PLAN_WIND_Z", "RESERVE_RANGE_KT", "WEATHER_RESERVE_KT", "WIND_Z",
           "Operator"]
