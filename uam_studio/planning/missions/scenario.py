"""The paper's three scenarios as rules, in one place: how far an episode goes and what the vertiport does.

- ``single_flight``: one leg out to one destination; no way back is planned (``one_leg``).
- ``single_charge``: one sortie from the vertiport and back on one charge (``one_sortie``).
- ``multi_charge``: sorties until every reachable destination is served; arriving at the vertiport
  recharges the cell (``recharges``).

Planners, the environment and the operator ask these rules instead of comparing scenario names.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from uam_studio.errors import InputError, short_repr

SCENARIOS = ("single_flight", "single_charge", "multi_charge")
DEFAULT_SCENARIO = "single_charge"


@dataclass(frozen=True)
class Scenario:
    """One scenario's rules (see the module docstring)."""

    name: str
    one_leg: bool  # the episode is one leg to one destination, with no way back planned
    recharges: bool  # arriving at the vertiport recharges the cell and the episode goes on

    @property
    def one_sortie(self) -> bool:
        """One trip from the vertiport and back on one charge (``single_charge``)."""
        return not (self.one_leg or self.recharges)


RULES = {
    "single_flight": Scenario("single_flight", one_leg=True, recharges=False),
    "single_charge": Scenario("single_charge", one_leg=False, recharges=False),
    "multi_charge": Scenario("multi_charge", one_leg=False, recharges=True),
}


def check_scenario(name: Any, field: str = "scenario") -> str:
    """``name`` if it names a scenario.

    :raises InputError: (``field``) ``<value> is not a scenario; allowed: single_flight, ...``.
    """
    if not isinstance(name, str) or name not in RULES:
        raise InputError(field, f"{short_repr(name)} is not a scenario; allowed: {', '.join(SCENARIOS)}")
    return name


def scenario_rules(name: Any) -> Scenario:
    """The rules of the scenario ``name`` (:func:`check_scenario`'s error for another value)."""
    return RULES[check_scenario(name)]
