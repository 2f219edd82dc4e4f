"""Rule-based driver: lane keeping at the speed limit, gap keeping behind a stopped vehicle,
stopping at a red light, following waypoints through junctions, and collision / road-edge
rates on the bundled map far below random actions."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from loadfile import load_sim_helpers

from selfplaydrive.drivers import DriverParams, RandomDriver, RuleBasedDriver, StaticDriver
from selfplaydrive.maps import LaneElement, MapElements, PolylineElement, TrafficLightElement, compile_map
from selfplaydrive.sim import ContinuousActions, VecEnv

LIMIT = 13.9  # [m/s] speed limit of the test road
ROAD = 800.0  # [m] length of the test road
W = 3.5  # [m] lane width
COLLIDE, OFFROAD, RED = 1, 4, 8  # event bits (docs/world.md)


H = load_sim_helpers()


def _road(light_at: float | None = None):
    """Two 800 m lanes (east at y=0, west at y=3.5), road edges at the outer lane borders and
    optionally a traffic-light line across the east lane at x = light_at (original frame)."""
    lanes = [
        LaneElement(np.array([[0.0, 0.0], [ROAD, 0.0]]), width=W, speed_limit=LIMIT, source_id="east"),
        LaneElement(np.array([[ROAD, W], [0.0, W]]), width=W, speed_limit=LIMIT, source_id="west"),
    ]
    edges = [
        PolylineElement(np.array([[0.0, -W / 2], [ROAD, -W / 2]]), source_id="south"),
        PolylineElement(np.array([[0.0, 1.5 * W], [ROAD, 1.5 * W]]), source_id="north"),
    ]
    lights = []
    if light_at is not None:
        lights = [
            TrafficLightElement(
                np.array([[light_at, -W / 2], [light_at, W / 2]]), signal_group=0, lanes=[0], source_id="tl"
            )
        ]
    return compile_map(MapElements(name="road", lanes=lanes, road_edges=edges, traffic_lights=lights))


def _east_start(m) -> np.ndarray:
    """Start of the east lane in the compiled (recentred) frame."""
    return m.lanes.centerlines[0][0].astype(np.float64)


def _run(env, driver, seconds: float) -> dict[str, np.ndarray]:
    ever = np.zeros(env.num_agents, np.uint8)
    speeds = []
    for _ in range(round(seconds / env.params.dt)):
        env.step(driver.act())
        ever |= env.state.events
        speeds.append(env.state.speed.copy())
    return {"ever": ever, "speed": np.array(speeds)}


def test_straight_road_reaches_the_limit_and_keeps_its_lane():
    m = _road()
    x0, y0 = _east_start(m)
    sc = H.make_scenario([dict(xy=(x0 + 10, y0 + 0.4), heading=0.03, speed=0.0)], episode_length=40.0, A=2)
    env = VecEnv(m, H.FixedSpawner(sc), 1)
    env.reset(0)
    drv = RuleBasedDriver(env)
    out = _run(env, drv, 30.0)
    v = out["speed"][:, 0]
    assert v[-100:].min() > 0.9 * LIMIT and v.max() <= LIMIT * 1.02  # near the limit, not above
    assert v[50] > 0.5 * LIMIT  # it accelerated within 5 s
    assert out["ever"][0] & (OFFROAD | COLLIDE) == 0
    assert abs(float(env.state.y[0]) - y0) < 0.5  # still centred in its lane after 30 s
    assert float(env.state.x[0]) - x0 > 0.85 * LIMIT * 30


def test_stops_behind_a_stopped_vehicle_without_collision():
    m = _road()
    x0, y0 = _east_start(m)
    sc = H.make_scenario(
        [dict(xy=(x0 + 10, y0), speed=12.0)], statics=[dict(xy=(x0 + 110, y0))], episode_length=40.0, A=2
    )
    env = VecEnv(m, H.FixedSpawner(sc), 1)
    env.reset(0)
    out = _run(env, RuleBasedDriver(env), 20.0)
    assert out["ever"][0] & (COLLIDE | OFFROAD) == 0
    assert out["speed"][-20:, 0].max() == 0.0  # stopped and stays stopped
    gap = (x0 + 110 - 2.25) - (float(env.state.x[0]) + 2.25)  # bumper to bumper [m]
    assert 0.5 < gap < 6.0


@pytest.mark.parametrize("state, stops", [(1, True), (3, False)])
def test_stops_at_a_red_light_line_and_passes_a_green_one(state, stops):
    m = _road(light_at=300.0)
    x0, y0 = _east_start(m)
    line_x = float(m.light_lines[0][:, 0].mean())
    sc = H.make_scenario(
        [dict(xy=(x0 + 200, y0), speed=LIMIT)], lights=[(state, 1e4)], episode_length=40.0, A=2
    )
    env = VecEnv(m, H.FixedSpawner(sc), 1)
    env.reset(0)
    out = _run(env, RuleBasedDriver(env), 15.0)
    front = float(env.state.x[0]) + 2.25
    assert out["ever"][0] & (RED | COLLIDE | OFFROAD) == 0
    if stops:
        assert out["speed"][-10:, 0].max() == 0.0 and line_x - 4.0 < front < line_x
    else:
        assert front > line_x + 50.0


def _along(line: np.ndarray, d: float) -> np.ndarray:
    """Point `d` metres along polyline `line`."""
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    return np.array([np.interp(d, cum, line[:, 0]), np.interp(d, cum, line[:, 1])])


def _junction_approach(m) -> int:
    """A lane outside junctions whose end has three successors (left, straight, right)."""
    lanes = m.lanes
    for i in range(len(lanes)):
        succ = lanes.successors(i)
        if not lanes.in_junction[i] and len(succ) == 3 and all(len(lanes.successors(c)) for c in succ):
            return i
    raise AssertionError("the grid map has no three-way approach")


@pytest.mark.parametrize("branch", [0, 1, 2])
def test_follows_its_waypoint_through_a_junction(grid_map, branch):
    lanes = grid_map.lanes
    approach = _junction_approach(grid_map)
    line = lanes.centerlines[approach].astype(np.float64)
    connector = int(lanes.successors(approach)[branch])
    exit_lane = int(lanes.successors(connector)[0])
    wp = _along(lanes.centerlines[exit_lane].astype(np.float64), 12.0)
    start = _along(line, 2.0)
    heading = float(np.arctan2(*(line[1] - line[0])[::-1]))
    sc = H.make_scenario(
        [dict(xy=start, heading=heading, speed=5.0, waypoints=[wp])], A=2, episode_length=30.0
    )
    env = VecEnv(grid_map, H.FixedSpawner(sc), 1)
    env.reset(0)
    drv = RuleBasedDriver(env)
    ever = 0
    for _ in range(200):
        env.step(drv.act())
        ever |= int(env.state.ever[0])
        if env.state.wp_idx[0] == 1:
            break
    assert env.state.wp_idx[0] == 1, f"waypoint {wp} not reached; car at {env.state.x[0]}, {env.state.y[0]}"
    assert ever & (COLLIDE | OFFROAD) == 0


def test_continuous_actions_and_inactive_slots(straight_map):
    sc = H.make_scenario([dict(xy=(0, -2), speed=5.0)], episode_length=5.0)
    env = VecEnv(straight_map, H.FixedSpawner(sc), 1, actions=ContinuousActions())
    env.reset(0)
    a = RuleBasedDriver(env).act()
    assert a.dtype == np.float32 and a.shape == (4, 2)
    assert np.all(np.abs(a) <= env.action_table.high)
    np.testing.assert_array_equal(a[1:], [[-4.0, 0.0]] * 3)  # empty slots: brake, straight
    np.testing.assert_array_equal(StaticDriver(env).act(), [[-4.0, 0.0]] * 4)


def _event_rates(env) -> dict[str, float]:
    """Share of agents (finished episodes plus the running ones) with at least one
    collision / road-edge contact / red-light event."""
    stats = env.pop_episode_stats()
    n = sum(s["num_agents"] for s in stats)
    counts = {k: sum(s["agents_with"][k] for s in stats) for k in ("collision", "offroad", "red_light")}
    valid = env.state.agent_valid.astype(bool)
    n += int(valid.sum())
    for k, bit in (("collision", COLLIDE), ("offroad", OFFROAD), ("red_light", RED)):
        counts[k] += int(((env.state.ever & bit) > 0)[valid].sum())
    return {k: v / n for k, v in counts.items()}


def _compare_with_random(num_worlds: int, seconds: float, seed: int) -> dict[str, dict[str, float]]:
    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.scenario.spawner import PaperSpawner

    m = load_map("default")
    rates = {}
    for name in ("rule", "random"):
        env = VecEnv(m, PaperSpawner(), num_worlds, seed=seed)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
            env.reset(seed)
            drv = RuleBasedDriver(env) if name == "rule" else RandomDriver(env, seed=0)
            _run(env, drv, seconds)
        rates[name] = _event_rates(env)
    print(rates)
    return rates


def test_bundled_map_two_worlds_rates_below_random_actions():
    rates = _compare_with_random(num_worlds=2, seconds=10.0, seed=5)
    rule, rnd = rates["rule"], rates["random"]
    assert rule["collision"] < 0.5 * rnd["collision"]
    assert rule["offroad"] < 0.25 * rnd["offroad"]


@pytest.mark.slow
def test_bundled_map_rates_far_below_random_actions():
    """8 worlds, 30 s (the acceptance check of docs/drivers.md)."""
    rates = _compare_with_random(num_worlds=8, seconds=30.0, seed=11)
    rule, rnd = rates["rule"], rates["random"]
    assert rule["collision"] < 0.25 * rnd["collision"] and rule["collision"] < 0.04
    assert rule["offroad"] < 0.25 * rnd["offroad"] and rule["offroad"] < 0.08


def test_localises_on_the_map_of_its_world(grid_map):
    """Two maps in one env: lane ids of map 1 are offset by map 0's lane count."""
    road = _road()
    x0, y0 = _east_start(road)
    sc = H.make_scenario([dict(xy=(x0 + 50, y0), speed=8.0)], A=2, episode_length=20.0, map_index=1)
    env = VecEnv([grid_map, road], H.FixedSpawner(sc), 2)
    env.reset(0)
    drv = RuleBasedDriver(env)
    out = _run(env, drv, 5.0)
    assert (env.state.map_id == 1).all()
    lanes = drv.debug["lane"][[0, 2]]
    np.testing.assert_array_equal(lanes, [len(grid_map.lanes)] * 2)  # the east lane of map 1
    assert out["speed"][-1, 0] > 10.0 and out["ever"][0] & (COLLIDE | OFFROAD) == 0


@pytest.mark.parametrize("blocked", [False, True])
def test_passes_a_vehicle_parked_partly_in_its_lane(blocked):
    """A static car 1.2 m right of the lane centre leaves 1.45 m of the 3.5 m lane free: with
    passing on (max_nudge), the driver pulls over to pass it, unless a vehicle stands in the
    other lane beside it; with the default (passing off) it waits behind."""
    m = _road()
    x0, y0 = _east_start(m)
    statics = [dict(xy=(x0 + 70, y0 - 1.2))]
    if blocked:
        statics.append(dict(xy=(x0 + 72, y0 + W), heading=np.pi))
    sc = H.make_scenario([dict(xy=(x0 + 10, y0), speed=8.0)], statics=statics, episode_length=40.0, A=2)
    env = VecEnv(m, H.FixedSpawner(sc), 1)
    env.reset(0)
    out = _run(env, RuleBasedDriver(env, DriverParams(max_nudge=2.0)), 25.0)
    assert out["ever"][0] & (COLLIDE | OFFROAD) == 0
    x, y = float(env.state.x[0]), float(env.state.y[0])
    if blocked:  # waits behind the parked car
        assert out["speed"][-10:, 0].max() == 0.0 and x < x0 + 70 - 4.5
    else:  # passed it and came back to the lane centre
        assert x > x0 + 150 and abs(y - y0) < 0.5


def test_waits_behind_a_parked_vehicle_by_default():
    m = _road()
    x0, y0 = _east_start(m)
    sc = H.make_scenario(
        [dict(xy=(x0 + 10, y0), speed=8.0)], statics=[dict(xy=(x0 + 70, y0 - 1.2))], episode_length=40.0, A=2
    )
    env = VecEnv(m, H.FixedSpawner(sc), 1)
    env.reset(0)
    out = _run(env, RuleBasedDriver(env), 15.0)
    assert out["ever"][0] & (COLLIDE | OFFROAD) == 0
    assert out["speed"][-10:, 0].max() == 0.0 and float(env.state.x[0]) < x0 + 70 - 4.5
