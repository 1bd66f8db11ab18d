"""Agreement with NASA progpy's BatteryElectroChemEOD (runs when the `reference` extra is installed).

Each load profile is checked on three of the twelve (q_max, R0) grid points, every q_max once, and the
four profiles together cover the whole grid once (``grid_points``). The whole grid under every profile is
a benchmark: ``python benchmarks/bench_progpy_agreement.py``.
"""

import numpy as np
import pytest

from uam_studio.battery import simulate
from uam_studio.flight import leg_current

progpy_models = pytest.importorskip("progpy.models", reason="install the 'reference' extra (progpy)")

Q_GRID = (5000.0, 6500.0, 8000.0)
R_GRID = (0.017, 0.117, 0.25, 0.45)


def progpy_run(current, q_max, r0, dt=1.0):
    """progpy reference: voltage at t = dt, 2 dt, ... and the EOD time (s)."""
    m = progpy_models.BatteryElectroChemEOD(qMobile=q_max, Ro=r0)  # qMobile in the constructor
    n = len(current)

    def load(t, x=None):
        return m.InputContainer({"i": float(current[min(int(t // dt), n - 1)])})

    res = m.simulate_to_threshold(load, dt=dt, save_freq=dt, horizon=n * dt)
    v = np.array([float(z["v"]) for z in res.outputs])[1:]
    reached = bool(m.threshold_met(res.states[-1])["EOD"])
    return v, (float(res.times[-1]) if reached else np.nan)


def flight_like():
    return np.concatenate([
        leg_current(50.0, 1000, 39), np.zeros(120), leg_current(35.0, 2000, -13),
        leg_current(45.0, 500, 26), leg_current(55.56, 3000, 0.0),
    ])


def grid_points(k: int) -> list[tuple[float, float]]:
    """The (q_max C, R0 ohm) grid points checked under profile number ``k`` (0-3): those with
    (q index + R0 index) % 4 == k, three points holding each q_max once."""
    return [(q, r) for i, q in enumerate(Q_GRID) for j, r in enumerate(R_GRID) if (i + j) % 4 == k]


def agreement(cur: np.ndarray, points: list[tuple[float, float]]) -> tuple[float, float]:
    """Worst |voltage difference| (V) and worst |EOD difference| (s) against progpy over ``points``;
    asserts that both models agree on whether EOD is reached."""
    worst_dv, worst_deod = 0.0, 0.0
    qs, rs = np.array(points).T
    batch = simulate(np.broadcast_to(cur, (qs.size, cur.size)), q_max=qs, r0=rs)
    for b, (q, r) in enumerate(points):
        v_ref, eod_ref = progpy_run(cur, q, r)
        valid = batch.valid[b]
        n = min(len(v_ref), int(valid.sum()))
        assert n > 0
        worst_dv = max(worst_dv, float(np.max(np.abs(batch.voltage_v[b, :n] - v_ref[:n]))))
        eod = batch.eod_s[b]
        assert np.isnan(eod) == np.isnan(eod_ref), (q, r, eod, eod_ref)
        if not np.isnan(eod):
            worst_deod = max(worst_deod, abs(eod - eod_ref))
    return worst_dv, worst_deod


PROFILES = {
    "const_0.5A": np.full(20000, 0.5),
    "const_1.5A": np.full(9000, 1.5),
    "const_3A": np.full(5000, 3.0),
    "flight": flight_like(),
}


def test_grid_points_cover_the_grid_once():
    seen = [p for k in range(len(PROFILES)) for p in grid_points(k)]
    assert sorted(seen) == sorted((q, r) for q in Q_GRID for r in R_GRID)
    assert all(sorted(q for q, _ in grid_points(k)) == list(Q_GRID) for k in range(len(PROFILES)))


@pytest.mark.reference
@pytest.mark.parametrize("k, profile", list(enumerate(PROFILES)))
def test_agrees_with_progpy_over_health_grid(k, profile):
    worst_dv, worst_deod = agreement(PROFILES[profile], grid_points(k))
    print(f"{profile}: max|dV| = {worst_dv:.3e} V, max|dEOD| = {worst_deod:.1f} s")
    assert worst_dv <= 1e-3
    assert worst_deod <= 1.0
