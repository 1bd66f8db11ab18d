"""No method reads a discharge's record after its context: the history method (its first prediction
included), the physics method, the Dynaformer and the one health belief.

The boundary is computed here from the raw record (the samples whose time from the first loaded sample is
at most the context), never from the library's ``known_before``; every sample after it has its voltage and
current replaced. The lives' sample times are jittered off the 10 s grid (as the real rig's are), so a
sample a fraction of a second past the context is there to be read if a method reads it. Each method's
prediction of that discharge must not change in any field.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.nasa_synthetic import synthetic_cell
from uam_studio.battery.parameters import NASA_18650
from uam_studio.battery.real.nasa_belief import belief_life
from uam_studio.battery.real.nasa_data import NasaCell, NasaDischarge
from uam_studio.battery.real.nasa_eval import fit_nasa_model, score_cell
from uam_studio.battery.real.nasa_physics import predict_life
from uam_studio.dynaformer.nasa_discharges import score_dynaformer

CONTEXT_S = 300.0
SCORED = (0, 3, 7)  # discharges whose record after the context is changed (0: a cell's first prediction)


def _jittered(cell: NasaCell, seed: int) -> NasaCell:
    """``cell`` with every sample after each discharge's first loaded one moved later by 0-0.9 s (still in
    order): samples no longer fall on whole 10 s steps, and one lands just past the context."""
    rng = np.random.default_rng(seed)
    out = []
    for d in cell.discharges:
        t = d.time_s.copy()
        after = np.arange(t.size) > d.load_start
        t[after] += rng.uniform(0.0, 0.9, int(after.sum()))
        first_past = d.load_start + int(np.argmax(t[d.load_start:] - t[d.load_start] > CONTEXT_S))
        t[first_past] = t[d.load_start] + CONTEXT_S + 0.3  # a sample 0.3 s past the context
        out.append(replace(d, time_s=t))
    return replace(cell, discharges=tuple(out))


def _boundary(d: NasaDischarge) -> int:
    """How many samples an operator holds at the prediction instant, counted from the raw record."""
    t0 = d.time_s[d.load_start]
    return sum(1 for t in d.time_s if t - t0 <= CONTEXT_S)


def _changed_after_context(cell: NasaCell, k: int) -> NasaCell:
    """``cell`` with discharge ``k``'s voltage and current after its context changed: 80 mV lower and a fifth
    more current (a record the methods can still fit once it has finished, as they may)."""
    d = cell.discharges[k]
    end = _boundary(d)
    n = d.time_s.size - end
    assert n > 10 and d.time_s[end] - d.time_s[d.load_start] < CONTEXT_S + 1.0  # the next sample is just past it
    changed = replace(d, voltage_v=np.r_[d.voltage_v[:end], d.voltage_v[end:] - 0.08],
                      current_a=np.r_[d.current_a[:end], d.current_a[end:] * 1.2])
    return replace(cell, discharges=cell.discharges[:k] + (changed,) + cell.discharges[k + 1:])


@pytest.fixture(scope="module")
def lives(tmp_path_factory) -> list[NasaCell]:
    tmp = tmp_path_factory.mktemp("peek")
    return [_jittered(synthetic_cell(tmp, seed, n=8), seed) for seed in (21, 22, 23)]


def _history(cells: list[NasaCell], cell: NasaCell) -> dict:
    model = fit_nasa_model(cells[1:], CONTEXT_S, 3.0)
    return {r.discharge: (r.median_s, r.low_s, r.high_s, r.bound95_s, r.bound99_s, r.method, r.flag)
            for r in score_cell(cell, model, progpy=False)}


def _physics(cells: list[NasaCell], cell: NasaCell) -> dict:
    return {p.index: (p.median_s, p.q_max, p.r0) for p in predict_life(cell, NASA_18650)}


def _belief(cells: list[NasaCell], cell: NasaCell) -> dict:
    return {p.discharge.index: (p.median_s, p.q_max, p.q_max_sd, p.r0) for p in belief_life(cell, NASA_18650)}


def _dynaformer(cells: list[NasaCell], cell: NasaCell) -> dict:
    return {r["discharge"]: (r["median_s"], r["low_s"], r["high_s"], r["raw_median_s"], r["health_from"])
            for r in score_dynaformer([cell], CONTEXT_S)}


@pytest.mark.parametrize("method", [_history, _physics, _belief, _dynaformer],
                         ids=["history", "physics", "belief", "dynaformer"])
def test_no_method_reads_a_discharge_after_its_context(lives, method):
    cell = lives[0]
    before = method(lives, cell)
    for k in SCORED:
        after = method(lives, _changed_after_context(cell, k))
        assert after[k] == before[k], (method.__name__, k)
