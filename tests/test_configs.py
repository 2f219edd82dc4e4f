"""Hydra configs: every option of every group composes and instantiates; YAML keys are exactly
the constructor arguments (no key silently ignored); bad keys and options list the choices."""

from __future__ import annotations

import inspect
from importlib import resources

import numpy as np
import pytest
from hydra.utils import get_object
from omegaconf import OmegaConf

from selfplaydrive.builder import build_env, build_maps, compose, valid_options
from selfplaydrive.errors import ConfigError

# arguments the builder passes as objects built from other groups, never from YAML
BUILDER_ARGS = {
    "selfplaydrive.sim.vec_env.VecEnv": {"maps", "spawner", "physics", "obs", "reward_hooks", "obs_hooks"},
}
ENV_GROUPS = ("spawner", "physics", "reward", "obs", "env", "env/actions")


def _target_nodes(node, path=""):
    """Yield (dotted path, node) of every config node with a `_target_`."""
    if OmegaConf.is_dict(node):
        if "_target_" in node:
            yield path, node
        for k in node.keys():
            yield from _target_nodes(node[k], f"{path}.{k}" if path else str(k))


def _group_files(group: str) -> list[str]:
    return valid_options(group)


@pytest.mark.parametrize("group", (*ENV_GROUPS, "map"))
def test_every_group_has_options(group):
    assert _group_files(group), f"config group {group} ships no option"


@pytest.mark.parametrize(
    "override",
    [f"{g}={o}" for g in ENV_GROUPS for o in valid_options(g)],
)
def test_every_env_option_builds_and_steps(override):
    cfg = compose("sim", [override, "env.num_worlds=1"])
    env = build_env(cfg)
    obs = env.reset(seed=1)
    assert np.all(np.isfinite(obs))
    env.action_space.seed(0)
    env.step(np.stack([env.action_space.sample() for _ in range(env.num_agents)]))
    assert np.all(np.isfinite(env.rewards))


def test_map_options_instantiate():
    cfg = compose("sim", ["map=procedural", "map.size=500", "map.num_roundabouts=0"])
    (road_map,) = build_maps(cfg.map)
    assert road_map.vehicle_lane_km() > 1.0
    default_npz = resources.files("selfplaydrive").parent / "maps" / "default_town.npz"
    cfg = compose("sim", ["map=file", f"map.spec={default_npz}"])
    assert build_maps(cfg.map)[0].name == "default_town"


def test_tartu_map_option(monkeypatch):
    from sharedmaps import shared_map

    path = shared_map("tartu_lanelet2/tartu_demo_l.osm")
    monkeypatch.setenv("SELFPLAYDRIVE_SHARED_MAPS", str(path.parents[1]))
    (road_map,) = build_maps(compose("sim", ["map=tartu"]).map)
    assert abs(road_map.vehicle_lane_km() - 15.99) < 0.02 * 15.99


@pytest.mark.parametrize("override", [f"{g}={o}" for g in ENV_GROUPS for o in valid_options(g)])
def test_yaml_keys_are_constructor_arguments(override):
    """Parity: every `_target_` node lists exactly its constructor's arguments."""
    cfg = compose("sim", [override])
    for path, node in _target_nodes(cfg):
        target = node["_target_"]
        params = inspect.signature(get_object(target)).parameters
        accepted = {n for n, p in params.items() if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)}
        keys = {str(k) for k in node.keys()} - {"_target_", "_partial_", "_convert_"}
        unknown = keys - accepted
        assert not unknown, f"{path} ({target}): keys {unknown} are not constructor arguments"
        if target.startswith("selfplaydrive.maps.loader") or path == "":
            continue  # load_map takes loader kwargs; maps are checked by the loaders' own tests
        missing = accepted - keys - BUILDER_ARGS.get(target, set())
        assert not missing, f"{path} ({target}): constructor arguments {missing} have no config key"


def test_unknown_option_lists_choices():
    with pytest.raises(ConfigError, match=r"bicycle.*friction"):
        compose("sim", ["physics=warp_drive"])


def test_unknown_key_lists_valid_keys():
    with pytest.raises(ConfigError, match=r"valid keys under 'reward':.*collision"):
        compose("sim", ["reward.colision.high=0.5"])


def test_sweep_syntax_reaches_the_sampler():
    """`reward.collision.high=0.5` (the documented sweep key) changes the drawn coefficients."""
    from selfplaydrive.builder import instantiate

    lo = instantiate(compose("sim", ["reward.collision.high=0.5"]).reward)
    hi = instantiate(compose("sim", ["reward.collision.high=1.0"]).reward)
    assert lo.collision == (0.0, 0.5) and hi.collision == (0.0, 1.0)
    spawner = instantiate(compose("sim", ["reward.collision.high=0.5"]).spawner)
    assert spawner.conditioning.collision == (0.0, 0.5)


def test_component_catalogue_is_current():
    """docs/components.md is generated from the shipped configs; regenerate it when they change."""
    from pathlib import Path

    from selfplaydrive.catalogue import catalogue

    page = Path(__file__).resolve().parents[1] / "docs" / "components.md"
    assert page.read_text() == catalogue(), "run: python -m selfplaydrive.catalogue > docs/components.md"
