"""VecEnv: action validation, autoreset, final observations, statistics, lights, pedestrians,
hooks and determinism across thread counts (spec items 7-9)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from helpers import FixedSpawner, RandomSpawner, cross_map, make_scenario

from selfplaydrive.sim import ContinuousActions, SimParams, VecEnv


@pytest.fixture(scope="module")
def cmap():
    return cross_map()


def test_action_validation_names_argument_value_and_expectation(straight_map):
    env = VecEnv(straight_map, FixedSpawner(make_scenario([dict(xy=(0, -2))])), 2)
    env.reset(0)
    N = env.num_agents
    with pytest.raises(ValueError, match=r"actions: expected shape \(8, 2\), got \(8, 3\)"):
        env.step(np.zeros((N, 3), np.int64))
    with pytest.raises(ValueError, match="expected an integer array"):
        env.step(np.zeros((N, 2), np.float32))
    bad = np.zeros((N, 2), np.int64)
    bad[5, 1] = 13
    with pytest.raises(
        ValueError, match=r"actions\[5, 1\] \(steering index\) = 13: expected an integer in \[0, 13\)"
    ):
        env.step(bad)
    with pytest.raises(ValueError, match="numpy array"):
        env.step([[0, 0]] * N)
    cenv = VecEnv(
        straight_map, FixedSpawner(make_scenario([dict(xy=(0, -2))])), 1, actions=ContinuousActions()
    )
    cenv.reset(0)
    a = np.zeros((cenv.num_agents, 2), np.float32)
    a[2, 0] = np.nan
    with pytest.raises(ValueError, match=r"actions\[2, 0\] = nan: expected a finite number"):
        cenv.step(a)
    a[2, 0] = 5.0
    with pytest.raises(ValueError, match=r"actions\[2, 0\] = 5.0: expected a value in \[-4.0, 4.0\]"):
        cenv.step(a)
    a[2, 0] = 0.0
    a[0, 0] = 1.0
    cenv.step(a)
    assert cenv.buffers["speed"][0] == pytest.approx(0.1)


def test_autoreset_truncation_final_observation_and_stats(straight_map):
    sc = make_scenario([dict(xy=(-50, -2), speed=10.0), dict(xy=(0, -2), speed=5.0)], episode_length=1.0)
    env = VecEnv(straight_map, FixedSpawner(sc), 2)
    env.reset(0)
    acts = np.tile(np.array([3, 6]), (env.num_agents, 1))
    for _ in range(9):
        env.step(acts)
        assert not env.truncations.any()
    before = env.observations[0].copy()
    env.step(acts)  # step 10: time limit of 1 s
    assert env.truncations[[0, 1, 4, 5]].all() and not env.terminations.any()
    # final observation: speed feature of the ended agent; the new episode starts at -50 again
    assert env.final_observations[0, 2] == pytest.approx(10.0 / 40.0)
    assert not np.array_equal(env.final_observations[0], before)
    assert env.buffers["x"][0] == pytest.approx(-50.0) and env.buffers["step"][0] == 0
    assert env.masks[[0, 1, 4, 5]].all()
    stats = env.pop_episode_stats()
    assert len(stats) == 2 and stats[0]["num_agents"] == 2
    assert stats[0]["spawn_shortfall"] == env.agents_per_world - 2
    assert stats[0]["km"] == pytest.approx((10.0 + 5.0) * 1.0 / 1000.0, rel=1e-4)
    assert stats[0]["events"]["truncated"] == 2
    assert stats[0]["terms"]["velocity"] > 0


def test_world_resets_when_all_agents_terminated(straight_map):
    sc = make_scenario([dict(xy=(0, -3.2), speed=5.0, coeffs=dict(offroad=0.9))], episode_length=10.0)
    env = VecEnv(straight_map, FixedSpawner(sc), 1)
    env.reset(0)
    env.step(np.tile(np.array([3, 6]), (env.num_agents, 1)))
    assert env.terminations[0] and env.masks[0]  # ended, and the world was resampled
    st = env.pop_episode_stats()
    assert st[0]["events"]["offroad"] == 1 and st[0]["agents_with"]["offroad"] == 1
    assert st[0]["events"]["terminated"] == 1


def test_lights_change_with_durations_in_range(cmap):
    sc = make_scenario([dict(xy=(50, -1.75))], lights=[(1, 0.05), (3, 0.05)], episode_length=100.0)
    env = VecEnv(cmap, FixedSpawner(sc), 3, params=SimParams(light_min=0.5, light_max=10.0))
    env.reset(7)
    b = env.buffers
    seen, times = set(), []
    for _ in range(300):
        env.step(np.tile(np.array([3, 6]), (env.num_agents, 1)))
        seen.update(b["light_state"].tolist())
        times.extend(b["light_time"].tolist())
    assert seen == {0, 1, 2, 3}
    assert max(times) <= 10.0 and min(times) > 0.0
    off = make_scenario([dict(xy=(50, -1.75))], episode_length=100.0)
    off.light_state = np.array([1, 1], np.int8)
    off.light_time_left = np.array([0.05, 0.05], np.float32)  # lights_enabled False: stay off
    env = VecEnv(cmap, FixedSpawner(off), 1)
    env.reset(0)
    for _ in range(20):
        env.step(np.tile(np.array([3, 6]), (env.num_agents, 1)))
    assert np.all(env.buffers["light_state"] == 0)


@pytest.mark.parametrize("end, here", [("stand", 1), ("vanish", 0)])
def test_pedestrian_waits_walks_and_stands_or_vanishes(straight_map, end, here):
    ped = dict(path=[(0.0, 10.0), (0.0, 13.0)], speed=1.5, start=1.0)
    env = VecEnv(
        straight_map,
        FixedSpawner(make_scenario([dict(xy=(-50, -2))], peds=[ped], episode_length=100.0)),
        1,
        params=SimParams(pedestrian_end=end),
    )
    env.reset(0)
    b = env.buffers
    acts = np.tile(np.array([3, 6]), (env.num_agents, 1))
    for _ in range(9):  # t = 0.9: still waiting
        env.step(acts)
    assert (b["ped_x"][0], b["ped_y"][0], b["ped_vy"][0]) == (0.0, 10.0, 0.0)
    for _ in range(11):  # t = 2.0: walked 1.5 m
        env.step(acts)
    assert b["ped_y"][0] == pytest.approx(11.5, abs=1e-4) and b["ped_vy"][0] == pytest.approx(1.5)
    for _ in range(20):  # t = 4.0: path (3 m) done at t = 3
        env.step(acts)
    assert b["ped_y"][0] == pytest.approx(13.0) and b["ped_vy"][0] == 0.0 and b["ped_here"][0] == here


def test_python_hooks_run_after_kernels(straight_map):
    class Bonus:
        name = "bonus"

        def __call__(self, state):
            return np.where(state.active, 1.0, 0.0).astype(np.float32)

    class Speed2:
        name = "speed2"
        dim = 1

        def __call__(self, state):
            return (state.speed / 40.0)[:, None] ** 2

    env = VecEnv(
        straight_map,
        FixedSpawner(make_scenario([dict(xy=(0, -2), speed=20.0)])),
        1,
        reward_hooks=[Bonus()],
        obs_hooks=[Speed2()],
    )
    env.reset(0)
    assert env.observations.shape[1] == env.layout.kernel_dim + 1
    env.step(np.tile(np.array([3, 6]), (env.num_agents, 1)))
    assert env.extra_terms[0, 0] == 1.0 and env.extra_terms[1, 0] == 0.0
    # the hook's column is the last column of reward_terms, whose sum is the reward
    assert env.term_names[-1] == "bonus" and env.reward_terms[0, -1] == 1.0
    assert env.rewards[0] == pytest.approx(env.reward_terms[0].sum())
    assert env.observations[0, -1] == pytest.approx(0.25)
    with pytest.raises(ValueError):
        env.state.x[0] = 1.0  # read-only views


def rollout_digest(cmap, threads: int, steps: int) -> str:
    env = VecEnv(cmap, RandomSpawner(), 8, num_threads=threads, seed=123)
    env.reset(123)
    rng = np.random.default_rng(9)
    h = hashlib.sha256()
    for _ in range(steps):
        env.step(rng.integers(0, [7, 13], size=(env.num_agents, 2)))
        for arr in (
            env.observations,
            env.rewards,
            env.reward_terms,
            env.terminations,
            env.truncations,
            env.masks,
        ):
            h.update(arr.tobytes())
    return h.hexdigest()


def test_determinism_500_steps_one_and_two_threads(cmap):
    d1 = rollout_digest(cmap, 1, 500)
    assert d1 == rollout_digest(cmap, 2, 500)
    assert d1 == rollout_digest(cmap, 1, 500)


def _bodies_in_range(env, i: int) -> int:
    """Bodies agent slot i observes (NumPy count): other agents (active, obstacles, or ended
    this step: the observation precedes their removal), static vehicles, present pedestrians
    within the observation radius, at most max_objects."""
    st, A = env.state, env.agents_per_world
    w = i // A
    a = slice(w * A, (w + 1) * A)
    s = slice(w * env.dims.S, (w + 1) * env.dims.S)
    p = slice(w * env.dims.P, (w + 1) * env.dims.P)
    keep = (st.active[a] | st.obstacle[a] | st.term[a] | st.trunc[a]).astype(bool)
    keep[i - w * A] = False
    xs = np.concatenate(
        [
            st.x[a][keep],
            st.st_x[s][st.st_valid[s] > 0],
            st.ped_x[p][(st.ped_valid[p] > 0) & (st.ped_here[p] > 0)],
        ]
    )
    ys = np.concatenate(
        [
            st.y[a][keep],
            st.st_y[s][st.st_valid[s] > 0],
            st.ped_y[p][(st.ped_valid[p] > 0) & (st.ped_here[p] > 0)],
        ]
    )
    d2 = (xs - st.x[i]) ** 2 + (ys - st.y[i]) ** 2
    return min(int(np.count_nonzero(d2 <= env.obs_config.radius**2)), env.layout.max_objects)


def test_padding_rows_stay_zero_and_observations_are_read_only():
    """The observation stage clears only the padding rows whose count changed since the slot's
    last observation; over a rollout on the bundled town (object counts rise and fall, agents
    end, worlds reset) every padding row must still be zero and every valid row first."""
    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.scenario.spawner import PaperSpawner

    env = VecEnv(load_map("default"), PaperSpawner(), 4, seed=5)
    env.reset(5)
    lay = env.layout
    rng = np.random.default_rng(2)
    counts = set()
    for step in range(160):
        env.step(rng.integers(0, [7, 13], size=(env.num_agents, 2)))
        rows = env.observations[env.masks]
        for start, n, dim in (
            (lay.ego_dim, lay.max_objects, 9),
            (lay.ego_dim + 9 * lay.max_objects, lay.max_road, 8),
        ):
            block = rows[:, start : start + n * dim].reshape(len(rows), n, dim)
            if dim == 9:
                k = np.array([_bodies_in_range(env, i) for i in np.flatnonzero(env.masks)])
                counts.update(k.tolist())
            else:
                k = env.state.road_n[env.masks]
            valid = np.arange(n)[None, :] < k[:, None]
            assert np.all(block[valid][:, 0] == 1.0), step
            assert not np.any(block[~valid]), f"stale padding row at step {step}"
    assert len(counts) > 10  # the object counts did change
    with pytest.raises(ValueError):
        env.observations[0, 0] = 1.0
    with pytest.raises(ValueError):
        env.final_observations[0, 0] = 1.0


def test_road_segments_are_global_indices_of_the_road_rows():
    """`road_segments` converts the atlas positions of `road_idx` to `RoadMap.segments`
    indices: each row's midpoint, in the ego frame, is that segment's midpoint."""
    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.scenario.spawner import PaperSpawner

    road_map = load_map("default")
    env = VecEnv(road_map, PaperSpawner(), 1, seed=1)
    env.reset(1)
    lay, st = env.layout, env.state
    i = int(np.flatnonzero(env.masks)[0])
    seg = env.road_segments(i)
    assert len(seg) == st.road_n[i] > 0 and len(set(seg.tolist())) == len(seg)
    rows = env.observations[i, lay.ego_dim + 9 * lay.max_objects :][: 8 * len(seg)].reshape(-1, 8)
    mid = road_map.segments.mid[seg].astype(np.float64)
    c, s = float(st.hcos[i]), float(st.hsin[i])
    dx, dy = mid[:, 0] - st.x[i], mid[:, 1] - st.y[i]
    want = np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1) / env.obs_config.radius
    np.testing.assert_allclose(rows[:, 1:3], np.clip(want, -1, 1), atol=2e-5)
    with pytest.raises(IndexError):
        env.road_segments(env.num_agents)


def test_smallest_candidate_capacity_gives_the_same_rollout():
    """`sim.cand_cap=1` (the smallest accepted) is raised to what the collision and observation
    kernels write into the per-world scratch, and the gather's fallbacks keep the results:
    the rollout equals the default capacity's at 1 and 2 threads. (Regression: the scratch was
    sized 10 NB + 32 while the body table writes 9 NB + 2 pad4(NB) entries, so with a small
    cand_cap the last world wrote past the buffer: other results, heap corruption.)"""
    from selfplaydrive._sim.events import collision_scratch
    from selfplaydrive._sim.observe import body_scratch
    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.scenario.spawner import PaperSpawner

    road_map = load_map("default")

    def digest(cap: int, threads: int) -> str:
        env = VecEnv(road_map, PaperSpawner(), 4, seed=3, num_threads=threads, params=SimParams(cand_cap=cap))
        d = env.dims
        assert d.cand_cap >= max(body_scratch(d.A, d.S, d.P), collision_scratch(d.A, d.S, d.P))
        env.reset(3)
        rng = np.random.default_rng(1)
        h = hashlib.sha256()
        for _ in range(100):
            env.step(rng.integers(0, [7, 13], size=(env.num_agents, 2)))
            for arr in (env.observations, env.rewards, env.terminations, env.state.road_n):
                h.update(arr.tobytes())
        return h.hexdigest()

    assert body_scratch(80, 48, 8) == 9 * 136 + 2 * 136  # NB = 136: records, distances, x, y
    assert collision_scratch(30, 1, 0) == 3 * (32 + 4 + 0)
    want = digest(SimParams().cand_cap, 1)
    assert digest(1, 1) == want
    assert digest(1, 2) == want


def test_huge_lane_radius_gives_the_same_lanes(cmap):
    """Lane association looks within min(lane_radius, obs radius); a radius of 1e12 m (accepted)
    must give the same rollout as 1e3 m. (Regression: the grid bounds overflowed int, the
    gather scanned nothing and no agent had a lane or road rows.)"""

    def digest(lane_radius: float) -> tuple[str, bool]:
        env = VecEnv(cmap, RandomSpawner(), 2, seed=4, params=SimParams(lane_radius=lane_radius))
        env.reset(4)
        rng = np.random.default_rng(3)
        h, lanes = hashlib.sha256(), False
        for _ in range(30):
            env.step(rng.integers(0, [7, 13], size=(env.num_agents, 2)))
            lanes |= bool(env.state.lane_valid[env.masks].any())
            for arr in (env.observations, env.rewards, env.state.road_n, env.state.lane_s):
                h.update(arr.tobytes())
        return h.hexdigest(), lanes

    want, lanes = digest(1e3)
    assert lanes
    assert digest(1e12) == (want, True)


def _one_agent(**agent):
    a = dict(xy=(1.75, -40.0), heading=np.pi / 2, speed=5.0, waypoints=[(1.75, 0), (1.75, 40)])
    a.update(agent)
    return make_scenario(
        [a], A=2, K=3, S=1, P=1, statics=[dict(xy=(10.0, 10.0))], peds=[dict(path=[(-5.0, 0.0), (5.0, 0.0)])]
    )


def _edit(sc, name: str, index, value):
    getattr(sc, name)[index] = value
    return sc


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (
            lambda sc: _edit(sc, "num_waypoints", 0, 4),
            r"scenario.num_waypoints: expected counts in \[0, 3\].*got 4 in slot 0",
        ),
        (
            lambda sc: _edit(sc, "ped_num_points", 0, 9),
            r"scenario.ped_num_points: expected counts in \[0, 3\].*got 9",
        ),
        (
            lambda sc: _edit(sc, "waypoints", (0, 1, 0), np.nan),
            r"scenario.waypoints: expected finite points.*slot 0",
        ),
        (lambda sc: _edit(sc, "ped_path", (0, 0, 1), np.inf), r"scenario.ped_path: expected finite points"),
        (
            lambda sc: _edit(sc, "agent_length", 0, 0.0),
            r"scenario.agent_length: expected positive finite sizes.*slot 0",
        ),
        (lambda sc: _edit(sc, "agent_xy", (0, 1), np.nan), r"scenario.agent_xy: expected finite values"),
        (lambda sc: _edit(sc, "coeffs", (0, 2), np.inf), r"scenario.coeffs: expected finite values"),
        (lambda sc: _edit(sc, "static_width", 0, -1.0), r"scenario.static_width: expected positive finite"),
        (lambda sc: _edit(sc, "ped_size", (0, 1), np.nan), r"scenario.ped_size: expected positive finite"),
    ],
)
def test_inconsistent_custom_scenario_is_refused(cmap, edit, match):
    """A custom spawner's scenario whose counts exceed its arrays (the kernels would read past
    the slot's row and, in the last world, past the buffer), or with non-finite positions or
    non-positive sizes (a zero length is 0/0 in the bicycle model), raises a ValueError that
    names the field, the value and the slot at reset."""
    VecEnv(cmap, FixedSpawner(_one_agent()), 2).reset(0)  # the unedited scenario is fine
    env = VecEnv(cmap, FixedSpawner(edit(_one_agent())), 2)
    with pytest.raises(ValueError, match=match):
        env.reset(0)
