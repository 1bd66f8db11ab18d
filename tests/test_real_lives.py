"""Leave one cell out over the real lives (uam_studio.studies.real_lives, issue 38): the conformal margin,
what the identification reads, and a scored life (the real-data tests run where ../shared/data is)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from uam_studio.battery.cmu_data import LIFE_FILES, load_cell_log
from uam_studio.battery.parameters import VTC6
from uam_studio.errors import InputError
from uam_studio.studies.real_lives import conformal_margin, score_life, segments_without

DATA = os.environ.get("UAM_STUDIO_CMU_DATA") or str(Path(__file__).resolve().parents[2] / "shared" / "data" / "cmu_evtol")
real = pytest.mark.skipif(not Path(DATA, "VAH07.csv.mat").is_file(), reason="the CMU eVTOL dataset is not at ../shared/data/cmu_evtol or $UAM_STUDIO_CMU_DATA")


@given(scores=st.lists(st.floats(-1.0, 1.0), max_size=60), level=st.floats(0.5, 0.99))
def test_conformal_margin_is_the_split_conformal_quantile(scores, level):
    m = conformal_margin(scores, level)
    n = len(scores)
    k = int(np.ceil((n + 1) * level))
    if k > n:
        assert m == float("inf")
    else:
        assert m >= 0.0
        assert sum(s <= m for s in scores) >= min(k, n)  # at least the k smallest are held


def test_conformal_margin_covers_exchangeable_scores():
    """Scores drawn i.i.d.: the margin from the first n holds the next one about 90% of the time."""
    rng = np.random.default_rng(0)
    hits = [rng.normal() <= conformal_margin(list(rng.normal(size=40))) for _ in range(2000)]
    assert 0.87 < np.mean(hits) < 0.95


@real
def test_the_identification_never_reads_the_held_out_cell():
    for held in LIFE_FILES:
        names = {s.name.split()[0] for s in segments_without(DATA, held)}
        assert names == {f[:5] for f in LIFE_FILES} - {held[:5]}
    with pytest.raises(InputError, match="^held: "):
        segments_without(DATA, "VAH01_20.csv")


@real
def test_a_life_scored_at_its_landing_times():
    """Every 25th mission of VAH09 on the bundled set (which never read VAH09): each scored sample has an
    interval around a finite median; the calibrated interval covers at least what the health-only one
    does and misses no more breaches."""
    score = score_life(load_cell_log(Path(DATA) / "VAH09.csv.mat"), VTC6, every=25)
    assert score.missions >= 15 and score.samples >= score.missions
    assert all(lo <= med <= hi and np.isfinite(med) for _, lo, med, hi in score.rows)
    assert score.inside >= score.raw_inside and score.missed <= score.raw_missed
    assert score.strict_missed <= score.raw_missed  # the safety bound is never above the health-only low end
    assert np.isinf(score.rows[0][1])  # no earlier prediction: no calibration yet, no safe verdict
