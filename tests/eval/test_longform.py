"""Long-form self-play evaluation (km between incidents) and the shared report writer."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from selfplaydrive.builder import make_env
from selfplaydrive.eval.longform import (
    RuleBasedPolicy,
    WaypointRefresher,
    _OnsetCounter,
    run_longform,
)
from selfplaydrive.eval.report import markdown_table, table_rows, write_report
from selfplaydrive.eval.stats import km_between_incidents, proportion
from selfplaydrive.scenario.conditioning import ConditioningSampler


def _capturing_factory(holder: list):
    def factory(spawner, num_worlds, seed, **kw):
        env = make_env("default", spawner=spawner, num_worlds=num_worlds, seed=seed, **kw)
        holder.append(env)
        return env

    return factory


def _fake_env(events: np.ndarray, acted: np.ndarray, A: int) -> SimpleNamespace:
    return SimpleNamespace(
        num_agents=len(events),
        num_worlds=len(events) // A,
        agents_per_world=A,
        reward_mask=acted,
        state=SimpleNamespace(events=events),
    )


def test_onsets_are_rising_edges_of_agents_that_acted():
    env = _fake_env(np.zeros(4, np.uint8), np.ones(4, bool), A=2)
    c = _OnsetCounter(env)
    # agent 0 vehicle contact over 5 steps: 0 1 1 0 1 -> 2 onsets, 3 agent-steps
    # agent 3 road edge each step but acted only in steps 0, 1, 3 -> onsets at 0 and 3
    seq0 = [0, 1, 1, 0, 1]
    acted3 = [1, 1, 0, 1, 1]
    for t in range(5):
        env.state.events = np.array([seq0[t], 0, 0, 4], np.uint8)
        env.reward_mask = np.array([1, 1, 1, acted3[t]], bool)
        c.after_step()
    assert c.onsets["vehicle_collisions"] == 2 and c.agent_steps["vehicle_collisions"] == 3
    assert c.onsets["road_edge"] == 2 and c.agent_steps["road_edge"] == 4
    assert c.acted_steps == 19
    # world 1's episode statistics say 6 road-edge agent-steps: 2 were wiped by the autoreset
    c.episode_ended(
        {"world": 1, "events": {"collision": 0, "pedestrian_collision": 0, "offroad": 6, "red_light": 0}}
    )
    assert c.onsets["road_edge"] == 4 and c.agent_steps["road_edge"] == 6
    assert not c.prev["road_edge"][2:].any()


def test_longform_rule_based_60s_matches_simulator_statistics():
    envs: list = []
    res = run_longform(_capturing_factory(envs), RuleBasedPolicy(), duration_s=60.0, num_worlds=2, seed=0)
    env = envs[0]
    assert res.steps == 600 and res.dt == pytest.approx(0.1)
    # every agent drives with the paper's fixed evaluation coefficients (section 5)
    want = ConditioningSampler(mode="eval").eval_vector()
    valid = env.state.agent_valid.astype(bool)
    np.testing.assert_allclose(env.state.coeffs[valid], np.tile(want, (valid.sum(), 1)))
    assert res.coefficients["collision"] == 1.0 and res.coefficients["center_bias"] == 0.0
    assert res.coefficients["waypoint_radius"] == 3.0
    # no world ended early here: our agent-step counts equal the kernels' own counters
    if res.world_episodes == 0:
        counts = env.state.ev_count.sum(axis=0)
        assert res.agent_steps["vehicle_collisions"] == counts[0]
        assert res.agent_steps["pedestrian_collisions"] == counts[1]
        assert res.agent_steps["road_edge"] == counts[2]
        assert res.agent_steps["red_light"] == counts[3]
        assert res.km == pytest.approx(env.state.dist.sum() / 1000.0)
    for t, k in res.onsets.items():
        assert 0 <= k <= res.agent_steps[t]
    assert res.km > 5.0  # 64 agents x 60 s of driving
    assert 0.5 < res.agent_hours <= 64 * 60 / 3600 + 1e-9
    assert res.waypoint_refreshes > 0
    d = res.to_dict()
    exp = km_between_incidents(res.incidents, res.km).to_dict()
    assert d["km_between_incidents"] == exp
    json.dumps(d, allow_nan=False)  # strict JSON
    print("longform 60 s x 2 worlds:", {k: d[k] for k in ("km", "incidents", "onsets", "mean_speed_kmh")})


def test_waypoint_refresher_writes_a_route_ahead():
    from selfplaydrive.scenario.spawner import PaperSpawner

    env = make_env("default", spawner=PaperSpawner(num_agents=8), num_worlds=1, seed=3)
    env.reset(seed=3)
    env.step(RuleBasedPolicy()(env.observations, env))
    ref = WaypointRefresher(env, np.random.default_rng(0))
    assert len(ref.due()) == 0
    rows = np.flatnonzero(env.masks)[:3]
    env.buffers["wp_idx"][rows] = env.buffers["num_wp"][rows]  # routes used up
    assert set(ref.due()) == set(rows)
    assert ref.refresh() + ref.unplaced == len(rows)
    st = env.state
    done = rows[st.wp_idx[rows] == 0]
    assert len(done) == ref.refreshed >= 1
    for i in done:
        n = st.num_wp[i]
        assert 1 <= n <= st.waypoints.shape[1]
        first = st.waypoints[i, 0] - np.array([st.x[i], st.y[i]])
        heading = np.array([np.cos(st.heading[i]), np.sin(st.heading[i])])
        assert first @ heading > 0.0  # the new route starts ahead of the agent
        # waypoints lie on lane centrelines (the localiser's samples are every 2 m)
        d, _ = ref.lanes.tree.query(np.add(st.waypoints[i, :n], [env.state.map_id[0] * 1e6, 0]))
        assert np.all(d < 1.5)
    assert len(ref.due()) == 0


def test_longform_rejects_bad_arguments():
    with pytest.raises(ValueError, match="duration_s"):
        run_longform("default", RuleBasedPolicy(), duration_s=0.0, num_worlds=1)
    with pytest.raises(ValueError, match="num_worlds"):
        run_longform("default", RuleBasedPolicy(), duration_s=1.0, num_worlds=0)
    with pytest.raises(ValueError, match="env factory"):
        run_longform(42, RuleBasedPolicy(), duration_s=1.0, num_worlds=1)


@pytest.mark.slow
def test_longform_600s_two_worlds():
    res = run_longform("default", RuleBasedPolicy(), duration_s=600.0, num_worlds=2, seed=0)
    d = res.to_dict()
    assert res.steps == 6000 and res.km > 50.0
    k = d["km_between_incidents"]
    assert k["incidents"] == res.incidents and k["lo"] <= (k["value"] if res.incidents else math.inf)
    print("longform 600 s x 2 worlds:", {x: d[x] for x in ("km", "incidents", "onsets", "world_episodes")})


def test_report_writes_json_and_markdown(tmp_path):
    result = {
        "collision_rate": proportion(1, 4),
        "km_between_incidents": km_between_incidents(0, 100.0),
        "n": 4,
        "nested": {"ade_m": 1.5},
        "samples": [1, 2, 3],
    }
    paths = write_report(result, tmp_path, "eval", title="Test")
    data = json.loads(paths["json"].read_text())
    assert data["km_between_incidents"]["value"] == "inf" and data["n"] == 4
    md = paths["markdown"].read_text()
    assert md.startswith("## Test")
    rows = {r[0]: r for r in table_rows(result)}
    assert rows["collision_rate"][1:] == ("0.25", "[0.04559, 0.6994]", "1 / 4")
    assert rows["km_between_incidents"][1] == "inf" and rows["km_between_incidents"][3] == "100 km / 0"
    assert rows["km_between_incidents"][2] == "[27.11, inf]"
    assert rows["nested.ade_m"][1] == "1.5" and "samples" not in rows
    assert md.count("\n| ") == len(rows) + 1  # header plus one row per metric
    assert "| n | 4 |  |  |" in markdown_table(result)
    with pytest.raises(ValueError, match="object"):
        write_report({"x": object()}, tmp_path, "bad")
    with pytest.raises(ValueError, match="file stem"):
        write_report({}, tmp_path, "a/b")
