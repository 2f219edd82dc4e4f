"""Where missed waypoints go (`selfplaydrive.eval.misses`, `VecEnv.record_agents`): hand-made
outcomes, the end state read from buffers, and a real rollout whose breakdown agrees with the
simulator's own counters."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.builder import make_env
from selfplaydrive.eval.misses import OUTCOMES, MissBreakdown, breakdown_of, classify, completion_breakdown
from selfplaydrive.policies import make_policy
from selfplaydrive.sim.agent_outcomes import agent_outcomes


def test_classify_first_match_wins():
    # done beats a contact; vehicle beats pedestrian beats road edge; then behind / ahead
    ever = np.array([1, 1 | 2 | 4, 2 | 4, 4, 8, 0, 0])
    reached = np.array([8, 2, 2, 2, 2, 2, 2])
    assigned = np.array([8, 8, 8, 8, 8, 8, 8])
    ahead = np.array([np.nan, 5.0, 5.0, 5.0, -0.1, 3.0, -40.0])
    names = [OUTCOMES[k] for k in classify(ever, reached, assigned, ahead)]
    assert names == [
        "all_reached",
        "vehicle_collision",
        "pedestrian",
        "road_edge",
        "off_route",  # a red-light bit is no contact
        "pending_ahead",
        "off_route",
    ]


def _buffers(A: int = 2, K: int = 3) -> dict[str, np.ndarray]:
    N = 2 * A
    return {
        "agent_valid": np.zeros(N, np.uint8),
        "wp_idx": np.zeros(N, np.int32),
        "num_wp": np.zeros(N, np.int32),
        "waypoints": np.zeros(N * K * 2, np.float32),
        "x": np.zeros(N, np.float32),
        "y": np.zeros(N, np.float32),
        "heading": np.zeros(N, np.float32),
        "ever": np.zeros(N, np.uint8),
    }


def test_agent_outcomes_hand_computed():
    b = _buffers()
    wp = b["waypoints"].reshape(4, 3, 2)
    # world 1 (slots 2, 3): slot 2 heads north at (10, 0) with its 2nd waypoint at (10, 25):
    # 25 m ahead; slot 3 heads east at (0, 0), 3rd waypoint at (-5, 12): 5 m behind, 13 m away
    b["agent_valid"][2:4] = 1
    b["x"][2], b["heading"][2] = 10.0, np.pi / 2
    b["wp_idx"][2:4] = [1, 2]
    b["num_wp"][2:4] = [3, 3]
    wp[2, 1] = (10.0, 25.0)
    wp[3, 2] = (-5.0, 12.0)
    b["ever"][3] = 4
    out = agent_outcomes(b, world=1, agents_per_world=2)
    np.testing.assert_allclose(out["ahead_m"], [25.0, -5.0], atol=1e-5)
    np.testing.assert_allclose(out["away_m"], [25.0, 13.0], atol=1e-5)
    assert out["reached"].tolist() == [1, 2] and out["assigned"].tolist() == [3, 3]
    assert out["ever"].tolist() == [0, 4]
    # world 0 has no valid agent; a finished route has no pending waypoint
    assert agent_outcomes(b, world=0, agents_per_world=2)["reached"].size == 0
    b["wp_idx"][2] = 3
    assert np.isnan(agent_outcomes(b, world=1, agents_per_world=2)["ahead_m"][0])


def test_breakdown_shares_add_up_to_the_missed_waypoints():
    t = MissBreakdown()
    t.add({"ever": [0, 1, 0], "reached": [4, 1, 2], "assigned": [4, 4, 4], "ahead_m": [np.nan, 3.0, -8.0]})
    assert t.completion == pytest.approx(7 / 12)
    assert t.agents["vehicle_collision"] == 1 and t.agents["off_route"] == 1
    missed = sum(t.missed_share(n) for n in OUTCOMES)
    assert missed == pytest.approx(1 - t.completion)
    assert "| off_route | 1 (33.3%) | 2 / 4 | 16.7% |" in t.markdown()
    with pytest.raises(ValueError, match="record_agents"):
        breakdown_of([{"world": 0}])


def test_rule_based_rollout_agrees_with_the_simulators_counters():
    env = make_env("default", num_worlds=2, seed=3)
    policy = make_policy("rule_based", env)
    env.record_agents = True
    env.reset(seed=3)
    assigned = np.asarray(env.state.num_wp).reshape(2, -1)[
        np.asarray(env.state.agent_valid).reshape(2, -1) > 0
    ]
    records = []
    for _ in range(3000):
        env.step(policy(env.observations, env))
        records += env.pop_episode_stats()
        if len(records) >= 2:
            break
    assert len(records) >= 2
    rec = records[0]
    agents = rec["agents"]
    assert len(agents["reached"]) == rec["num_agents"]
    # every reached waypoint is one waypoint event of the world; contacts match the ever-counts
    assert int(np.sum(agents["reached"])) == rec["events"]["waypoint"]
    assert int(np.count_nonzero(np.asarray(agents["ever"]) & 1)) == rec["agents_with"]["collision"]
    assert int(np.count_nonzero(np.asarray(agents["ever"]) & 4)) == rec["agents_with"]["offroad"]
    first = next(r for r in records if r["world"] == 0)
    assert int(np.sum(first["agents"]["assigned"])) == int(assigned[: first["num_agents"]].sum())
    # the wrapper drives the same way and restores the flag
    env.record_agents = False
    table = completion_breakdown(env, policy, world_episodes=2, seed=3)
    assert env.record_agents is False
    assert table.episodes == 2 and 0.0 < table.completion < 1.0
    assert sum(table.agents.values()) == sum(r["num_agents"] for r in records[:2])
