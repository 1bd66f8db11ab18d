"""One model of a mission episode: the rules every planner searches under.

An :class:`Episode` is a mission's leg table (:class:`~uam_studio.planning.legs.LegTable`), the cell
the planner flies it with (:class:`~uam_studio.battery.parameters.Cell`: parameter set, q_max C, R0 ohm,
cut-off V) and the scenario's rules (:class:`~uam_studio.planning.missions.scenario.Scenario`). It
answers what every planner asks, each in one place:

* which destinations may ever be served (:attr:`Episode.servable`);
* which moves are open from a node, given what is visited (:meth:`Episode.targets`,
  :meth:`Episode.moves`: the action mask before the battery is asked);
* the cell's state after legs, many at once (:meth:`Episode.fly`, the batched battery
  :func:`fly_batch`), and a full charge (:meth:`Episode.fresh`);
* what arriving somewhere does (:meth:`Episode.arrive`: a landing at the vertiport recharges in
  ``multi_charge``) and whether the episode ends there (:meth:`Episode.ends_after`).

The gym environment, greedy, the attention beam search, the exact oracle, its reference solver and the
operator build their search on it and supply only the search. The operator's episode holds its belief
(the cautious cell, the forecast winds), never the world's truth.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from uam_studio.battery import STATE_NAMES, full_charge, kernel
from uam_studio.battery.electrochem import model_constants
from uam_studio.battery.parameters import Cell
from uam_studio.planning.legs import DT_S, LegTable
from uam_studio.planning.missions.scenario import Scenario, scenario_rules


def fly_batch(
    currents: Sequence[np.ndarray], x0: np.ndarray, cell: Cell, split: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """Fly many legs of different lengths from many states of one ``cell`` on the compiled battery kernel
    (:func:`uam_studio.battery.kernel.fly_rows`: each row one pass, stopped at its cut-off).

    :param currents: B per-cell currents (A, 1 s samples), any lengths.
    :param x0: start states, shape [B, 8] (order of ``STATE_NAMES``).
    :param cell: the parameter set, health (q_max C, R0 ohm) and cut-off (V) flown.
    :param split: optional [B] sample counts (1 to the row's length): also return the state after
        that many samples of each row (e.g. the end of the first of two legs flown as one row).
    :return: ``(ok [B], x_end [B, 8], v_min [B])``: no sample below the cut-off; state after the
        last sample (the start state where not ok); lowest voltage (V) up to the first sample below
        the cut-off, that sample included (0 where it is NaN). Same numbers as :func:`uam_studio.battery.simulate` leg
        by leg (same kernel). With ``split``, a fourth array ``x_split [B, 8]``: the state after ``split`` samples (the
        start state where the row failed before them).
    """
    b = len(currents)
    x_start = np.asarray(x0, dtype=float).reshape(b, len(STATE_NAMES))  # read, never written
    params = cell.params
    ok, x_end, v_min, x_split = kernel.fly_rows(currents, x_start, float(params.q_total(cell.q_max)), float(cell.r0),
                                                DT_S, model_constants(params), float(cell.eod_v), split)
    v_min = np.nan_to_num(v_min, nan=0.0)
    return (ok, x_end, v_min) if split is None else (ok, x_end, v_min, x_split)


@dataclass(frozen=True)
class Episode:
    """The rules of one mission's episode (module docstring).

    :param legs: the mission's leg table (node ``legs.home`` is the vertiport).
    :param cell: the cell the planner flies (its parameter set, q_max C, R0 ohm, cut-off V).
    :param rules: the scenario's rules.
    """

    legs: LegTable
    cell: Cell
    rules: Scenario

    @classmethod
    def of(cls, legs: LegTable, scenario: str | None = None, cell: Cell | None = None) -> Episode:
        """The episode of ``legs.mission`` under ``scenario`` (default: the mission's) with ``cell``
        (default: the mission's own, :attr:`~uam_studio.planning.missions.mission.Mission.cell`)."""
        m = legs.mission
        return cls(legs, m.cell if cell is None else cell,
                   scenario_rules(scenario if scenario is not None else m.scenario))

    @property
    def home(self) -> int:
        """Node index of the vertiport."""
        return self.legs.home

    @property
    def slots(self) -> int:
        """Destination slots of the leg table."""
        return self.legs.slots

    def fresh(self) -> np.ndarray:
        """The state of a fully charged, rested cell, shape [8] (what a recharge resets the cell to)."""
        return full_charge(self.cell.q_max, self.cell.params).as_array()[0]

    @functools.cached_property
    def servable(self) -> np.ndarray:
        """bool [slots]: destinations the aircraft may ever fly to: present and far enough from the
        vertiport for some level (a way back exists at that level too); in ``single_flight`` only
        ``destinations[0]``. Do not modify."""
        out = cast(np.ndarray, self.legs.feasible[self.home, :self.slots].any(axis=1))  # [slots, levels] -> [slots]
        if self.rules.one_leg:
            out[1:] = False
        out.setflags(write=False)
        return out

    def targets(self, node: int | np.ndarray, visited: np.ndarray, among: np.ndarray | None = None) -> np.ndarray:
        """bool [B, slots + 1]: the nodes a next leg may go to from ``node`` ([B] node indices) with
        ``visited`` ([B, slots] bool) already served: the destinations ``among`` ([slots] bool; default
        :attr:`servable`) not yet visited, and the vertiport from anywhere but itself (never in
        ``single_flight``)."""
        node = np.atleast_1d(np.asarray(node))
        visited = np.asarray(visited, dtype=bool).reshape(node.size, self.slots)
        ok = self.servable if among is None else np.asarray(among, dtype=bool)
        out = np.zeros((node.size, self.slots + 1), dtype=bool)
        out[:, :self.slots] = ok[None, :] & ~visited
        out[:, self.home] = (node != self.home) & (not self.rules.one_leg)
        return out

    def moves(self, node: int | np.ndarray, visited: np.ndarray, among: np.ndarray | None = None) -> np.ndarray:
        """bool [B, slots + 1, levels]: the (node, level) moves open from ``node``: :meth:`targets`
        whose leg fits the level (``legs.feasible``). The battery is not asked."""
        node = np.atleast_1d(np.asarray(node))
        return self.targets(node, visited, among)[:, :, None] & self.legs.feasible[node]

    def fly(self, moves: Sequence[tuple[int, int, int]], states: np.ndarray,
            split: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """Fly legs ``(from, to, level)`` from ``states`` ([B, 8], or one [8] state for all) on the
        episode's cell: :func:`fly_batch`'s ``(ok, x_end, v_min)`` (and ``x_split`` with ``split``)."""
        currents = [self.legs.current(int(i), int(j), int(a)) for i, j, a in moves]
        return self.fly_currents(currents, states, split)

    def fly_currents(self, currents: Sequence[np.ndarray], states: np.ndarray,
                     split: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """:meth:`fly` for given per-cell currents (A, 1 s samples; e.g. legs under other winds, or two
        legs flown as one row)."""
        x0 = np.asarray(states, dtype=float)
        if x0.ndim == 1:
            x0 = np.repeat(x0[None, :], len(currents), axis=0)
        return fly_batch(currents, x0, self.cell, split=split)

    def there_and_home(self, moves: Sequence[tuple[int, int, int | None]], states: np.ndarray) -> np.ndarray:
        """bool [B]: each move ``(from, to, level)`` (level None: the leg's cheapest), then the way home at
        its cheapest level, flown as one row from ``states`` [B, 8] on this episode, ends above the
        cut-off. A move to the vertiport passes; a leg with no feasible level fails."""
        legs, home = self.legs, self.home
        out = np.ones(len(moves), dtype=bool)
        rows, idx = [], []
        for k, (i, j, a) in enumerate(moves):
            if j == home:
                continue
            go = legs.cheapest_level(int(i), int(j)) if a is None else int(a)
            back = legs.cheapest_level(int(j), home)
            if go is None or back is None or not legs.feasible[int(i), int(j), go]:
                out[k] = False
                continue
            rows.append(np.concatenate([legs.current(int(i), int(j), go), legs.current(int(j), home, back)]))
            idx.append(k)
        if rows:
            out[idx] = self.fly_currents(rows, np.asarray(states, dtype=float)[idx])[0]
        return out

    def arrive(self, node: int, state: np.ndarray) -> np.ndarray:
        """The cell's state once landed at ``node``: a full charge at the vertiport where the scenario
        recharges (:meth:`fresh`), else ``state`` itself."""
        if node == self.home and self.rules.recharges:
            return self.fresh()
        return state

    def ends_after(self, node: int, visited: np.ndarray) -> bool:
        """Does the episode end once the aircraft has landed safely at ``node`` with ``visited`` ([slots]
        bool, ``node`` included) served? ``single_flight``: after its one leg; ``single_charge``: back at
        the vertiport; ``multi_charge``: back at the vertiport with every servable destination visited."""
        if node != self.home:
            return self.rules.one_leg
        if not self.rules.recharges:
            return True
        return bool(np.asarray(visited, dtype=bool)[self.servable].all())


__all__ = ["Episode", "fly_batch"]
