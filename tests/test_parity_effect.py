"""Parity by effect: every config key of the env-building groups changes what the kernels see.

tests/test_configs.py checks that each YAML key is a constructor argument; this file checks
that the argument is then used. For every leaf key of every shipped option of map, spawner,
physics, reward, obs, env (params included) and env/actions, and for the top-level seed, it
sets the key to another valid value, builds the env and compares the kernels' view
(`kernel_view`: the dims, the kernel parameters and action tables handed to `World`, the map
atlas, every buffer after the reset, i.e. the scenario and first observation, and every buffer
after a few steps of fixed random actions) with the unchanged config's view. A key that
changes none of it is silently ignored and fails the test, unless it is in `NO_KERNEL_EFFECT`
with the reason. New keys and options are picked up automatically: they must either change
the view or be added to that list.

The default options run in the default suite; the other options are marked slow.
"""

from __future__ import annotations

import hashlib
from contextlib import contextmanager
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from selfplaydrive.builder import build_env, build_maps, compose, valid_options

WORLDS = 2
STEPS = 8
DEFAULT_NPZ = str(resources.files("selfplaydrive").parent / "maps" / "default_town.npz")
SMALL_TOWN = "procedural:seed=1,size=400"

# (config group, option) -> extra overrides of its base config
CONTEXTS = {
    ("spawner", "paper"): [],
    ("physics", "friction"): [],
    ("physics", "bicycle"): [],
    ("physics", "pymunk"): [],
    ("physics", "jerk"): [],
    ("physics", "delta"): [],
    ("physics", "custom"): ["physics.model.target=selfplaydrive.physics:JerkBicycleModel"],
    ("reward", "paper"): [],
    ("reward", "eval"): [],
    ("obs", "paper"): [],
    ("obs", "partial"): [],
    ("obs", "custom"): ["obs.target=selfplaydrive.obs:PaperEncoder"],
    ("obs", "rules"): [],
    ("env", "default"): [],
    ("env/actions", "discrete"): [],
    ("env/actions", "continuous"): [],
    ("map", "default"): [],
    ("map", "procedural"): ["map.size=400"],  # a small town: each perturbation generates one
    ("map", "file"): [f"map.spec={DEFAULT_NPZ}"],
    ("map", "tartu"): [],
    ("map", "several"): [f"map.specs=[{DEFAULT_NPZ},'{SMALL_TOWN}']"],
}
DEFAULT_OPTIONS = {
    ("spawner", "paper"),
    ("physics", "friction"),
    ("reward", "paper"),
    ("obs", "paper"),
    ("env", "default"),
    ("env/actions", "discrete"),
}

# Keys that cannot change what the kernels see, each with the reason. Keyed by
# (group, option, dotted key); the test fails when an entry no longer names a key.
NO_KERNEL_EFFECT = {
    # thread count and profiling change how the kernels run, never their inputs or results
    # (tests/sim check bit-identical results at 1 and 2 threads)
    ("env", "default", "env.num_threads"): "parallelism only; results are bit-identical",
    ("env", "default", "env.profile"): "timing instrumentation only",
    # eval mode fixes each coefficient at the high end of its range, B = eval_center_bias and
    # D = eval_waypoint_radius; the lows and the mode mixtures only shape training draws
    **{
        ("reward", "eval", f"reward.{k}.low"): "eval mode uses each range's high end"
        for k in ("collision", "offroad", "red_light", "comfort", "center_high", "align_high")
    },
    **{
        ("reward", "eval", f"reward.{k}"): "eval mode uses the second mode's high end"
        for k in (
            "center_low.low",
            "center_low.high",
            "align_low.low",
            "align_low.high",
            "center_low_prob",
            "align_low_prob",
        )
    },
    # (the ends of waypoint_radius and center_bias and, in train mode, the eval values act
    # through the observed-coefficient scale: max |value| of either mode, RewardSettings)
    ("reward", "eval", "reward.waypoint_radius.low"): "eval mode uses eval_waypoint_radius",
    # the Tartu map needs $SELFPLAYDRIVE_SHARED_MAPS; its one key is load_map's spec, tested
    # under map=default and map=file
    ("map", "tartu", "map.spec"): "needs the shared maps; same key as map=file",
}

# Keys that act only in some situations, with the other keys set so that the situation occurs
# (in both the unchanged and the perturbed config).
KEY_SETTINGS = {
    # with every light off (all_off_prob = 0.5 per world) no initial state is drawn
    "spawner.lights.state_probs": {"spawner.lights.all_off_prob": 0.0},
    # the spawner draws candidates one at a time: the budget binds only in worlds that cannot
    # be filled (32 agents 40 m apart do not fit in a 200 m region)
    "spawner.candidates_per_agent": {"spawner.min_agent_distance": 40.0},
    # the first round's draws are one block: it shifts later draws only where the agents fill
    # before the block is used up (5 m apart: within about 40 candidates)
    "spawner.first_round_candidates": {"spawner.min_agent_distance": 5.0},
    # obs=partial: a false positive's size shows only when there are false positives, and the
    # encoder's seed only where something is drawn
    "obs.fp_length": {"obs.fp_rate": 1.0},
    "obs.fp_width": {"obs.fp_rate": 1.0},
    "obs.seed": {"obs.p_miss": 0.3},
}

# Perturbations for values the generic rule (bool: flip; number: x0.5 or x2; list of numbers:
# each x0.5 or x2) cannot make, or makes invalid. The first candidate that builds is used;
# candidates equal to the current value are skipped.
SPECIAL = {
    "map.spec": [SMALL_TOWN, DEFAULT_NPZ],
    "map.specs": [[SMALL_TOWN], [DEFAULT_NPZ]],
    "map.size": [500.0],
    "map.num_roundabouts": [0, 2],
    "spawner.static_count": [[3, 6]],
    "spawner.sizes": [
        {
            "_target_": "selfplaydrive.scenario.vehicles.VehicleSizeSampler",
            "categories": [["van", 6.0, 2.2, 1.0]],
        }
    ],
    "spawner.static_sizes": [
        {
            "_target_": "selfplaydrive.scenario.vehicles.VehicleSizeSampler",
            "categories": [["van", 6.0, 2.2, 1.0]],
        }
    ],
    "spawner.parked_share": [0.9],
    "spawner.max_shoulder": [0.2],  # the default town's road edges are within 1 m of the lanes
    "spawner.pedestrians.vehicle_clearance": [5.0],
    "spawner.lane_change_prob": [0.9],
    "spawner.min_region_lane_length": [100.0, 3000.0],
    "spawner.lights.state_probs": [[0.0, 1.0, 0.0, 0.0]],
    "spawner.lights.all_off_prob": [0.0, 1.0],
    "spawner.pedestrians.crosswalk_share": [0.0, 1.0],
    "reward.mode": ["train", "eval"],
    "reward.comfort.low": [0.005],
    "reward.center_low_prob": [0.0, 1.0],
    "reward.align_low_prob": [0.0, 1.0],
    "env.terminated_vehicle": ["remove", "obstacle"],
    "physics.model.target": ["selfplaydrive.physics:BicycleModel"],
    # a Python encoder defined in a file (a test module's): the swap the option is for
    "obs.target": [f"{Path(__file__).parent / 'obs' / 'test_obs_encoders.py'}:SpeedOnly"],
    "env.params.pedestrian_end": ["stand", "vanish"],
    "reward.terminate_threshold": [0.05, 1.0],
}


def _digest(value) -> str:
    a = np.ascontiguousarray(np.asarray(value))
    return hashlib.sha1(f"{a.dtype}{a.shape}".encode() + a.tobytes()).hexdigest()


def _actions(env, rng):
    space = env.action_space
    n = env.num_agents
    if hasattr(space, "nvec"):
        return rng.integers(0, np.asarray(space.nvec), size=(n, len(space.nvec)))
    return rng.uniform(space.low, space.high, size=(n, *space.shape)).astype(np.float32)


def kernel_view(env) -> dict[str, str]:
    """Digests of everything the kernels read: dims, kernel parameters (action tables
    included), the reward terms and weights, the map atlas, every buffer after the reset and
    after `STEPS` random steps."""
    view = {f"dims.{k}": repr(v) for k, v in vars(env.dims).items()}
    view.update({f"param.{k}": _digest(v) for k, v in env._kernel_params().items()})
    # the reward stage's component table (World's `terms` argument): addresses and weights
    view.update({f"reward.{c.name}": repr((c.term, c.weight)) for c in env.reward.columns})
    view.update({f"atlas.{k}": _digest(v) for k, v in env.atlas.items()})
    env.reset()
    view.update({f"reset.{k}": _digest(v) for k, v in env.buffers.items()})
    rng = np.random.default_rng(0)
    for _ in range(STEPS):
        env.step(_actions(env, rng))
    view.update({f"step.{k}": _digest(v) for k, v in env.buffers.items()})
    return view


def _leaves(cfg, node_path: str, skip: str | None = None):
    """(dotted key, value) of every leaf under `node_path`: lists are leaves, `_target_` and
    `_partial_` are not keys; interpolations to a whole node (spawner.hidden: ${physics.hidden})
    are tested at their source, scalar ones (env.seed: ${seed}) with their resolved value."""
    node = OmegaConf.select(cfg, node_path)
    for key in node.keys():
        key = str(key)
        path = f"{node_path}.{key}"
        if key in ("_target_", "_partial_") or path == skip:
            continue
        if OmegaConf.is_interpolation(node, key):
            value = OmegaConf.select(cfg, path)
            if OmegaConf.is_config(value):
                continue
            yield path, value
        elif OmegaConf.is_dict(node[key]):
            yield from _leaves(cfg, path, skip)
        else:
            value = node[key]
            yield path, OmegaConf.to_container(value) if OmegaConf.is_list(value) else value


def _scaled(value, factor):
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return max(1, int(value * factor)) if value else 1
    if isinstance(value, float):
        return value * factor if value else factor / 2
    if isinstance(value, list) and value and all(isinstance(v, (int, float)) for v in value):
        return [_scaled(v, factor) if v else v for v in value]
    return None


def candidates(key: str, value) -> list:
    out = SPECIAL.get(key) or [c for c in (_scaled(value, 0.5), _scaled(value, 2.0)) if c is not None]
    return [c for c in out if c != value]


def _raw(cfg, key: str):
    """The value of `key` as written (an interpolation stays a `${...}` string)."""
    parent, _, last = key.rpartition(".")
    node = (OmegaConf.select(cfg, parent) if parent else cfg)._get_node(last)
    return OmegaConf.to_container(node, resolve=False) if OmegaConf.is_config(node) else node._value()


@contextmanager
def _setting(cfg, values: dict):
    """Set dotted keys of `cfg` for the duration of the block, then restore them (cheaper
    than copying the config for each of some hundred perturbations)."""
    old = {k: _raw(cfg, k) for k in values}
    try:
        for k, v in values.items():
            OmegaConf.update(cfg, k, v, merge=False)
        yield cfg
    finally:
        for k, v in old.items():
            OmegaConf.update(cfg, k, v, merge=False)


def _build(group, cfg, maps):
    if group == "map":
        return build_env(cfg)
    return build_env(cfg, maps=maps)


def _base(group, option):
    return compose("sim", [f"{group}={option}", f"env.num_worlds={WORLDS}", *CONTEXTS[(group, option)]])


pytestmark = pytest.mark.filterwarnings("ignore:PaperSpawner placed:UserWarning")


@pytest.fixture(scope="module")
def default_maps():
    return build_maps(compose("sim").map)


def test_contexts_cover_every_option():
    groups = ("map", "spawner", "physics", "reward", "obs", "env", "env/actions")
    shipped = {(g, o) for g in groups for o in valid_options(g)}
    assert set(CONTEXTS) == shipped, "add the new option to CONTEXTS (and its base overrides)"


def check_context(group: str, option: str, maps) -> None:
    cfg = _base(group, option)
    node_path = group.replace("/", ".")
    skip = "env.actions" if group == "env" else None  # env/actions has its own contexts
    keys = list(_leaves(cfg, node_path, skip))
    if group == "env":
        keys.append(("seed", cfg.seed))  # the top-level seed every component follows
    allowed = {k for (g, o, k) in NO_KERNEL_EFFECT if (g, o) == (group, option)}
    assert allowed <= {k for k, _ in keys}, f"NO_KERNEL_EFFECT names keys that no longer exist: {allowed}"
    if group == "map" and option == "tartu":
        assert [k for k, _ in keys] == ["map.spec"]
        return
    base = kernel_view(_build(group, cfg, maps))
    assert base == kernel_view(_build(group, cfg, maps)), "the kernel view must be deterministic"
    snapshot = OmegaConf.to_container(cfg, resolve=False)
    ignored, untested, effective = [], [], []
    for key, value in keys:
        with _setting(cfg, KEY_SETTINGS.get(key, {})):
            key_base = kernel_view(_build(group, cfg, maps)) if key in KEY_SETTINGS else base
            changed, errors = None, []
            for new in candidates(key, value):
                try:
                    with _setting(cfg, {key: new}):
                        view = kernel_view(_build(group, cfg, maps))
                except Exception as exc:  # an invalid candidate: try the next one
                    errors.append(f"{new!r}: {type(exc).__name__}: {str(exc)[:120]}")
                    continue
                changed = sorted(k for k in key_base.keys() | view.keys() if key_base.get(k) != view.get(k))
                if changed:
                    break
        if key in allowed:
            if changed:  # the allow-list must stay true too
                effective.append(f"{key} (changes {changed[:3]})")
        elif changed is None:
            untested.append(f"{key}={value!r}: no valid perturbation ({'; '.join(errors) or 'none'})")
        elif not changed:
            ignored.append(f"{key}={value!r}")
    assert OmegaConf.to_container(cfg, resolve=False) == snapshot  # every change was undone
    assert not untested, f"{group}={option}: add a SPECIAL perturbation for: {untested}"
    assert not effective, f"{group}={option}: remove from NO_KERNEL_EFFECT: {effective}"
    assert not ignored, (
        f"{group}={option}: these keys change nothing the kernels see (wire them up, or add them "
        f"to NO_KERNEL_EFFECT with the reason): {ignored}"
    )


@pytest.mark.parametrize("group,option", sorted(DEFAULT_OPTIONS))
def test_every_key_of_the_default_options_reaches_the_kernels(group, option, default_maps):
    check_context(group, option, default_maps)


@pytest.mark.slow
@pytest.mark.parametrize("group,option", sorted(set(CONTEXTS) - DEFAULT_OPTIONS))
def test_every_key_of_the_other_options_reaches_the_kernels(group, option, default_maps):
    check_context(group, option, default_maps)


def test_an_ignored_key_is_caught(default_maps, monkeypatch):
    """The check can fail: an observation config that drops `radius` is reported."""
    from selfplaydrive.obs.config import ObsConfig

    init = ObsConfig.__init__

    def dropping(self, *args, **kwargs):
        kwargs.pop("radius", None)
        init(self, *args, **kwargs)

    monkeypatch.setattr(ObsConfig, "__init__", dropping)
    with pytest.raises(AssertionError, match=r"change nothing the kernels see.*obs\.radius=100\.0"):
        check_context("obs", "paper", default_maps)
