"""The planning environment: Gymnasium API, action masks, rewards per scenario, backends."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from uam_studio.battery import simulate
from uam_studio.errors import InputError
from uam_studio.planning.env import (
    FEATURE_NAMES,
    N_FEATURES,
    OBS_DIM,
    UAMPlanningEnv,
    fallback_health,
    make_env,
    observe_takeoff,
)
from uam_studio.planning.legs import (
    ALTITUDES_M,
    N_ACTIONS,
    N_MAX,
    VERTIPORT_SLOT,
    decode_action,
    encode_action,
)
from uam_studio.planning.missions.check import check_plan
from uam_studio.planning.missions.mission import Battery, Destination, Mission, Vertiport

V = VERTIPORT_SLOT


def hand_mission(scenario="single_charge", q_max=7600.0, r0=0.05) -> Mission:
    """A at 20 km (3 levels), B 4 km from A (no leg A-B), C at 12 km (2 levels), D 3 km out (never)."""
    return Mission(
        "hand",
        Vertiport(0.0, 0.0, 0.0),
        (
            Destination("A", 20.0, 0.0, 3, 0.0),
            Destination("B", 20.0, 4.0, 1, 0.0),
            Destination("C", 0.0, 12.0, 2, 0.0),
            Destination("D", 3.0, 0.0, 2, 0.0),
        ),
        scenario,
        Battery(q_max, r0),
    )


def valid(env) -> set[tuple[int, int]]:
    return {decode_action(a) for a in np.flatnonzero(env.action_masks())}


def test_action_encoding_round_trip():
    assert N_ACTIONS == 36 and len(ALTITUDES_M) == 4
    for a in range(N_ACTIONS):
        assert encode_action(*decode_action(a)) == a
    assert decode_action(35) == (8, 3)
    with pytest.raises(InputError):
        decode_action(36)


@pytest.mark.parametrize("scenario", ["single_flight", "single_charge", "multi_charge"])
def test_gymnasium_env_checker_random_missions(scenario):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(UAMPlanningEnv(scenario=scenario), skip_render_check=True)


def test_env_checker_fixed_mission_and_dynaformer_backend():
    m = hand_mission("multi_charge")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(UAMPlanningEnv(m, randomize_battery=True, randomize_wind=True), skip_render_check=True)
        check_env(UAMPlanningEnv(m, backend="dynaformer", predictor=FakePredictor(m)), skip_render_check=True)


def test_observation_layout_and_mask_in_observation():
    env = UAMPlanningEnv(hand_mission())
    obs, info = env.reset(seed=0)
    assert len(FEATURE_NAMES) == N_FEATURES == 80 and OBS_DIM == 116 and obs.shape == (OBS_DIM,)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    np.testing.assert_array_equal(obs[-N_ACTIONS:] > 0.5, env.action_masks())
    f = dict(zip(FEATURE_NAMES, obs[:N_FEATURES]))
    assert f["slot0_present"] == 1 and f["slot4_present"] == 0
    assert f["slot0_dx"] == pytest.approx(0.2) and f["slot2_dy"] == pytest.approx(0.12)
    assert f["slot0_priority"] == pytest.approx(1.0) and f["scenario_single_charge"] == 1
    assert f["x"] == 0 and f["n_reached"] == 0 and f["charge_used"] == 0
    assert info["reached"] == [] and info["route"] == []


def test_masks_padding_visited_infeasible():
    env = UAMPlanningEnv(hand_mission())
    env.reset(seed=0)
    # at the vertiport: A at 500/1000/2000 m (20 km < 22.8 km for 3000 m), B (20.4 km) likewise,
    # C at 500/1000 m (12 km < 16.1 km), D never (3 km from the vertiport), no padding, no vertiport
    assert valid(env) == {(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1)}
    obs, r, term, trunc, info = env.step(encode_action(0, 0))
    assert not term and info["reached"] == ["A"]
    # at A: A visited, B only 4 km away (no level), C 23.3 km (all 4), D unservable, home at 3 levels
    assert valid(env) == {(2, 0), (2, 1), (2, 2), (2, 3), (V, 0), (V, 1), (V, 2)}
    f = dict(zip(FEATURE_NAMES, obs[:N_FEATURES]))
    assert f["slot0_visited"] == 1 and f["x"] == pytest.approx(0.2) and f["slot0_dist"] == 0
    assert f["vertiport_dx"] == pytest.approx(-0.2) and f["charge_used"] > 0


def test_single_flight_mask_only_first_destination():
    env = UAMPlanningEnv(hand_mission("single_flight"))
    env.reset(seed=0)
    assert valid(env) == {(0, 0), (0, 1), (0, 2)}


def test_rewards_single_charge():
    env = UAMPlanningEnv(hand_mission(), alpha=2.0, beta=0.5, gamma=7.0)
    env.reset(seed=0)
    rewards = []
    for a in [encode_action(0, 0), encode_action(2, 0), encode_action(V, 0)]:
        obs, r, term, trunc, info = env.step(a)
        rewards.append(r)
    assert rewards == [2.0 * 3, 2.0 * 2, -0.5]
    assert term and not trunc and not obs[-N_ACTIONS:].any()
    assert info["reached"] == ["A", "C"] and info["charging_cycles"] == 1 and not info["eod"]
    assert info["route"] == ["A", "C", "vertiport"] and info["altitudes_m"] == [500.0] * 3
    plan = env.episode_plan("test")
    assert plan.reached_priority == 5 and check_plan(env.mission, plan.route, plan.altitudes_m).safe


def test_rewards_multi_charge_recharges_and_ends_when_all_reachable_visited():
    env = UAMPlanningEnv(hand_mission("multi_charge"))
    obs0, _ = env.reset(seed=0)
    steps = [(0, 0), (V, 0), (1, 0), (V, 0), (2, 0), (V, 0)]  # D is never reachable
    out = [env.step(encode_action(*s)) for s in steps]
    assert [o[1] for o in out] == [3.0, -1.0, 1.0, -1.0, 2.0, -1.0]
    assert [o[2] for o in out] == [False] * 5 + [True]
    info = out[-1][4]
    assert info["charging_cycles"] == 3 and sorted(info["reached"]) == ["A", "B", "C"]
    # a landing recharges: the voltage feature is back to its value at the start
    i_v = FEATURE_NAMES.index("voltage")
    assert out[1][0][i_v] == pytest.approx(obs0[i_v]) and out[1][0][FEATURE_NAMES.index("charge_used")] == 0


def test_single_flight_reward_and_end():
    env = UAMPlanningEnv(hand_mission("single_flight"), alpha=1.5)
    env.reset(seed=0)
    obs, r, term, trunc, info = env.step(encode_action(0, 1))
    assert (r, term, info["reached"]) == (4.5, True, ["A"])


def test_eod_penalty_terminates():
    far = Mission("far", Vertiport(0.0, 0.0, 39.0),
                  (Destination("F", 150.0, 0.0, 3, 39.0), Destination("G", 0.0, 150.0, 1, 39.0)),
                  "single_charge", Battery(5000.0, 0.3))
    env = UAMPlanningEnv(far, gamma=6.0)
    env.reset(seed=0)
    obs, r, term, trunc, info = env.step(encode_action(0, 0))
    assert (r, term, info["eod"], info["reached"]) == (-6.0, True, True, [])
    assert info["leg_min_voltage_v"] < 3.0
    assert not check_plan(far, info["route"], info["altitudes_m"]).safe


def test_safe_return_ends_a_stranding_leg_before_it_is_flown():
    """F at 60 km: the cell flies there (paper setting: +3) but could not fly back."""
    def strand(safe_return):
        m = Mission("strand", Vertiport(0.0, 0.0, 0.0), (Destination("F", 60.0, 0.0, 3, 0.0),
                                                          Destination("N", 20.0, 0.0, 1, 0.0)),
                    "single_charge", Battery(5000.0, 0.25))
        env = UAMPlanningEnv(m, gamma=7.0, safe_return=safe_return)
        env.reset(seed=0)
        return env, env.step(encode_action(0, 0))

    env, (_, r, term, _, info) = strand(False)
    assert (r, term, info["eod"], info["stranded"], info["reached"]) == (3.0, False, False, False, ["F"])
    env, (_, r, term, _, info) = strand(True)
    assert (r, term, info["eod"], info["stranded"], info["reached"], info["route"]) == (
        -7.0, True, False, True, [], [])
    env, _ = strand(True)  # a leg with a way home is flown as usual, from the same cell state
    env.reset(seed=0)
    _, r, term, _, info = env.step(encode_action(1, 0))
    assert (r, term, info["stranded"], info["reached"]) == (1.0, False, False, ["N"])
    _, r, term, _, info = env.step(encode_action(VERTIPORT_SLOT, 0))
    assert (r, term, info["eod"]) == (-1.0, True, False)
    plain = UAMPlanningEnv(env.mission)
    plain.reset(seed=0)
    plain.step(encode_action(1, 0))
    _, _, _, _, ref = plain.step(encode_action(VERTIPORT_SLOT, 0))
    assert ref["leg_min_voltage_v"] == info["leg_min_voltage_v"]


def test_invalid_action_is_penalised_not_raised():
    env = UAMPlanningEnv(hand_mission())
    env.reset(seed=0)
    obs, r, term, trunc, info = env.step(encode_action(3, 0))  # D: unreachable
    assert (r, term, info["invalid_action"]) == (-5.0, True, True)


def test_truncation():
    env = UAMPlanningEnv(hand_mission("multi_charge"), max_steps=3)
    env.reset(seed=0)
    for s in [(0, 0), (V, 0)]:
        assert not env.step(encode_action(*s))[3]
    obs, r, term, trunc, info = env.step(encode_action(1, 0))
    assert trunc and not term and obs[-N_ACTIONS:].any()  # mask kept for bootstrapping


def test_random_episodes_always_have_a_valid_action():
    env = UAMPlanningEnv(scenario="multi_charge")
    rng = np.random.default_rng(1)
    env.reset(seed=1)
    episodes = 0
    for _ in range(300):
        mask = env.action_masks()
        assert mask.any()
        obs, r, term, trunc, info = env.step(int(rng.choice(np.flatnonzero(mask))))
        assert np.all(np.isfinite(obs)) and env.observation_space.contains(obs)
        if term or trunc:
            episodes += 1
            env.reset()
    assert episodes > 20


class FakePredictor:
    """A 'Dynaformer' that is the physics model of the mission's cell (for backend tests)."""

    def __init__(self, mission: Mission) -> None:
        self.q, self.r0 = mission.battery.q_max, mission.battery.r0
        self.health_calls = []

    def predict(self, context_current_a, context_voltage_v, current_a, dt_s=1.0):
        return simulate(np.asarray(current_a), dt_s, self.q, self.r0, eod_v=2.5).voltage_v

    def health(self, context_current_a, context_voltage_v):
        self.health_calls.append((np.array(context_current_a), np.array(context_voltage_v)))
        return np.array([0.25, -0.5])


@pytest.mark.parametrize("scenario, q_max, r0, ends_in_eod",
                         [("multi_charge", 7000.0, 0.05, False), ("single_charge", 5200.0, 0.3, True)])
def test_physics_and_fake_dynaformer_backends_agree(scenario, q_max, r0, ends_in_eod):
    m = hand_mission(scenario, q_max=q_max, r0=r0)
    fake = FakePredictor(m)
    envs = [UAMPlanningEnv(m), UAMPlanningEnv(m, backend="dynaformer", predictor=fake)]
    obs = [e.reset(seed=3)[0] for e in envs]
    for s in [(0, 2), (2, 3), (V, 1), (1, 0), (V, 0)]:
        outs = [e.step(encode_action(*s)) for e in envs]
        (o1, r1, t1, _, i1), (o2, r2, t2, _, i2) = outs
        assert not i1["invalid_action"]
        assert (r1, t1, i1["eod"], i1["reached"]) == (r2, t2, i2["eod"], i2["reached"])
        np.testing.assert_allclose(o1[2:], o2[2:], atol=1e-5)  # all but the health features
        assert i1["leg_min_voltage_v"] == pytest.approx(i2["leg_min_voltage_v"], abs=1e-6)
        if t1:
            break
    assert t1 and i1["eod"] == ends_in_eod
    if not ends_in_eod:
        assert i1["charging_cycles"] == 2 and sorted(i1["reached"]) == ["A", "B", "C"]
    assert len(fake.health_calls) == 1  # once per episode, on the 20 s take-off observation
    ci, cv = fake.health_calls[0]
    assert ci.shape == cv.shape == (20,) and ci.min() > 2.5
    np.testing.assert_allclose(obs[1][:2], [0.25, -0.5])


def test_fallback_health_tracks_r0_and_q_max_from_the_observation():
    h = {(q, r): fallback_health(*observe_takeoff(q, r)) for q in (5000.0, 8000.0) for r in (0.02, 0.3)}
    assert h[5000.0, 0.3][0] > h[5000.0, 0.02][0] + 1 and h[8000.0, 0.3][0] > h[8000.0, 0.02][0] + 1
    assert h[5000.0, 0.3][1] > h[8000.0, 0.3][1] and h[5000.0, 0.02][1] > h[8000.0, 0.02][1]
    assert all(np.all(np.abs(v) < 5) for v in h.values())


def test_bad_arguments_and_missions():
    with pytest.raises(InputError, match="empty"):
        UAMPlanningEnv(Mission("e", Vertiport(0, 0)))
    many = tuple(Destination(f"P{k}", 10.0 + 10 * k, 0.0, 1) for k in range(N_MAX + 1))
    with pytest.raises(InputError, match="slots"):
        UAMPlanningEnv(Mission("m", Vertiport(0, 0), many))
    with pytest.raises(InputError, match="too close"):
        UAMPlanningEnv(Mission("c", Vertiport(0, 0), (Destination("X", 2.0, 0.0, 1),)))
    with pytest.raises(InputError, match="predictor"):
        UAMPlanningEnv(backend="dynaformer")
    with pytest.raises(InputError, match="scenario"):
        UAMPlanningEnv(scenario="tour")
    with pytest.raises(InputError, match="n_dest"):
        UAMPlanningEnv(n_dest=(0, 9))
    with pytest.raises(InputError, match=r"n_dest: \(1, 9\) is out of range; allowed 1 <= lo <= hi <= 8"):
        UAMPlanningEnv(n_dest=(1, 9))  # missions may have 20 destinations; the environment has 8 slots


def test_make_env_factory_and_reset_options():
    factory = make_env(scenario="multi_charge", n_dest=3)
    e1, e2 = factory(), factory()
    assert e1 is not e2 and e1.scenario == "multi_charge"
    o1, _ = e1.reset(seed=5)
    o2, _ = e2.reset(seed=5)
    np.testing.assert_array_equal(o1, o2)
    assert len(e1.mission.destinations) == 3
    m = hand_mission()
    e1.reset(options={"mission": m})
    assert e1.mission is m


@pytest.mark.parametrize("q_max, r0", [(5000.0, 0.017), (8000.0, 0.45), (4000.0, 0.6), (9000.0, 0.9)])
def test_takeoff_observation_equals_simulate(q_max, r0):
    """The env's take-off observation (the first 20 s of the planners' one take-off run, legs.fly_takeoff) is
    simulate()'s on those 20 s, to rounding (the run is vectorised over the whole take-off), including cells that end
    below 2.5 V."""
    from uam_studio.battery.simulate import EOD_RANGE

    ci, cv = observe_takeoff(q_max, r0)
    ref = simulate(ci, 1.0, q_max, r0, eod_v=EOD_RANGE[0]).voltage_v
    assert cv.shape == ref.shape
    np.testing.assert_allclose(cv, ref, rtol=0.0, atol=1e-9)
