"""Rule-complete reward terms (issue #15 item 1, issue #16 item 3): red_intersection, stop_sign,
crosswalk_yield, wrong_way and turn_lane, hand-computed on test roads, equal to their NumPy
references on random rollouts, deterministic across threads, with their state saved and
restored."""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from selfplaydrive.errors import ConfigError
from selfplaydrive.eval.suites.base import FixedScenarioSpawner, blank_scenario, put_agent
from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.elements import (
    CrosswalkElement,
    LaneElement,
    MapElements,
    PolylineElement,
    StopKind,
    StopLineElement,
    TrafficLightElement,
)
from selfplaydrive.maps.loader import load_map
from selfplaydrive.rewards import TERM_NAMES, KernelTerm, LinearReward, get_term
from selfplaydrive.rewards.rules import turn_records
from selfplaydrive.scenario.lights import GREEN, RED
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.actions import ContinuousActions
from selfplaydrive.testing import rule_terms

RULES = ("red_intersection", "stop_sign", "crosswalk_yield", "wrong_way", "turn_lane")
STATEFUL = ("stop_sign", "turn_lane")  # their references take and return their state column
Y0, Y1 = -1.75, 1.75  # [m] centerlines of the eastbound lane 0 and the westbound lane 1
X0 = -100.0  # [m] the map is compiled centred on its bounds: road x below is local x - X0


def rule_road():
    """A straight two-way road along x (0..200 m, lanes 3.5 m wide) with, on the eastbound
    lane: a STOP line at x = 50, a traffic light (group 0) at x = 100, a YIELD line at x = 150
    and a crosswalk over both lanes from x = 170 to 173 (stored shifted by `X0`)."""
    lanes = [
        LaneElement(np.array([[X0, Y0], [200.0 + X0, Y0]]), 3.5, 14.0, source_id="east"),
        LaneElement(np.array([[200.0 + X0, Y1], [X0, Y1]]), 3.5, 14.0, source_id="west"),
    ]
    across = lambda x: np.array([[x + X0, -3.5], [x + X0, 0.0]])  # noqa: E731  (the eastbound half)
    return compile_map(
        MapElements(
            name="rule_road",
            source="tests/rewards/test_rules.py",
            lanes=lanes,
            road_edges=[PolylineElement(np.array([[X0, s], [200.0 + X0, s]])) for s in (-3.5, 3.5)],
            stop_lines=[
                StopLineElement(across(50.0), StopKind.STOP, [0]),
                StopLineElement(across(150.0), StopKind.YIELD, [0]),
            ],
            traffic_lights=[TrafficLightElement(across(100.0), 0, [0])],
            crosswalks=[
                CrosswalkElement(
                    np.array([[170.0, -3.5], [173.0, -3.5], [173.0, 3.5], [170.0, 3.5]]) + np.array([X0, 0.0])
                )
            ],
        )
    )


@pytest.fixture(scope="module")
def road():
    return rule_road()


def reward(*names, args=None):
    """The paper's terms and `names` at weight 1 (`args`: name -> the term's parameters)."""
    args = args or {}
    extra = {n: {"weight": 1.0, "args": list(args[n])} if n in args else 1.0 for n in names}
    return LinearReward({**{n: 1.0 for n in TERM_NAMES}, **extra})


def drive(road, cars, steps=40, light=RED, peds=(), accel=None):
    """Per-step rule columns (steps, A, 4) and x of slot 0 (steps,) of cars (x, y, heading,
    speed) on the test road, driven straight at constant speed (or `accel(step)` m/s^2)."""
    sc = blank_scenario(road, 0, np.array([0.0, 0.0]), 6.0)
    for k, (x, y, h, v) in enumerate(cars):
        put_agent(
            sc,
            k,
            np.array([x + X0, y]),
            h,
            v,
            (4.5, 2.0),
            0 if h == 0.0 else 1,
            np.array([[x + X0 + 30.0, y]]),
        )
    sc.lights_enabled = True
    sc.light_state[:] = light
    sc.light_time_left[:] = 1.0e4
    for k, (path, speed) in enumerate(peds):
        sc.ped_valid[k], sc.ped_num_points[k], sc.ped_speed[k] = True, len(path), speed
        sc.ped_path[k, : len(path)] = path + np.array([X0, 0.0])
        sc.ped_size[k] = (0.5, 0.5)
    env = VecEnv(road, FixedScenarioSpawner([sc]), 1, actions=ContinuousActions(), reward=reward(*RULES))
    env.reset(0)
    cols = [env.term_names.index(n) for n in RULES]
    out, xs = [], []
    for f in range(steps):
        a = np.zeros((env.num_agents, 2), np.float32)
        if accel is not None:
            a[0, 0] = accel(f)
        env.step(a)
        out.append(env.reward_terms[: len(cars)][:, cols].copy())
        xs.append(float(env.state.x[0]) - X0)
    return np.array(out), np.array(xs)


# -- hand-computed cases -------------------------------------------------------------------
def test_red_intersection_own_lane_oncoming_lane_and_green(road):
    # 10 m/s from x = 90.5: the centre crosses the light line x = 100 on step 10 (99.5 -> 100.5)
    own, _ = drive(road, [(90.5, Y0, 0.0, 10.0)])
    assert own[9, 0, 0] == -1.0 and own[:, 0, 0].sum() == -1.0  # once, on entering
    # the oncoming-lane bypass: the line (y in [-3.5, 0]) is never touched, the area is entered
    # (it reaches 12 m left of the line point), same step
    bypass, _ = drive(road, [(90.5, Y1, 0.0, 10.0)])
    assert bypass[9, 0, 0] == -1.0 and bypass[:, 0, 0].sum() == -1.0
    green, _ = drive(road, [(90.5, Y1, 0.0, 10.0)], light=GREEN)
    assert green[:, 0, 0].sum() == 0.0
    # driving west through the area (heading 180 degrees from the approach) is no entry
    west, _ = drive(road, [(115.5, Y1, np.pi, 10.0)])
    assert west[:, 0, 0].sum() == 0.0


def test_stop_sign_full_stop_rolling_stop_no_stop_and_yield(road):
    # no stop: crosses x = 50 on step 10 (49.5 -> 50.5) at 10 m/s
    none, _ = drive(road, [(40.5, Y0, 0.0, 10.0)])
    assert none[9, 0, 1] == -1.0 and none[:, 0, 1].sum() == -1.0
    # rolling stop: 1.5 m/s > v_stop = 0.5 m/s all the way, crossing on step 31 (x 49.95 -> 50.1)
    rolling, x = drive(road, [(45.45, Y0, 0.0, 1.5)], steps=45)
    assert x[30] > 50.0 > x[29]
    assert rolling[30, 0, 1] == -1.0 and rolling[:, 0, 1].sum() == -1.0
    # full stop: starting at rest 4.5 m before the line, 2 m/s^2: stopped at step 1 (0.2 m/s),
    # crosses 4.5 m of driving later < 8 m + half the length
    full, x = drive(road, [(45.5, Y0, 0.0, 0.0)], accel=lambda f: 2.0)
    assert x[-1] > 55.0 and full[:, 0, 1].sum() == 0.0
    # a stop long before does not count: at rest at x = 20, 30 m of driving to the line
    early, x = drive(road, [(20.0, Y0, 0.0, 0.0)], steps=55, accel=lambda f: 4.0 if f < 25 else 0.0)
    assert x[-1] > 55.0 and early[:, 0, 1].sum() == -1.0
    # YIELD line at x = 150: never penalised (the paper's rule, section 2.1)
    yld, _ = drive(road, [(140.5, Y0, 0.0, 10.0)])
    assert yld[:, 0, 1].sum() == 0.0


def test_crosswalk_yield_with_and_without_pedestrian(road):
    # the centre enters the crosswalk (x >= 170) on step 10 (169.5 -> 170.5)
    on = [(np.array([[171.5, 3.0], [171.5, -3.0]]), 1.0)]  # walking over it the whole time
    hit, _ = drive(road, [(160.5, Y0, 0.0, 10.0)], peds=on)
    assert hit[9, 0, 2] == -1.0 and hit[:, 0, 2].sum() == -1.0
    clear, _ = drive(road, [(160.5, Y0, 0.0, 10.0)])
    assert clear[:, 0, 2].sum() == 0.0
    far = [(np.array([[171.5, 30.0], [171.5, 40.0]]), 1.0)]  # walking away, 26.5 m off
    away, _ = drive(road, [(160.5, Y0, 0.0, 10.0)], peds=far)
    assert away[:, 0, 2].sum() == 0.0


def test_wrong_way_costs_one_per_second(road):
    wrong, _ = drive(road, [(20.5, Y1, 0.0, 10.0)], steps=10)
    np.testing.assert_array_equal(wrong[:, 0, 3], np.full(10, -0.1, np.float32))  # -dt per step
    right, _ = drive(road, [(20.5, Y0, 0.0, 10.0)], steps=10)
    assert right[:, 0, 3].sum() == 0.0
    slow, _ = drive(road, [(20.5, Y1, 0.0, 0.8)], steps=10)  # below v_min = 1 m/s
    assert slow[:, 0, 3].sum() == 0.0


# -- kernels against the NumPy references -------------------------------------------------
def random_rollout(maps, steps, threads=1, worlds=4, seed=3, check=True, args=None):
    """Random driving, mostly ahead (accelerations >= 0, steering within the middle of the
    table) so cars reach junctions; with `check`, every step's rule columns and stop_sign state
    equal the NumPy references (`args`: name -> parameters other than the defaults). Returns
    the env and how often each term fired."""
    spawner = PaperSpawner(num_agents=16)
    env = VecEnv(maps, spawner, worlds, seed=seed, num_threads=threads, reward=reward(*RULES, args=args))
    env.reset(seed)
    rng = np.random.default_rng(seed)
    params = {n: get_term(n).params for n in RULES} | dict(args or {})
    cols = {n: env.term_names.index(n) for n in RULES}
    offset = {c.name: int(c.term.args[0]) for c in env.reward.columns if c.name in STATEFUL}
    assert sorted(offset.values()) == [0, 1]
    fired = dict.fromkeys(RULES, 0)
    for _ in range(steps):
        before = {n: env.state.term_state[:, k].copy() for n, k in offset.items()}
        env.step(np.stack([rng.integers(3, 7, env.num_agents), rng.integers(4, 9, env.num_agents)], axis=1))
        if not check:
            continue
        # the references read `active` as the kernels saw it: the slots that acted this step
        st = SimpleNamespace(**{**vars(env.state), "active": env.reward_mask.copy()})
        live = np.repeat(env.state.step != 0, env.agents_per_world) & env.reward_mask
        ref = {
            "red_intersection": rule_terms.red_intersection(st, env.maps, params["red_intersection"]),
            "crosswalk_yield": rule_terms.crosswalk_yield(st, env.maps, params["crosswalk_yield"]),
            "wrong_way": rule_terms.wrong_way(st, env.maps, params["wrong_way"], env.params.dt),
        }
        for n in STATEFUL:
            ref[n], new_state = getattr(rule_terms, n)(st, env.maps, params[n], before[n])
            np.testing.assert_array_equal(st.term_state[live, offset[n]], new_state[live], err_msg=n)
        for n in RULES:
            np.testing.assert_array_equal(env.reward_terms[live, cols[n]], ref[n][live], err_msg=n)
            fired[n] += int(np.count_nonzero(ref[n][live]))
    return env, fired


def test_kernels_equal_numpy_references_on_random_rollouts(road):
    """Random driving on the bundled town and on a grid town with lights, crosswalks and a STOP
    line per road (several maps in one env: per-map tables)."""
    from selfplaydrive.scenario._testmaps import grid_elements

    el = grid_elements(2, 2, block=80.0)
    for k, lane in enumerate(el.lanes[:8]):  # STOP lines across the first roads' lanes, mid-block
        p = lane.centerline
        mid, d = p.mean(axis=0), (p[-1] - p[0]) / np.linalg.norm(p[-1] - p[0])
        n = np.array([-d[1], d[0]])
        el.stop_lines.append(StopLineElement(np.stack([mid - 1.75 * n, mid + 1.75 * n]), StopKind.STOP, [k]))
    grid = compile_map(el)
    _, fired = random_rollout([load_map("default"), grid], steps=150)
    assert fired["red_intersection"] > 0 and fired["wrong_way"] > 0 and fired["stop_sign"] > 0, fired
    # wrong-lane turns need the bundled town's multi-lane approaches
    _, fired = random_rollout(load_map("default"), steps=150)
    assert fired["turn_lane"] > 0, fired
    # entry gates 10 m before the junction (the tables change, the kernel does not)
    _, fired = random_rollout(load_map("default"), steps=150, args={"turn_lane": (0.7071, 10.0)})
    assert fired["turn_lane"] > 0, fired


def test_deterministic_at_one_and_two_threads():
    town = load_map("default")
    one, _ = random_rollout(town, 80, threads=1, check=False)
    two, _ = random_rollout(town, 80, threads=2, check=False)
    for name in ("terms", "term_sum", "term_state", "x", "reward"):
        np.testing.assert_array_equal(one.buffers[name], two.buffers[name], err_msg=name)


def test_state_round_trip_keeps_the_term_state():
    town = load_map("default")
    env, _ = random_rollout(town, 40, check=False)
    assert env.buffers["term_state"].shape == (env.num_agents, 2) and env.buffers["term_state"].any()
    saved = env.get_state()
    rng = np.random.default_rng(9)
    acts = [
        np.stack([rng.integers(0, 7, env.num_agents), rng.integers(0, 13, env.num_agents)], axis=1)
        for _ in range(30)
    ]
    for a in acts:
        env.step(a)
    after = {k: env.buffers[k].copy() for k in ("term_state", "term_sum", "terms")}
    other = VecEnv(town, PaperSpawner(num_agents=16), env.num_worlds, seed=3, reward=reward(*RULES))
    other.set_state(saved)
    np.testing.assert_array_equal(other.buffers["term_state"], saved["buffers.term_state"])
    for a in acts:
        other.step(a)
    for k, v in after.items():
        np.testing.assert_array_equal(other.buffers[k], v, err_msg=k)


# -- the contract ---------------------------------------------------------------------------
def test_terms_are_off_by_default_and_registered():
    assert not set(RULES) & set(LinearReward().names)
    from selfplaydrive.rewards import registered_terms

    assert set(RULES) <= set(registered_terms())
    with pytest.raises(ConfigError, match="bind"):
        LinearReward({"wrong_way": 1.0}).plan()


def test_bind_lays_out_state_and_packs_tables(road):
    bound = LinearReward({"stop_sign": 1.0, "wrong_way": 2.0, "red_intersection": 1.0}).bind([road, road])
    terms = [c.term for c in bound.columns]
    assert all(isinstance(t, KernelTerm) for t in terms)
    assert bound.term_state_dim == 1 and terms[0].state_dim == 1 and terms[0].args[0] == 0.0
    # header: state offset, layout version 1, 2 maps, parameters, 2 body offsets
    t = terms[1]
    assert t.args[1] == 1.0 and t.args[2] == 2.0 and t.args[3] == 1.0
    assert isinstance(t.args, np.ndarray) and t.args.dtype == np.float32 and not t.args.flags.writeable
    # a second stateful term gets the next column
    two = LinearReward({"stop_sign": 1.0, "stop2": 1.0}, terms=[_renamed("stop_sign", "stop2")]).bind([road])
    assert two.term_state_dim == 2 and [c.term.args[0] for c in two.columns] == [0.0, 1.0]


def _renamed(name, new):
    import dataclasses

    return dataclasses.replace(get_term(name), name=new, kernel=name)


def test_args_set_parameters_and_bad_args_raise(road):
    lr = LinearReward({"wrong_way": {"weight": 1.0, "args": [3.0]}})
    assert lr.columns[0].term.params == (3.0,)
    with pytest.raises(ConfigError, match="v_min"):
        LinearReward({"wrong_way": {"weight": 1.0, "args": [3.0, 1.0]}})
    with pytest.raises(ConfigError, match="state_dim"):
        KernelTerm("x", 1, (), state_dim=1)


def test_packing_refuses_tables_beyond_exact_float32_indices():
    from selfplaydrive.rewards.rule_tables import pack

    with pytest.raises(ConfigError, match="2\\*\\*24"):
        pack("big", (), [np.zeros(2**24)])


# -- the red-light suite's scripted drivers -------------------------------------------------
def _suite_sums(town, items, plan_fn, suite, term="red_intersection"):
    """Classifications of the scripted driver `plan_fn` on suite scenarios and each episode's
    sum of `term`."""
    from selfplaydrive.eval.suites import run_suite, scripted

    envs = []

    def make(spawner, n):
        envs.append(VecEnv(town, spawner, n, actions=ContinuousActions(), reward=reward(term)))
        return envs[-1]

    trajs = run_suite(make, scripted.ScriptedDriver.factory(plan_fn), items)
    classes = [suite.classify(i, t) for i, t in zip(items, trajs, strict=True)]
    stats = {rec["world"]: rec["terms"][term] for rec in envs[0].pop_episode_stats()}
    return classes, [stats[w] for w in range(len(items))]


def test_bypass_through_the_oncoming_lane_pays_and_the_compliant_driver_does_not():
    """Issue #15 "Done when": the scripted oncoming-lane bypass of the red-light suite, on the
    bundled town, is classified "bypassed" and pays red_intersection; stopping pays nothing."""
    from selfplaydrive.eval.suites import RedLightSuite

    town = load_map("default")
    items = RedLightSuite().generate(town, np.random.default_rng(4), 6)
    around = [it for it in items if it.info["oncoming_offset_m"] is not None]
    assert len(around) >= 3
    from selfplaydrive.eval.suites.scripted import red_light_plans

    classes, sums = _suite_sums(town, around, red_light_plans("bypass"), RedLightSuite())
    assert [c["outcome"] for c in classes] == ["bypassed"] * len(around)
    assert all(s < 0 for s in sums), sums
    classes, sums = _suite_sums(town, items, red_light_plans("comply"), RedLightSuite())
    assert [c["outcome"] for c in classes] == ["stopped"] * len(items) and sums == [0.0] * len(items)


def test_turn_lane_on_the_turn_lane_suite_s_scripted_drivers():
    """Paper 5.3 on the bundled town: changing to the correct lane early pays nothing; turning
    from the lane next to it pays -1 once. From two lanes over, the scripted curve can pass
    between the junction lanes' mid gates and pay nothing (docs/rewards.md "Limits")."""
    from selfplaydrive.eval.suites import TurnLaneSuite
    from selfplaydrive.eval.suites.scripted import turn_early_change, turn_from_wrong_lane

    town = load_map("default")
    suite = TurnLaneSuite()
    items = suite.generate(town, np.random.default_rng(0), 8)
    classes, sums = _suite_sums(town, items, turn_early_change, suite, "turn_lane")
    assert [c["outcome"] for c in classes] == ["correct_lane"] * len(items) and sums == [0.0] * len(items)
    classes, sums = _suite_sums(town, items, turn_from_wrong_lane, suite, "turn_lane")
    assert [c["outcome"] for c in classes] == ["wrong_lane"] * len(items)
    next_lane = [s for c, s in zip(classes, sums, strict=True) if c["entry_offset_m"] < 5.0]
    assert len(next_lane) >= 3 and next_lane == [-1.0] * len(next_lane), sums
    assert set(sums) <= {0.0, -1.0} and sums.count(-1.0) >= 5, sums


def test_rule_terms_pass_the_reward_term_checker():
    from selfplaydrive.testing import check_reward_term

    town = load_map("default")
    for name in RULES:
        check_reward_term(get_term(name), town, steps=20)


def test_hydra_selects_rule_terms_with_parameters():
    from selfplaydrive.builder import build_env, compose

    over = ["+reward.terms.red_intersection=2.0", "+reward.terms.stop_sign={weight:1.0,args:[0.3,6.0]}"]
    env = build_env(compose("sim", over), maps=[rule_road()], num_worlds=1)
    assert env.term_names[-2:] == ("red_intersection", "stop_sign")
    assert env.reward.columns[-2].weight == 2.0 and tuple(env.reward.columns[-1].term.args[3:5]) == (
        np.float32(0.3),
        6.0,
    )


def test_the_suite_and_the_term_share_the_controlled_area():
    """One definition (maps/rule_geometry.py): the red-light suite's controlled area of each
    scenario is the term's zone of its (light line, lane), to the path's rounding (the suite
    finds the line point on its joined ego path, the term on the lane's own centerline)."""
    from selfplaydrive.eval.suites import RedLightSuite
    from selfplaydrive.maps.rule_geometry import controlled_area, controlled_zones, line_point

    town = load_map("default")
    zones = controlled_zones(town)
    for it in RedLightSuite().generate(town, np.random.default_rng(4), 12):
        c, h = line_point(town, it.info["light_line"], it.info["lane"])
        np.testing.assert_allclose(controlled_area(c, h), it.paths["area"], atol=0.01)
        assert np.min(np.hypot(*(zones[:, :2] - c).T)) < 1e-9  # and the term packs that zone


def test_numba_view_has_the_term_state_fields():
    pytest.importorskip("numba")
    from selfplaydrive._sim.reward import abi_sizes
    from selfplaydrive.rewards.numba_abi import SIM, struct_dtype

    assert SIM.phys_state < SIM.term_state_dim < SIM.term_state  # appended after phys_state
    assert struct_dtype("sim").itemsize == abi_sizes()["sim"]


def test_rule_terms_without_their_observation_warn():
    """stop_sign / crosswalk_yield depend on state only obs=rules shows (issue #15 item 1)."""
    import warnings

    from selfplaydrive.builder import build_env, compose

    with pytest.warns(UserWarning, match=r"\['stop_sign'\] are selected .* select obs=rules"):
        build_env(compose("train", ["+reward.terms.stop_sign=1.0", "env.num_worlds=1"]))
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="reward terms")
        build_env(compose("train", ["+reward.terms.stop_sign=1.0", "obs=rules", "env.num_worlds=1"]))
        build_env(compose("train", ["+reward.terms.red_intersection=1.0", "env.num_worlds=1"]))


# -- turn_lane on a hand-built junction ------------------------------------------------------
R_TURN = 15.0  # [m] radius of the left turn


def turn_junction():
    """A two-lane eastbound approach (x -60 .. 0; left lane 0 at y = 1.75, right lane 1 at
    y = -1.75, changes between them legal) into a junction: lane 0 leads to the left turn JL
    (lane 2, a quarter circle of radius `R_TURN` ending northbound), lane 1 to the straight JS
    (lane 3, 20 m); exit lanes 4 (north) and 5 (east)."""
    th = np.linspace(0.0, np.pi / 2, 16)
    left = np.stack([R_TURN * np.sin(th), Y1 + R_TURN * (1.0 - np.cos(th))], axis=1)
    top = left[-1]
    lanes = [
        LaneElement(
            np.array([[-60.0, Y1], [0.0, Y1]]), 3.5, 14.0, successors=[2], right=1, right_change_legal=True
        ),
        LaneElement(
            np.array([[-60.0, Y0], [0.0, Y0]]), 3.5, 14.0, successors=[3], left=0, left_change_legal=True
        ),
        LaneElement(left, 3.5, 14.0, successors=[4], in_junction=True),
        LaneElement(np.array([[0.0, Y0], [20.0, Y0]]), 3.5, 14.0, successors=[5], in_junction=True),
        LaneElement(np.array([top, top + np.array([0.0, 40.0])]), 3.5, 14.0),
        LaneElement(np.array([[20.0, Y0], [60.0, Y0]]), 3.5, 14.0),
    ]
    return compile_map(MapElements(name="turn_junction", source="tests/rewards/test_rules.py", lanes=lanes))


@pytest.fixture(scope="module")
def junction():
    return turn_junction()


def centre_path(road_map, pieces):
    """Points 1 m apart along the joined `pieces`: lane ids (their centerlines, local frame)
    or (2,) points in the frame the elements were written in (shifted like the lanes)."""
    shift = road_map.lanes.centerlines[5][-1].astype(np.float64) - [60.0, Y0]
    pts = np.concatenate(
        [
            road_map.lanes.centerlines[p].astype(np.float64)
            if isinstance(p, int)
            else np.asarray(p)[None] + shift
            for p in pieces
        ]
    )
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    keep = np.concatenate([[True], np.diff(s) > 1e-9])
    t = np.arange(0.0, s[-1], 1.0)
    return np.stack([np.interp(t, s[keep], pts[keep, 0]), np.interp(t, s[keep], pts[keep, 1])], axis=1)


def drive_path(road_map, paths, reset_before=(), entry_back=0.0):
    """Slot 0 posed on each point of the joined `paths` in turn and stepped once towards the
    next (speed = 1 m / dt, accel and steering 0). Returns the turn_lane column (steps,) and
    its state (steps,) after each step; the world restarts before path k in `reset_before`."""
    start = paths[0][0]
    sc = blank_scenario(road_map, 0, start, 60.0)
    put_agent(sc, 0, start, 0.0, 0.0, (4.5, 2.0), 1, np.array([[500.0, 500.0]]))
    rew = reward("turn_lane", args={"turn_lane": (get_term("turn_lane").params[0], entry_back)})
    env = VecEnv(road_map, FixedScenarioSpawner([sc]), 1, actions=ContinuousActions(), reward=rew)
    env.reset(0)
    col = env.term_names.index("turn_lane")
    off = next(int(c.term.args[0]) for c in env.reward.columns if c.name == "turn_lane")
    values, states = [], []
    for k, path in enumerate(paths):
        if k in reset_before:
            env.reset_worlds([0])
        for p, q in itertools.pairwise(path):
            d = q - p
            env.set_poses([0], p[None], np.array([np.arctan2(d[1], d[0])]), np.array([1.0 / env.params.dt]))
            env.step(np.zeros((env.num_agents, 2), np.float32))
            values.append(float(env.reward_terms[0, col]))
            states.append(float(env.buffers["term_state"][0, off]))
    return np.array(values), np.array(states)


def test_turn_lane_tables_of_the_hand_built_junction(junction):
    rec, _, _ = turn_records(junction)
    kinds = {int(r[7]): (r[6], int(r[8]), list(r[9 : 9 + int(r[8])])) for r in rec}
    assert kinds == {0: (0.0, 0, []), 1: (0.0, 0, []), 2: (1.0, 1, [0.0]), 3: (1.0, 1, [1.0])}
    jl = rec[rec[:, 7] == 2][0]  # JL's gate: at 45 degrees round the turn, a lane width long
    np.testing.assert_allclose(np.hypot(jl[2], jl[3]), 3.5, rtol=1e-9)
    np.testing.assert_allclose(jl[4:6], [np.cos(np.pi / 4), np.sin(np.pi / 4)], atol=0.06)


def test_turn_lane_pays_once_for_turning_from_the_wrong_lane(junction):
    # right lane, then along JL: the junction lane the right lane does not lead to
    wrong, state = drive_path(junction, [centre_path(junction, [(-40.0, Y0), (0.0, Y0), 2, 4])])
    assert wrong.sum() == -1.0 and np.count_nonzero(wrong) == 1
    assert state[np.flatnonzero(wrong)[0] - 1] == 2.0 and state[-1] == 0.0  # lane 1 on record, then cleared
    for legal in ([(-40.0, Y1), 0, 2, 4], [(-40.0, Y0), 1, 3, 5]):  # left lane + JL, right lane + JS
        values, state = drive_path(junction, [centre_path(junction, legal)])
        assert values.sum() == 0.0 and state.max() > 0.0 and state[-1] == 0.0
    # change right -> left before the entry gate, then JL: the left lane is on record
    changed, state = drive_path(
        junction, [centre_path(junction, [(-40.0, Y0), (-25.0, Y0), (-12.0, Y1), 0, 2, 4])]
    )
    assert changed.sum() == 0.0 and state.max() == 1.0 and state[-1] == 0.0


def test_turn_lane_entry_back_reads_the_lane_before_the_junction(junction):
    """With entry_back = 10 m the entry gates stand 10 m before the approach lanes' ends: a
    change into the turning lane finished 8 m before the junction pays -1, one finished 12 m
    before pays 0; with the default (gates at the ends) the late change pays 0."""
    end = junction.lanes.centerlines[0][-1].astype(np.float64)
    for back, x in ((0.0, 0.0), (10.0, -10.0), (100.0, -60.0)):  # lane 0 is 60 m long
        rec = turn_records(junction, back)[0]
        gate = rec[(rec[:, 6] == 0.0) & (rec[:, 7] == 0.0)][0]
        np.testing.assert_allclose(gate[:2] + 0.5 * gate[2:4], end + np.array([x, 0.0]), atol=1e-9)
        np.testing.assert_allclose(gate[4:6], [1.0, 0.0], atol=1e-12)
    assert (turn_records(junction, 0.0)[0] == turn_records(junction)[0]).all()
    late = centre_path(junction, [(-40.0, Y0), (-8.0, Y0), (-2.0, Y1), 2, 4])
    early = centre_path(junction, [(-40.0, Y0), (-25.0, Y0), (-12.0, Y1), (-2.0, Y1), 2, 4])
    assert drive_path(junction, [late])[0].sum() == 0.0
    values, state = drive_path(junction, [late], entry_back=10.0)
    assert values.sum() == -1.0 and state.max() == 2.0  # lane 1 on record at x = -10
    values, state = drive_path(junction, [early], entry_back=10.0)
    assert values.sum() == 0.0 and state.max() == 1.0
    with pytest.raises(ConfigError, match=r"entry_back must be a distance >= 0 .* got -5.0"):
        LinearReward({"turn_lane": {"weight": 1.0, "args": [0.7, -5.0]}}).bind([junction])


def test_turn_lane_decides_once_per_passage_and_forgets_at_spawn(junction):
    """Two junction passages in a row: the record is cleared by the first decision (else the
    second, which starts inside the junction with no entry, would pay for lane 0 -> JS), and
    by the world's restart (else the left-lane entry would make JS pay)."""
    inside_js = centre_path(junction, [(4.0, Y0), 3, 5])
    values, _ = drive_path(junction, [centre_path(junction, [(-40.0, Y1), 0, 2]), inside_js])
    assert values.sum() == 0.0
    entered = centre_path(junction, [(-40.0, Y1), (8.0, Y1)])  # entered from lane 0, no check yet
    values, state = drive_path(junction, [entered, inside_js], reset_before=(1,))
    assert state[len(entered) - 2] == 1.0 and values.sum() == 0.0
    # the control: without the restart the same drive pays
    values, _ = drive_path(junction, [entered, inside_js])
    assert values.sum() == -1.0


def test_turn_lane_refuses_more_entry_lanes_than_packed():
    ys = 3.5 * np.arange(5)
    lanes = [LaneElement(np.array([[-30.0, y], [0.0, y]]), 3.5, 14.0, successors=[5]) for y in ys]
    lanes.append(LaneElement(np.array([[0.0, 0.0], [20.0, 0.0]]), 3.5, 14.0, in_junction=True))
    fan_in = compile_map(MapElements(name="fan_in", source="tests/rewards/test_rules.py", lanes=lanes))
    with pytest.raises(ConfigError, match=r"junction lane 5 .* 5 entry lanes.*TURN_PREDECESSORS = 4"):
        LinearReward({"turn_lane": 1.0}).bind([fan_in])
    four = [LaneElement(ln.centerline, 3.5, 14.0, successors=[4]) for ln in lanes[:4]] + [lanes[5]]
    rec = turn_records(compile_map(MapElements(name="four", source="t", lanes=four)))[0]
    assert rec[-1, 6:].tolist() == [1.0, 4.0, 4.0, 0.0, 1.0, 2.0, 3.0] and len(rec) == 5


def test_hydra_builds_and_steps_turn_lane_on_the_bundled_town():
    from selfplaydrive.builder import build_env, compose

    env = build_env(compose("sim", ["+reward.terms.turn_lane=1.0"]), maps=[load_map("default")], num_worlds=2)
    assert env.term_names[-1] == "turn_lane" and env.reward.term_state_dim == 1
    env.reset(0)
    for _ in range(5):
        env.step(np.zeros((env.num_agents, 2), np.int64))
    assert np.isfinite(env.reward_terms).all()
