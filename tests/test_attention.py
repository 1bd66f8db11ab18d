"""The attention planner: features, network, beam search behind the physics filter, weights files, training."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch

from uam_studio.errors import InputError
from uam_studio.planning.agents.attention.decode import (
    FORMAT,
    attention_plan,
    bundled_weights_path,
    load_policy,
)
from uam_studio.planning.agents.attention.features import mission_tokens, step_features
from uam_studio.planning.agents.attention.model import AttentionConfig, AttentionPolicy
from uam_studio.planning.agents.attention.train import AttentionTrainConfig, oracle_examples, train_attention
from uam_studio.planning.legs import ALTITUDES_M, N_MAX, LegTable
from uam_studio.planning.missions.check import check_plan
from uam_studio.planning.missions.generate import random_mission
from uam_studio.planning.missions.mission import VERTIPORT, Mission


def _mission(n: int, seed: int, scenario: str = "single_charge") -> Mission:
    return random_mission(np.random.default_rng(seed), (n, n), scenario, radius_km=(8.0, 45.0))


@pytest.fixture(scope="module")
def net() -> AttentionPolicy:
    if bundled_weights_path().is_file():
        return load_policy()[0]
    torch.manual_seed(0)
    return AttentionPolicy().eval()


def test_network_is_permutation_invariant():
    """Permuting the destinations permutes the logits and nothing else (no positional encoding)."""
    m = _mission(7, 1)
    legs = LegTable(m)
    tok = mission_tokens(legs, "single_charge")
    torch.manual_seed(0)
    net = AttentionPolicy().eval()
    perm = np.array([3, 0, 6, 1, 5, 2, 4])
    m2 = Mission(m.name, m.vertiport, tuple(m.destinations[k] for k in perm), m.scenario, m.battery, m.eod_v)
    tok2 = mission_tokens(LegTable(m2), "single_charge")
    visited = np.zeros(7, dtype=bool)
    visited[3] = True
    used = 1234.0

    def logits(t, at, vis):
        ctx, cand, mask = step_features(t, at, vis, used, 0)
        h, g = net.encode(torch.from_numpy(t.features)[None])
        with torch.no_grad():
            return net.decide(h, g, torch.tensor([at]), torch.from_numpy(ctx)[None], torch.from_numpy(cand)[None],
                              torch.from_numpy(mask)[None])[0].numpy()

    a = logits(tok, 5, visited)
    inv = np.argsort(perm)  # destination k of m is destination inv[k] of m2
    b = logits(tok2, int(inv[5]), visited[perm])
    np.testing.assert_allclose(a[:7], b[inv], rtol=1e-4, atol=1e-4)
    assert a[7] == pytest.approx(b[7], abs=1e-4)
    assert a[3] == -np.inf and b[inv[3]] == -np.inf  # visited: masked


@pytest.mark.parametrize("n,scenario", [(5, "single_charge"), (12, "single_charge"), (20, "single_charge"),
                                        (12, "multi_charge"), (20, "multi_charge")])
def test_filtered_plans_are_safe_on_physics(net, n, scenario):
    for seed in (11, 12):
        m = _mission(n, seed, scenario)
        plan = attention_plan(m, net, beam_width=3)
        check = check_plan(m, plan.route, plan.altitudes_m)
        assert check.safe, (plan.route, check.message)
        dests = [r for r in plan.route if r != VERTIPORT]
        assert len(dests) == len(set(dests))
        assert set(plan.altitudes_m) <= set(ALTITUDES_M)
        if plan.route:
            assert plan.route[-1] == VERTIPORT
        if scenario == "single_charge":
            assert plan.route.count(VERTIPORT) <= 1
        assert plan.stats["legs_flown"] > 0


def test_raw_agent_flies_nothing_while_planning(net):
    m = _mission(8, 3)
    plan = attention_plan(m, net, beam_width=1, safety_filter=False)
    assert plan.stats["legs_flown"] == 0
    assert plan.stats["safety_filter"] is False
    if plan.route:
        assert plan.route[-1] == VERTIPORT


def test_single_flight_takes_the_safest_level(net):
    m = _mission(1, 4, "single_flight")
    plan = attention_plan(m, net)
    levels = [a for a in ALTITUDES_M if check_plan(m, [m.destinations[0].name], [a]).safe]
    if not levels:
        assert plan.route == ()
        return
    best = max(levels, key=lambda a: check_plan(m, [m.destinations[0].name], [a]).min_voltage_v)
    assert plan.altitudes_m == (best,)


@pytest.mark.parametrize("width", [0, 65, 2.5, True, "3"])
def test_bad_beam_width(net, width):
    with pytest.raises(InputError, match="beam_width"):
        attention_plan(_mission(3, 5), net, beam_width=width)


class _Boom:
    def __reduce__(self):
        return (print, ("payload ran",))


def test_weights_file_never_runs_code(tmp_path, capsys):
    bad = tmp_path / "evil.pt"
    with open(bad, "wb") as f:
        pickle.dump({"format": FORMAT, "config": {}, "state_dict": _Boom()}, f)
    with pytest.raises(InputError, match="agent"):
        load_policy(bad)
    assert "payload ran" not in capsys.readouterr().out
    other = tmp_path / "other.pt"
    torch.save({"format": "something else"}, other)
    with pytest.raises(InputError, match="not an attention planner file"):
        load_policy(other)
    with pytest.raises(InputError, match="no such file"):
        load_policy(tmp_path / "missing.pt")


def test_oracle_examples_are_the_oracles_plans():
    from uam_studio.planning.solvers.oracle import oracle_plan

    m = _mission(5, 6)
    ex = oracle_examples(m)
    names = [d.name for d in m.destinations]
    single = oracle_plan(m, "single_charge")
    assert [names[k] for s in ex["single_charge"] for k in s] == [r for r in single.route if r != VERTIPORT]
    multi = oracle_plan(m, "multi_charge")
    assert len(ex["multi_charge"]) == multi.route.count(VERTIPORT)
    assert sorted(k for s in ex["multi_charge"] for k in s) == sorted(
        names.index(r) for r in multi.route if r != VERTIPORT)


def test_training_writes_a_loadable_planner_and_never_the_bundled_one(tmp_path):
    cfg = AttentionTrainConfig(oracle_missions=6, oracle_dest=(2, 4), search_missions=1, search_dest=(9, 10),
                               search_beam=2, epochs=1, search_epochs=1, workers=1,
                               network=AttentionConfig(d_model=16, heads=2, layers=1, ff=16))
    path = train_attention(cfg, tmp_path / "run", log=lambda s: None)
    net, card = load_policy(path)
    assert card["config"]["oracle_missions"] == 6
    assert card["stats"]["oracle_decisions"] > 0 and card["stats"]["search_decisions"] > 0
    plan = attention_plan(_mission(4, 7), net, beam_width=2)
    assert check_plan(_mission(4, 7), plan.route, plan.altitudes_m).safe
    with pytest.raises(InputError, match="bundled"):
        train_attention(cfg, bundled_weights_path().parent, log=lambda s: None)


def test_features_of_a_twenty_destination_mission():
    m = _mission(20, 8, "multi_charge")
    legs = LegTable(m, 20)
    tok = mission_tokens(legs, "multi_charge")
    assert tok.features.shape == (21, 13) and np.isfinite(tok.features).all()
    ctx, cand, mask = step_features(tok, 20, np.zeros(20, dtype=bool), 0.0, 0)
    assert mask[20] and np.isfinite(cand).all() and np.isfinite(ctx).all()
    assert LegTable(_mission(3, 9)).slots == N_MAX


# --------------------------------------------------------------------------- plan_mission's default


def test_plan_mission_defaults_to_the_attention_planner_on_twenty_destinations():
    from uam_studio.planning import MAX_DESTINATIONS, plan_mission

    for scenario in ("single_charge", "multi_charge"):
        m = _mission(MAX_DESTINATIONS, 21, scenario)
        res = plan_mission(m, predictor=False)
        assert res["policy"] == "attention" and res["exact"] is None
        assert res["safe"] and res["route"] and res["route"][-1] == VERTIPORT
        assert res["reached_priority"] == sum(d.priority for d in m.destinations if d.name in res["reached"])
        check = check_plan(m, res["route"], res["altitudes_m"])
        assert check.safe and res["charging_cycles"] == check.sim.charging_cycles


def test_plan_mission_attention_takes_a_weights_file_and_refuses_foreign_options(tmp_path):
    from uam_studio.planning import plan_mission

    m = _mission(5, 22)
    cfg = AttentionTrainConfig(oracle_missions=4, oracle_dest=(2, 3), search_missions=0, epochs=1, workers=1,
                               network=AttentionConfig(d_model=16, heads=2, layers=1, ff=16))
    path = train_attention(cfg, tmp_path / "run", log=lambda s: None)
    res = plan_mission(m, "attention", agent_path=path, predictor=False)
    assert res["policy"] == "attention" and res["safe"]
    with pytest.raises(InputError, match="agent"):
        plan_mission(m, "attention", agent_path=tmp_path / "missing.pt", predictor=False)
    with pytest.raises(InputError, match="agent_path"):
        plan_mission(m, "greedy", agent_path=path, predictor=False)
    with pytest.raises(InputError, match="lookahead"):
        plan_mission(m, "attention", lookahead=2, predictor=False)
