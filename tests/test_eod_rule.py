"""The end-of-discharge rule: one definition of "below the cut-off" (NaN counts as below)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.battery import simulate
from uam_studio.battery.eod import below_eod, first_below


def test_first_below_per_row_with_lengths_and_nan():
    v = np.array([[3.2, 3.1, 2.9, 2.8], [3.3, np.nan, 3.2, 3.1], [3.3, 3.2, 3.1, 2.9]])
    assert first_below(v, 3.0).tolist() == [2, 1, 3]  # a NaN is below: never a safe verdict on no number
    assert first_below(v, 3.0, length=[4, 4, 3]).tolist() == [2, 1, -1]  # samples past a row's length do not count
    assert int(first_below(np.array([3.5, 3.4]), 3.0)) == -1 and int(first_below(np.array([2.0]), 3.0)) == 0
    assert below_eod([3.0, 2.999, np.nan], 3.0).tolist() == [False, True, True]  # at the cut-off is not below


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.floats(2.9, 3.6), st.floats(0.5, 3.0), st.integers(200, 4000))
def test_simulate_marks_the_same_first_sample(eod_v, current_a, n):
    """simulate's EOD (``valid`` turns False, ``eod_s``) is the rule's first sample below."""
    sim = simulate(np.full(n, current_a), eod_v=eod_v)
    k = int(first_below(sim.voltage_v, eod_v))
    if k < 0:
        assert not sim.eod_reached and bool(sim.valid.all())
    else:
        assert sim.eod_reached and int(np.count_nonzero(sim.valid)) == k and sim.eod_s == sim.time_s[k]
