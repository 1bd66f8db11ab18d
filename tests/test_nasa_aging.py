"""The NASA aging law and a pack's capacity belief: on a synthetic life with a known law, and on the real
NASA lives (held out of the law's fit) where they sit beside the checkout."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uam_studio.fleet.aging import AGING_LAW, AgingLaw, LifePoints
from uam_studio.fleet.nasa_aging import (
    NASA_AGING_LAW,
    CapacityBelief,
    fit_nasa_law,
    forecast_score,
    nasa_leave_one_cell_out,
    nasa_life_points,
)

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nasa_pcoe"


def _life(name: str, law: AgingLaw, c0: float, n: int, seed: int, noise: float = 0.01) -> LifePoints:
    rng = np.random.default_rng(seed)
    efc = np.arange(n, dtype=float)
    cap = c0 * law.capacity_fraction(efc, 24.0) + rng.normal(0, noise, n)
    return LifePoints(name, efc, cap, np.arange(n), 24.0, efc[::10], 0.2 * (1 + 0.002 * efc[::10]))


def test_the_law_is_recovered_from_synthetic_lives_and_the_belief_band_covers():
    truth = AgingLaw(a=0.02, b=0.5, ea_k=0.0, k_r=0.002)
    lives = [_life(f"S{i}", truth, 1.8 + 0.05 * i, 150, i) for i in range(4)]
    law = fit_nasa_law(lives)
    assert law.capacity_fraction(100.0, 24.0) == pytest.approx(truth.capacity_fraction(100.0, 24.0), abs=0.01)
    assert law.k_r == pytest.approx(0.002, rel=0.05)
    scores = forecast_score(lives)
    assert all(s["rms_ah"] < 0.03 for s in scores), scores
    assert all(0.8 <= s["coverage90"] <= 1.0 for s in scores), scores


def test_a_belief_moves_towards_what_it_measures():
    b = CapacityBelief.start(NASA_AGING_LAW, 1.85, 24.0, 0.02)
    before, lo0, hi0 = (float(x[0]) for x in b.forecast(np.array([60.0])))
    for e in range(1, 60):
        b.observe(float(e), 1.85 * 0.9)  # a cell that holds 90% while the law fades it faster
    after, lo, hi = (float(x[0]) for x in b.forecast(np.array([60.0])))
    assert abs(after - 1.85 * 0.9) < 0.03 < abs(before - 1.85 * 0.9)
    assert lo < after < hi and hi - lo < 0.5 * (hi0 - lo0)


@pytest.mark.skipif(not DATA.is_dir(), reason="the NASA PCoE lives are not beside the checkout")
def test_on_the_2a_lives_the_nasa_law_beats_the_vtc6_law_held_out():
    lives = nasa_life_points(DATA)
    rows = {r["cell"]: r for r in nasa_leave_one_cell_out(lives)}
    for cell in ("B0005", "B0007", "B0018"):
        assert rows[cell]["rms_ah"] < 0.7 * rows[cell]["vtc6_rms_ah"], rows[cell]
    assert AGING_LAW != NASA_AGING_LAW
    scores = forecast_score(lives, cells=["B0005"])
    assert 0.85 <= scores[0]["coverage90"] <= 0.97 and scores[0]["rms_ah"] < 0.06, scores
