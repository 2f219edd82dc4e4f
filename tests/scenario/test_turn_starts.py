"""`PaperSpawner(turn_lane_starts=k)`: agents moved to turn-lane starts (scenario/turn_starts.py)."""

from __future__ import annotations

import numpy as np
import pytest
from lanegraph import reaches_by_following

from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.lane_paths import project
from selfplaydrive.maps.loader import load_map
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.scenario.turn_starts import TurnLaneStarts, start_table
from selfplaydrive.testing import check_spawner


@pytest.fixture(scope="module")
def town():
    return load_map("default")


@pytest.fixture(scope="module")
def table(town):
    return start_table(town)


def _spawner(k: int) -> PaperSpawner:
    return PaperSpawner(num_agents=16, turn_lane_starts=k, waypoint_spacing=2.5, lane_change_prob=0.5)


def _moved(sc, table) -> dict[int, int]:
    """Slot -> table row of every agent standing exactly on a start row with its waypoints."""
    out = {}
    for a in np.flatnonzero(sc.agent_valid):
        if sc.num_waypoints[a] != 2:
            continue
        d = np.hypot(*(table.xy - sc.agent_xy[a]).T)
        wd = np.abs(table.waypoints - sc.waypoints[a, :2]).max(axis=(1, 2))
        rows = np.flatnonzero((d < 1e-3) & (wd < 1e-3) & (table.lane == sc.agent_lane[a]))
        if len(rows):
            out[int(a)] = int(rows[0])
    return out


def test_start_rows_are_wrong_lanes_before_a_turn(town, table):
    assert len(table.xy) > 1000  # the bundled town has hundreds of sites
    rng = np.random.default_rng(0)
    lanes = town.lanes
    for row in rng.choice(len(table.xy), 40, replace=False):
        w = int(table.lane[row])
        line = lanes.centerlines[w].astype(np.float64)
        _, _, dist = project(line, table.xy[row : row + 1])
        assert dist[0] < 0.05  # on W's centerline
        assert not lanes.in_junction[w]
        assert 0.0 < table.speed_cap[row] == pytest.approx(0.8 * float(lanes.speed_limit[w]))
        # the two exit waypoints lie 10 m and 30 m along the exit lanes
        wp = table.waypoints[row]
        assert np.hypot(*(wp[1] - wp[0])) == pytest.approx(20.0, abs=0.5)


def test_moved_agents_start_on_table_rows_and_keep_their_distance(town, table):
    sp = _spawner(4)
    counts = []
    for seed in range(40):
        sc = sp.sample(town, np.random.default_rng(seed))
        moved = _moved(sc, table)
        counts.append(len(moved))
        assert len(moved) <= 4
        xy = sc.agent_xy[sc.agent_valid].astype(np.float64)
        d = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1))
        np.fill_diagonal(d, np.inf)
        assert d.min() >= 15.0 - 1e-3
        for slot, row in moved.items():
            assert sc.agent_lane[slot] == table.lane[row] and not sc.agent_parked[slot]
            assert 5.0 - 1e-4 <= sc.agent_speed[slot] <= min(8.0, table.speed_cap[row]) + 1e-4 or (
                sc.agent_speed[slot] == pytest.approx(table.speed_cap[row])
            )
            assert sc.agent_heading[slot] == pytest.approx(table.heading[row], abs=1e-5)
    assert np.mean(counts) > 1.5  # most worlds get some


def test_start_lane_needs_a_lane_change(town):
    """The suite's site rule, seen through the table: W never reaches J by lane following."""
    from selfplaydrive.eval.suites.turn_lanes import TurnLaneSuite
    from selfplaydrive.maps.lane_paths import LaneGeometry

    suite = TurnLaneSuite()
    geo = LaneGeometry(town)
    sites = suite.sites(town)
    for j, _p, w in [sites[i] for i in np.random.default_rng(1).choice(len(sites), 20, replace=False)]:
        if suite.site_starts(geo, j, _p, w) is not None:
            assert not reaches_by_following(town, w, j)


def test_spawner_contract_holds(town):
    check_spawner(_spawner(4), town, samples=6, seed=3)


def test_off_draws_nothing_extra(town):
    """turn_lane_starts=0 is the paper's spawner: the same scenario, bit for bit."""
    a = PaperSpawner(num_agents=16).sample(town, np.random.default_rng(5))
    b = PaperSpawner(num_agents=16, turn_lane_starts=0).sample(town, np.random.default_rng(5))
    for name in ("agent_xy", "agent_speed", "waypoints", "num_waypoints", "coeffs", "static_xy", "ped_path"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_same_seed_same_world(town):
    a = _spawner(4).sample(town, np.random.default_rng(9))
    b = _spawner(4).sample(town, np.random.default_rng(9))
    np.testing.assert_array_equal(a.agent_xy, b.agent_xy)
    np.testing.assert_array_equal(a.waypoints, b.waypoints)


def test_no_room_moves_nobody(town):
    """A world whose region holds no start row is left as it was."""
    sc = PaperSpawner(num_agents=16).sample(town, np.random.default_rng(2))
    sc.region[:] = (1e6, 1e6, 1e6 + 200.0, 1e6 + 200.0)
    before = sc.agent_xy.copy()
    assert TurnLaneStarts().apply(sc, town, np.random.default_rng(0), 4) == 0
    np.testing.assert_array_equal(sc.agent_xy, before)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"turn_lane_starts": -1}, "turn_lane_starts"),
        ({"turn_lane_starts": 2, "max_waypoints": 1}, "max_waypoints"),
        ({"turn_lane_worlds": 1.5}, "turn_lane_worlds"),
        ({"turn_lane_worlds": 0.5, "max_waypoints": 1}, "max_waypoints"),
    ],
)
def test_bad_settings_name_the_key(kwargs, words):
    with pytest.raises(ConfigError, match=words):
        PaperSpawner(**kwargs)


def test_turn_lane_worlds_hold_turn_lane_starts_only(town, table):
    sp = PaperSpawner(num_agents=16, turn_lane_worlds=1.0)
    check_spawner(sp, town, samples=4, seed=1)
    sizes = []
    for seed in range(16):
        sc = sp.sample(town, np.random.default_rng(seed))
        valid = np.flatnonzero(sc.agent_valid)
        moved = len(_moved(sc, table))
        if moved == 0:
            continue  # a region without starts stays a normal world
        sizes.append(len(valid))
        assert moved == len(valid)  # every agent on a start row with its waypoints
        gone = ~sc.agent_valid
        assert (sc.agent_lane[gone] == -1).all() and not sc.num_waypoints[gone].any()
        assert not sc.agent_parked.any() and len(valid) >= 1
        xy = sc.agent_xy[valid].astype(np.float64)
        d = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1))
        np.fill_diagonal(d, np.inf)
        assert d.min() >= 15.0 - 1e-3
    assert len(sizes) >= 10 and np.mean(sizes) > 4  # most regions hold several starts


def test_turn_lane_worlds_share(town):
    sp = PaperSpawner(num_agents=16, turn_lane_worlds=0.25)
    only = [
        bool((sc.num_waypoints[sc.agent_valid] == 2).all())
        for sc in (sp.sample(town, np.random.default_rng(s)) for s in range(120))
    ]
    assert 0.1 < np.mean(only) < 0.4
