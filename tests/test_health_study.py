"""Dynaformer study helpers, with stand-in predictors (no weights needed) and the bundled model."""

from __future__ import annotations

import numpy as np
import pytest

from uam_studio.battery import simulate
from uam_studio.dynaformer.data import make_dataset
from uam_studio.dynaformer.health_study import (
    accuracy_table,
    compare_with_physics,
    health_grid,
    takeoff_context_current,
)
from uam_studio.errors import InputError
from uam_studio.flight import leg_profile


class PhysicsOracle:
    """A 'predictor' that knows the cell: it returns the physics voltage (cut at 2.5 V)."""

    def __init__(self, q_max: float, r0: float) -> None:
        self.q_max, self.r0 = q_max, r0

    def predict(self, ci, cv, current_a, dt_s=1.0):
        return simulate(np.asarray(current_a), dt_s, self.q_max, self.r0, eod_v=2.5).voltage_v

    def health(self, ci, cv):
        cv = np.atleast_2d(cv)
        return np.column_stack([cv[:, 0] - cv[:, -1], cv[:, -1]])


def test_compare_with_physics_perfect_predictor():
    cur = np.concatenate([leg_profile(50.0, 1000.0, 13.0).current_a] * 4)
    c = compare_with_physics(PhysicsOracle(6000.0, 0.15), cur, 6000.0, 0.15)
    np.testing.assert_allclose(c.predicted_v, c.physics_v)
    assert c.eod_true_s is not None and c.eod_pred_s == c.eod_true_s and c.rte == 0.0
    assert c.time_s.size == cur.size and c.context_s == 20


def test_compare_with_physics_wrong_cell_and_bad_input():
    cur = np.concatenate([leg_profile(50.0, 1000.0, 13.0).current_a] * 4)
    c = compare_with_physics(PhysicsOracle(8000.0, 0.05), cur, 5000.0, 0.15)
    assert c.eod_pred_s > c.eod_true_s and c.rte > 0.1
    with pytest.raises(InputError):
        compare_with_physics(PhysicsOracle(8000.0, 0.05), cur, 5000.0, 0.15, context_s=0)


def test_health_grid_shapes_and_drop():
    g = health_grid(PhysicsOracle(7600.0, 0.1), [5000.0, 6000.0, 8000.0], [0.05, 0.3])
    assert g["pc1"].shape == g["pc2"].shape == g["voltage_drop_v"].shape == (2, 3)
    np.testing.assert_allclose(g["pc1"], g["voltage_drop_v"])
    assert (g["voltage_drop_v"][1] > g["voltage_drop_v"][0]).all()  # larger R0, larger drop
    assert takeoff_context_current(20).size == 20
    with pytest.raises(InputError):
        health_grid(PhysicsOracle(7600.0, 0.1), [], [0.1])


@pytest.mark.slow
def test_accuracy_table_bundled_model():
    from uam_studio.dynaformer import load_pretrained

    ds = make_dataset(12, seed=777, flight_fraction=1.0)
    rows = accuracy_table(load_pretrained(), ds, contexts_s=(20, 60), noises_mv=(0.0,))
    assert [(r["context_s"], r["noise_mv"]) for r in rows] == [(20, 0.0), (60, 0.0)]
    for r in rows:
        assert 0.0 <= r["abs_r_r0"] <= 1.0 and r["rmse_mv"] > 0.0
