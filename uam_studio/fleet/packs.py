"""A fleet's aircraft and their packs: the world's truth of each pack and the logbook its sensors keep.

- :class:`Fleet`: each aircraft's true pack (:class:`~uam_studio.fleet.aging.PackHealth`, the world's: its health as
  it ages and, in the varied world, its own parameter set) and its pack's logbook; an aircraft's belief is derived
  from its logbook (:meth:`Fleet.belief`, the one belief value on the fleet's declared configuration).
- The packs' cell types (:data:`PACK_LAWS`), their factory and their default age spread (:func:`default_age_spread`).

:mod:`uam_studio.fleet.day` flies them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from uam_studio.battery.health.belief import PackBelief
from uam_studio.battery.health.config import FLEET_LAWS, fleet_belief_config
from uam_studio.battery.health.logbook import Logbook
from uam_studio.battery.pack_variation import pack_params
from uam_studio.battery.parameters import DEFAULT_CELL, CellParameters
from uam_studio.errors import MAX_SEED, InputError, check_range, check_seed
from uam_studio.fleet.aging import END_OF_LIFE_FRACTION, AgingLaw, PackHealth
from uam_studio.fleet.demand import MAX_VERTIPORTS
from uam_studio.fleet.dispatch import EOD_V
from uam_studio.planning.operations.world import DEFAULT_WORLD, check_world

__all__ = ["AGE_SPREAD_LIFE", "FACTORY_Q_MAX_C", "FACTORY_R0_OHM", "NOISE_A", "NOISE_V", "PACK_LAWS", "Fleet",
           "default_age_spread", "pack_law"]

NOISE_V, NOISE_A = 0.005, 0.020  # the fleet's sensor noise std (V, A)
PACK_LAWS: dict[str, AgingLaw] = FLEET_LAWS  # how a fleet's packs age, by cell type (declared with their belief)
AGE_SPREAD_LIFE = 0.6  # default: the packs have delivered U(0, this share of their law's cycles to 80%)
FACTORY_Q_MAX_C = (7300.0, 7900.0)  # C: a new pack's q_max, uniform over this range
FACTORY_R0_OHM = (0.10, 0.13)  # ohm: a new pack's R0, uniform over this range


def default_age_spread(law: str = "nasa") -> float:
    """The packs' default age spread (equivalent full cycles): :data:`AGE_SPREAD_LIFE` of the cycles to
    80% of the first capacity under ``law`` at 25 C, to a whole cycle (54 for ``"nasa"``, 294 for
    ``"vtc6"``)."""
    return float(round(AGE_SPREAD_LIFE * pack_law(law).cycles_to(END_OF_LIFE_FRACTION)))


def pack_law(name: str) -> AgingLaw:
    """The aging law of cell type ``name`` (a key of :data:`PACK_LAWS`); one line naming ``law`` otherwise."""
    if name not in PACK_LAWS:
        raise InputError("law", f"{name!r}: allowed {', '.join(PACK_LAWS)}")
    return PACK_LAWS[name]


def _own_params(world: str, number: int) -> CellParameters | None:
    """A new pack's own parameter set in ``world`` (None: the cell type's, in the model world)."""
    return pack_params(DEFAULT_CELL, number) if world == "varied" else None


def _factory_pack(rng: np.random.Generator) -> tuple[float, float]:
    return float(rng.uniform(*FACTORY_Q_MAX_C)), float(rng.uniform(*FACTORY_R0_OHM))


@dataclass
class Fleet:
    """The aircraft: each one's true pack (``truth``, the world's) and its pack's ``logbooks`` (every flight as its
    sensors read it; an aircraft's belief is derived from its logbook, :meth:`belief`); ``in_service``
    false once a pack has retired (below 80% of its first capacity); ``base``: each one's vertiport
    (default all at vertiport 0); ``law``: the packs' cell type, a key of :data:`PACK_LAWS`; ``logbooks``: default
    empty ones of packs that have delivered what their truth has (the operator's current sensor logged it);
    ``world``: the world a renewed pack comes from (``"varied"``: its own parameter set; ``"model"``: its type's)."""

    truth: list[PackHealth]
    in_service: list[bool] = field(default_factory=list)
    base: list[int] = field(default_factory=list)
    law: str = "nasa"
    logbooks: list[Logbook] = field(default_factory=list)
    world: str = DEFAULT_WORLD
    _beliefs: dict[int, tuple[Logbook, PackBelief]] = field(default_factory=dict, init=False, repr=False,
                                                            compare=False)

    def __post_init__(self) -> None:
        pack_law(self.law)
        if not 1 <= len(self.truth) <= 50:
            raise InputError("aircraft", f"{len(self.truth)} aircraft: allowed 1-50")
        if not self.in_service:
            self.in_service = [not t.retired for t in self.truth]
        if not self.base:
            self.base = [0] * len(self.truth)
        if not self.logbooks:
            self.logbooks = [_new_logbook(t.delivered_c) for t in self.truth]
        if len(self.logbooks) != len(self.truth):
            raise InputError("logbooks", f"{len(self.logbooks)} logbooks for {len(self.truth)} aircraft: one each")
        if len(self.base) != len(self.truth) or not all(0 <= b < MAX_VERTIPORTS for b in self.base):
            raise InputError("vertiports", f"a base vertiport 0-{MAX_VERTIPORTS - 1} for each aircraft")

    def belief(self, i: int) -> PackBelief:
        """Aircraft ``i``'s belief at its next take-off, derived from its logbook
        (:meth:`~uam_studio.battery.health.belief.PackBelief.of` on the fleet's declared configuration,
        :func:`~uam_studio.battery.health.config.fleet_belief_config`, going on from the belief last derived)."""
        belief = PackBelief.of(self.logbooks[i], fleet_belief_config(self.law), self._beliefs.get(i))
        self._beliefs[i] = (self.logbooks[i], belief)
        return belief

    @property
    def beliefs(self) -> list[PackBelief]:
        """Every aircraft's :meth:`belief`."""
        return [self.belief(i) for i in range(len(self.truth))]

    @property
    def vertiports(self) -> int:
        """How many vertiports the fleet is based at (numbered from 0)."""
        return max(self.base) + 1

    @property
    def aging_law(self) -> AgingLaw:
        """The law the packs age by (and the beliefs with them)."""
        return PACK_LAWS[self.law]

    @classmethod
    def new(cls, n: int, seed: int, age_spread_efc: float | None = None, vertiports: int = 1,
            law: str = "nasa", world: str = DEFAULT_WORLD) -> Fleet:
        """``n`` aircraft whose packs of cell type ``law`` left the factory with q_max ~ U(7300, 7900) C and
        R0 ~ U(0.10, 0.13) ohm and have since delivered U(0, ``age_spread_efc``) equivalent full cycles
        (default :func:`default_age_spread`); each belief starts from the nominal new pack aged by the
        logged throughput. Aircraft ``i`` is based at vertiport ``i % vertiports`` (1-10, at most one per
        aircraft). In the ``"varied"`` world (default) each pack has its own parameter set
        (:func:`~uam_studio.battery.pack_variation.pack_params`, numbered from ``seed``); ``"model"``: its type's."""
        aging = pack_law(law)
        check_world(world)
        n = int(check_range("aircraft", n, 1, 50))
        ports = int(check_range("vertiports", vertiports, 1, min(MAX_VERTIPORTS, n)))
        spread = check_range("age_spread_efc", default_age_spread(law) if age_spread_efc is None else age_spread_efc,
                             0.0, 2000.0)
        rng = np.random.default_rng([check_seed("seed", seed), 42])
        numbers = np.random.default_rng([seed, 44]).integers(0, MAX_SEED, n, endpoint=True)
        truth = []
        for k in range(n):
            q0, r0 = _factory_pack(rng)
            delivered = float(rng.uniform(0.0, spread)) * q0
            truth.append(PackHealth(q0, r0, delivered, law=aging, params=_own_params(world, int(numbers[k]))))
        return cls(truth, base=[i % ports for i in range(n)], law=law, world=world)

    def renew_retired(self, seed: int, night: int = 0) -> list[int]:
        """Replace every retired pack by a new one from the factory (its belief: the nominal new pack),
        drawn with (``seed``, ``night``: the nights since the life began); the aircraft are back in
        service. Returns the aircraft renewed."""
        rng = np.random.default_rng([check_seed("seed", seed), 43, int(check_range("night", night, 0, 10**6))])
        numbers = np.random.default_rng([seed, 45, night]).integers(0, MAX_SEED, len(self.truth), endpoint=True)
        renewed = [i for i, s in enumerate(self.in_service) if not s]
        for i in renewed:
            q0, r0 = _factory_pack(rng)
            self.truth[i] = PackHealth(q0, r0, 0.0, law=self.aging_law, params=_own_params(self.world, int(numbers[i])))
            self.logbooks[i] = _new_logbook(0.0)
            self._beliefs.pop(i, None)
            self.in_service[i] = True
        return renewed


def _new_logbook(delivered_c: float) -> Logbook:
    """An empty logbook of a pack that has delivered ``delivered_c`` (C), read by the fleet's sensors."""
    return Logbook(delivered_before_c=delivered_c, noise_v=NOISE_V, eod_v=EOD_V)
