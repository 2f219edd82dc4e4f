"""Physics models as components (paper section 2.6; selfplaydrive_abi.h `sd_physics_fn`):
each kernel against its NumPy reference on random states, hand-computed cases, the delta
model's inverse, action spaces, the checker and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import FixedSpawner, make_scenario

from selfplaydrive.errors import ConfigError
from selfplaydrive.physics import (
    BicycleModel,
    DeltaModel,
    FrictionBicycleModel,
    JerkBicycleModel,
    KernelPhysics,
    load_physics,
)
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.actions import BoxActions, ContinuousActions, DiscreteActions
from selfplaydrive.testing.check_physics import PhysicsCheckError, check_physics
from selfplaydrive.testing.physics_reference import delta_step, jerk_step
from selfplaydrive.testing.reference import bicycle_step


def random_state_env(model, rng, actions=None, worlds=3):
    """An env whose agent slots hold random states (a third inactive), ready for the physics
    stage alone (`World.physics_stage`)."""
    from selfplaydrive.builder import make_env

    env = make_env("default", num_worlds=worlds, seed=0, physics=model, actions=actions)
    env.reset(seed=0)
    b, n = env.buffers, env.num_agents
    b["x"][:] = rng.uniform(-100, 100, n)
    b["y"][:] = rng.uniform(-100, 100, n)
    b["heading"][:] = rng.uniform(-math.pi, math.pi, n)
    b["hcos"][:] = np.cos(b["heading"])
    b["hsin"][:] = np.sin(b["heading"])
    b["speed"][:] = rng.uniform(0, 30, n)
    b["length"][:] = rng.uniform(3.5, 6, n)
    b["hidden"][:] = np.stack(
        [rng.uniform(0.7, 1.3, n), rng.uniform(0.9, 1.1, n), rng.uniform(0.9, 1.1, n)], 1
    )
    b["active"][:] = rng.random(n) < 0.67
    return env


def as_f32(d):
    return {k: np.asarray(v, np.float32) for k, v in d.items()}


def compare(env, ref, active, tol=2e-4):
    b = env.buffers
    for k in ("x", "y", "speed", "a_long", "a_lat"):
        np.testing.assert_allclose(b[k][active], ref[k][active], rtol=tol, atol=tol * 10, err_msg=k)
    dh = np.angle(np.exp(1j * (b["heading"][active] - ref["heading"][active])))
    np.testing.assert_allclose(dh, 0.0, atol=1e-4)
    np.testing.assert_allclose(b["hcos"][active], np.cos(b["heading"][active]), atol=1e-6)


# --------------------------------------------------------------------- kernels vs references
@pytest.mark.parametrize("friction", [False, True])
@pytest.mark.parametrize("discrete", [True, False])
def test_bicycle_components_match_reference(friction, discrete):
    rng = np.random.default_rng(3)
    model = FrictionBicycleModel() if friction else BicycleModel()
    actions = DiscreteActions() if discrete else ContinuousActions()
    env = random_state_env(model, rng, actions)
    b, n = env.buffers, env.num_agents
    if discrete:
        b["act_i"][:] = np.stack([rng.integers(0, 7, n), rng.integers(0, 13, n)], 1)
        acc, steer = actions.accel[b["act_i"][:, 0]], actions.steer[b["act_i"][:, 1]]
    else:
        b["act_f"][:] = rng.uniform(-1, 1, (n, 2)) * actions.high
        acc, steer = b["act_f"][:, 0], b["act_f"][:, 1]
    before = {k: b[k].copy() for k in ("x", "y", "heading", "speed", "length", "hidden", "active")}
    ref = bicycle_step(
        before["x"], before["y"], before["heading"], before["speed"], before["length"], acc, steer,
        before["hidden"].astype(np.float64), friction=friction,
    )  # fmt: skip
    env._world.physics_stage(1)
    active = before["active"].astype(bool)
    compare(env, ref, active)
    np.testing.assert_array_equal(b["px"], before["x"])
    assert np.all(b["a_long"][~active] == 0) and np.all(b["x"][~active] == before["x"][~active])


def test_jerk_component_matches_reference():
    rng = np.random.default_rng(4)
    model = JerkBicycleModel()
    env = random_state_env(model, rng)
    b, n, t = env.buffers, env.num_agents, env.action_table
    b["phys_state"][:] = np.stack([rng.uniform(-4, 4, n), rng.uniform(-0.6, 0.6, n)], 1)
    b["act_i"][:] = np.stack([rng.integers(0, len(t.accel), n), rng.integers(0, len(t.steer), n)], 1)
    before = {
        k: b[k].copy() for k in ("x", "y", "heading", "speed", "length", "hidden", "active", "phys_state")
    }
    ref = jerk_step(
        before["x"], before["y"], before["heading"], before["speed"], before["length"],
        before["phys_state"][:, 0], before["phys_state"][:, 1], t.accel[b["act_i"][:, 0]],
        t.steer[b["act_i"][:, 1]], before["hidden"].astype(np.float64),
    )  # fmt: skip
    env._world.physics_stage(1)
    active = before["active"].astype(bool)
    compare(env, ref, active)
    np.testing.assert_allclose(b["phys_state"][active, 0], ref["accel"][active], atol=1e-6)
    np.testing.assert_allclose(b["phys_state"][active, 1], ref["steer"][active], atol=1e-6)
    np.testing.assert_array_equal(b["phys_state"][~active], before["phys_state"][~active])


def test_delta_component_matches_reference():
    rng = np.random.default_rng(5)
    model = DeltaModel(max_backward=1.0, max_forward=5.0)  # some steps too long for max_speed
    env = random_state_env(model, rng)
    b, n, t = env.buffers, env.num_agents, env.action_table
    b["act_f"][:] = t.low + (t.high - t.low) * rng.random((n, 3)).astype(np.float32)
    before = {k: b[k].copy() for k in ("x", "y", "heading", "speed", "active", "act_f")}
    a = before["act_f"]
    ref = delta_step(before["x"], before["y"], before["heading"], before["speed"], a[:, 0], a[:, 1], a[:, 2])
    env._world.physics_stage(1)
    compare(env, ref, before["active"].astype(bool))


# ------------------------------------------------------------------------ hand-computed cases
def drive(road_map, model, actions, steps, agent=None):
    """One agent on the straight map driven by the same action every step; (steps, 6) track
    of x, y, heading, speed, a_long, a_lat (and the env)."""
    agent = agent or dict(xy=(-50.0, -2.0), speed=10.0)
    env = VecEnv(road_map, FixedSpawner(make_scenario([agent], episode_length=1000.0)), 1, physics=model)
    env.reset(0)
    acts = np.tile(np.asarray(actions), (env.num_agents, 1))
    track = []
    for _ in range(steps):
        env.step(acts)
        b = env.buffers
        track.append([b[k][0] for k in ("x", "y", "heading", "speed", "a_long", "a_lat")])
    return np.array(track, np.float64), env


def test_jerk_zero_change_keeps_10ms_for_2s_20m(straight_map):
    t, env = drive(straight_map, JerkBicycleModel(), (3, 4), 20)  # d_accel 0, d_steer 0
    assert t[-1, 0] == pytest.approx(-30.0, abs=1e-3) and t[-1, 3] == pytest.approx(10.0)
    assert env.buffers["phys_state"][0].tolist() == [0.0, 0.0]  # 0 at spawn, unchanged


def test_jerk_ramps_acceleration_then_clamps(straight_map):
    # +0.5 m/s^2 per step: commanded 0.5, 1.0, 1.5, 2.0 -> speed 10 + 0.1 * 5.0 = 10.5 m/s
    model = JerkBicycleModel(friction=False)
    t, env = drive(straight_map, model, (4, 4), 4)
    np.testing.assert_allclose(t[:, 4], [0.5, 1.0, 1.5, 2.0], atol=1e-4)
    assert t[-1, 3] == pytest.approx(10.5, abs=1e-5)
    # +2 m/s^2 per step reaches max_accel 4 after 2 steps and stays there
    t, env = drive(straight_map, model, (6, 4), 5)
    np.testing.assert_allclose(t[:, 4], [2.0, 4.0, 4.0, 4.0, 4.0], atol=1e-4)
    assert env.buffers["phys_state"][0, 0] == pytest.approx(4.0)


def test_jerk_steering_accumulates_and_clamps(straight_map):
    model = JerkBicycleModel(max_steer_deg=10.0)
    _, env = drive(straight_map, model, (3, 8), 3)  # +8 deg per step, bound 10 deg
    assert env.buffers["phys_state"][0, 1] == pytest.approx(math.radians(10.0), abs=1e-6)


def test_jerk_state_resets_to_zero_at_spawn(straight_map):
    _, env = drive(straight_map, JerkBicycleModel(), (6, 8), 3)
    assert np.any(env.buffers["phys_state"][0] != 0)
    env.reset(seed=1)
    assert np.all(env.buffers["phys_state"] == 0)


def test_delta_moves_1m_per_step_for_20_steps(straight_map):
    t, _ = drive(straight_map, DeltaModel(), np.array([1.0, 0.0, 0.0], np.float32), 20)
    assert t[-1, 0] == pytest.approx(-30.0, abs=1e-4) and t[-1, 1] == pytest.approx(-2.0, abs=1e-6)
    assert t[-1, 3] == pytest.approx(10.0, abs=1e-5)  # 1 m per 0.1 s


def test_delta_turns_and_moves_in_the_agent_frame(straight_map):
    # heading 0.1 rad per step for 5 steps: 0.5 rad; then 1 m "forward" is along 0.5 rad
    act = np.array([0.0, 0.0, 0.1], np.float32)
    t, env = drive(straight_map, DeltaModel(), act, 5, agent=dict(xy=(0.0, 0.0), speed=0.0))
    assert t[-1, 2] == pytest.approx(0.5, abs=1e-5) and t[-1, 3] == 0.0
    env.step(np.array([[1.0, 0.5, 0.0]] * env.num_agents, np.float32))
    b = env.buffers
    assert b["x"][0] == pytest.approx(math.cos(0.5) - 0.5 * math.sin(0.5), abs=1e-5)
    assert b["y"][0] == pytest.approx(math.sin(0.5) + 0.5 * math.cos(0.5), abs=1e-5)


# ---------------------------------------------------------------------------- delta inverse
def test_delta_inverse_round_trip_state_action_state():
    """state -> action (inverse) -> state (the kernel) on random pairs of states."""
    rng = np.random.default_rng(6)
    model = DeltaModel(max_backward=1.0)
    env = random_state_env(model, rng)
    b, n, t = env.buffers, env.num_agents, env.action_table
    b["active"][:] = 1
    x0, y0, h0 = b["x"].copy(), b["y"].copy(), b["heading"].copy()
    # targets reachable in one step: a random action from each state, in float64
    a = t.low + (t.high - t.low) * rng.random((n, 3))
    tgt = delta_step(x0, y0, h0, b["speed"], a[:, 0], a[:, 1], a[:, 2])
    act = DeltaModel.inverse(x0, y0, h0, tgt["x"], tgt["y"], tgt["heading"])
    np.testing.assert_allclose(act, a, atol=2e-5)
    b["act_f"][:] = np.clip(act, t.low, t.high)
    env._world.physics_stage(1)
    np.testing.assert_allclose(b["x"], tgt["x"], atol=1e-4)
    np.testing.assert_allclose(b["y"], tgt["y"], atol=1e-4)
    np.testing.assert_allclose(np.angle(np.exp(1j * (b["heading"] - tgt["heading"]))), 0.0, atol=1e-5)
    # and action -> state -> action: the recorded motion gives the action back
    back = DeltaModel.inverse(x0, y0, h0, b["x"], b["y"], b["heading"])
    np.testing.assert_allclose(back, b["act_f"], atol=1e-4)


def test_delta_inverse_hand_case():
    act = DeltaModel.inverse([1.0], [1.0], [math.pi / 2], [1.0], [3.0], [-math.pi + 0.1])
    np.testing.assert_allclose(act[0], [2.0, 0.0, -math.pi + 0.1 - math.pi / 2 + 2 * math.pi], atol=1e-6)


# ----------------------------------------------------------------------------- action spaces
def test_models_declare_their_action_spaces():
    assert BicycleModel().actions is None  # the env's (accel, steer) actions
    jerk = JerkBicycleModel()
    assert jerk.actions is not None and jerk.actions.names == ("d_accel", "d_steer")
    assert jerk.actions.space.nvec.tolist() == [7, 9]
    delta = DeltaModel()
    assert isinstance(delta.actions, BoxActions) and delta.actions.names == ("dx", "dy", "dyaw")
    assert delta.actions.units == ("m", "m", "rad") and delta.actions.space.shape == (3,)
    assert "d_accel [m/s^2 per step]" in jerk.describe() and "state: accel, steer" in jerk.describe()


def test_env_takes_the_models_action_space(straight_map):
    spawner = FixedSpawner(make_scenario([dict(xy=(0.0, 0.0), speed=5.0)]))
    env = VecEnv(straight_map, spawner, 2, physics=DeltaModel())
    assert env.action_space.shape == (3,) and env.buffers["act_f"].shape == (env.num_agents, 3)
    with pytest.raises(
        ValueError, match=r"actions\[0, 0\] = -1.0: expected a value in \[0.0, 3.5\] m \(dx\)"
    ):
        env.step(np.array([[-1.0, 0.0, 0.0]] * env.num_agents, np.float32))
    with pytest.raises(ConfigError, match="physics 'delta': reads continuous actions, got discrete"):
        VecEnv(straight_map, spawner, 2, physics=DeltaModel(), actions=DiscreteActions())
    with pytest.raises(ConfigError, match="physics 'jerk': expects 2 action columns"):
        VecEnv(straight_map, spawner, 2, physics=JerkBicycleModel(), actions=DeltaModel().actions)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: JerkBicycleModel(max_accel=-1), r"physics.max_accel: expected a value in \(0.0, 100.0\]"),
        (lambda: JerkBicycleModel(steer_deltas_deg=[]), "steer_deg: expected a non-empty"),
        (lambda: DeltaModel(max_yaw_deg=0), "physics.max_yaw_deg"),
        (lambda: DeltaModel(max_backward=-1), "physics.max_backward"),
        (lambda: KernelPhysics("m", 0), "address must be a positive integer, got 0"),
        (lambda: KernelPhysics("m", 1, args=(math.nan,)), "args must be finite"),
        (lambda: KernelPhysics("m", 1, state_dim=2, state_names=("a",)), "expected 2 names"),
        (lambda: KernelPhysics("m", 1, accepts=("tables",)), "accepts must name"),
        (lambda: KernelPhysics.from_numba("m", print), "expected a numba cfunc"),
        (lambda: load_physics("nomodule"), "expected 'module:attr'"),
        (lambda: load_physics("selfplaydrive.physics:Nope"), "has no 'Nope'"),
        (lambda: load_physics("/no/such/file.py:x"), "no file"),
        (lambda: load_physics("math:pi"), "expected a physics model"),
    ],
)
def test_bad_physics_input_names_key_and_value(make, match):
    with pytest.raises(ConfigError, match=match):
        make()


def test_load_physics_by_module_path():
    model = load_physics("selfplaydrive.physics:JerkBicycleModel", max_accel=3.0)
    assert isinstance(model, JerkBicycleModel) and model.max_accel == 3.0


# -------------------------------------------------------------------------------- the checker
@pytest.mark.parametrize(
    "model", [BicycleModel(), FrictionBicycleModel(), JerkBicycleModel(), DeltaModel(max_backward=0.5)]
)
def test_shipped_models_pass_the_checker(model):
    report = check_physics(model, rounds=6)
    assert report["agent_steps"] > 0 and report["max_speed_seen"] <= model.max_speed


def test_pymunk_model_passes_the_checker():
    pytest.importorskip("pymunk")
    from selfplaydrive.physics import PymunkModel

    check_physics(PymunkModel(), rounds=3, num_worlds=2)


def test_checker_catches_a_model_writing_outside_its_outputs():
    numba = pytest.importorskip("numba")
    from selfplaydrive.physics.numba_abi import SIGNATURE, SIM, f32_ptr, int_field

    @numba.cfunc(SIGNATURE)
    def rude(sim, prm, args, w, state):  # writes the reward buffer
        A = int_field(sim, SIM.A)
        reward = f32_ptr(sim, SIM.reward)
        for a in range(A):
            reward[w * A + a] = np.float32(1.0)

    with pytest.raises(PhysicsCheckError, match="wrote buffer 'reward'"):
        check_physics(KernelPhysics.from_numba("rude", rude), rounds=1)

    @numba.cfunc(SIGNATURE)
    def racer(sim, prm, args, w, state):  # speed above max_speed
        A = int_field(sim, SIM.A)
        speed = f32_ptr(sim, SIM.speed)
        for a in range(A):
            speed[w * A + a] = np.float32(99.0)

    with pytest.raises(PhysicsCheckError, match=r"speed\[\d+\] = 99.0, expected a value in \[0, 40.0\]"):
        check_physics(KernelPhysics.from_numba("racer", racer), rounds=1)

    @numba.cfunc(SIGNATURE)
    def frozen_cos(sim, prm, args, w, state):  # turns without updating hcos / hsin
        A = int_field(sim, SIM.A)
        heading = f32_ptr(sim, SIM.heading)
        for a in range(A):
            heading[w * A + a] = np.float32(0.5)

    with pytest.raises(PhysicsCheckError):
        check_physics(KernelPhysics.from_numba("frozen_cos", frozen_cos), rounds=1)


# ------------------------------------------------------------------------ the three forms
def test_cython_form_via_capi_gives_the_same_rollout():
    """A Cython module's exported function (here the library's own bicycle, through
    `__pyx_capi__` as a user's module is read) drives the same rollout as the built-in model."""
    from selfplaydrive._sim import physics as kernels
    from selfplaydrive.builder import make_env
    from selfplaydrive.testing.digest import rollout_digest

    ref = BicycleModel()
    model = KernelPhysics.from_cython("bicycle_capi", kernels, "phys_bicycle", args=ref.args())
    assert model.form == "cython" and model.address() == ref.address()
    digests = [rollout_digest(make_env("default", num_worlds=2, physics=m), steps=30) for m in (ref, model)]
    assert digests[0] == digests[1]
    with pytest.raises(ConfigError, match="exports no cdef function 'nope'"):
        KernelPhysics.from_cython("x", kernels, "nope")
    from selfplaydrive._sim import reward

    with pytest.raises(ConfigError, match=r"the function's signature is .*expected"):
        KernelPhysics.from_capsule("x", reward.__pyx_capi__["term_collision"])


def test_numba_form_with_state_and_args():
    """A numba model that owns per-agent state: counts the steps each slot was active (state
    column 0) and moves straight on at its speed; args[0] scales nothing but is passed."""
    numba = pytest.importorskip("numba")
    from selfplaydrive.physics.numba_abi import (
        PARAMS,
        SIGNATURE,
        SIM,
        f32_ptr,
        float_field,
        int_field,
        u8_ptr,
    )

    @numba.cfunc(SIGNATURE)
    def coast(sim, prm, args, w, state):
        A, dt = int_field(sim, SIM.A), float_field(prm, PARAMS.dt)
        x, y = f32_ptr(sim, SIM.x), f32_ptr(sim, SIM.y)
        c, s, v = f32_ptr(sim, SIM.hcos), f32_ptr(sim, SIM.hsin), f32_ptr(sim, SIM.speed)
        active = u8_ptr(sim, SIM.active)
        for a in range(A):
            i = w * A + a
            if active[i]:
                x[i] += v[i] * c[i] * dt
                y[i] += v[i] * s[i] * dt
                state[a] += args[0]

    model = KernelPhysics.from_numba("coast", coast, args=(1.0,), state_dim=1, state_names=("steps",))
    check_physics(model, rounds=3)
    from selfplaydrive.builder import make_env

    env = make_env("default", num_worlds=2, physics=model)
    env.reset(seed=0)
    on = env.masks.copy()
    for _ in range(5):
        env.step(np.zeros((env.num_agents, 2), np.int64))
    on &= env.masks
    assert np.all(env.buffers["phys_state"][on, 0] == 5.0)


@pytest.mark.parametrize("model", [JerkBicycleModel(), DeltaModel(max_backward=0.5)], ids=["jerk", "delta"])
def test_new_models_same_seed_same_rollout_at_1_and_2_threads(model):
    from selfplaydrive.builder import make_env
    from selfplaydrive.testing.digest import rollout_digest

    digests = {
        rollout_digest(make_env("default", num_worlds=4, physics=model, num_threads=t), 120) for t in (1, 2)
    }
    assert len(digests) == 1


def test_env_refuses_an_object_that_is_no_physics_model(straight_map):
    spawner = FixedSpawner(make_scenario([dict(xy=(0.0, 0.0), speed=5.0)]))
    with pytest.raises(ValueError, match=r"physics: expected a physics model .* lacks \['physics_slot'"):
        VecEnv(straight_map, spawner, 1, physics=object())
