"""Hydra configs: every option of every group composes and instantiates (env groups, model,
trainer, logger, eval, experiment, and the render/bench primary configs); YAML keys are
exactly the constructor arguments; bad keys and options list the choices. That every key then
changes what the kernels see is tests/test_parity_effect.py."""

from __future__ import annotations

import inspect
from importlib import resources

import numpy as np
import pytest
from hydra.utils import get_object
from omegaconf import OmegaConf

from selfplaydrive.builder import build_env, build_maps, build_spawner, compose, valid_options
from selfplaydrive.errors import ConfigError, MapError
from selfplaydrive.sim.reward_settings import CONSTANTS

# arguments the builder or the trainer passes at run time, never from YAML
_LOGGER_ARGS = {"run_dir", "total_updates", "progress_bar", "enabled", "initial"}
BUILDER_ARGS = {
    # `reward` (the LinearReward) comes from the reward group's `terms` key
    "selfplaydrive.sim.vec_env.VecEnv": {
        "maps",
        "spawner",
        "physics",
        "obs",
        "reward",
        "reward_hooks",
        "obs_hooks",
    },
    # the reward group's constants and coefficient scale (builder.build_params)
    "selfplaydrive.sim.params.SimParams": {*CONSTANTS, "coeff_scale"},
    # the reward group's conditioning sampler (builder.build_spawner)
    "selfplaydrive.scenario.spawner.PaperSpawner": {"conditioning"},
    "selfplaydrive.trainers.ppo.logging.TensorBoardLogger": _LOGGER_ARGS,
    "selfplaydrive.trainers.ppo.logging.JsonlLogger": _LOGGER_ARGS,
    "selfplaydrive.trainers.ppo.logging.ProgressLogger": _LOGGER_ARGS,
}
ENV_GROUPS = ("spawner", "physics", "reward", "obs", "env", "env/actions")
TRAIN_GROUPS = ("model", "trainer", "logger")
PRIMARY = ("sim", "train", "eval", "render", "bench")


def _target_nodes(node, path=""):
    """Yield (dotted path, node) of every config node with a `_target_`."""
    if OmegaConf.is_dict(node):
        if "_target_" in node:
            yield path, node
        for k in node.keys():
            if not OmegaConf.is_missing(node, k):  # ??? values (model.layout) the builder fills
                yield from _target_nodes(node[k], f"{path}.{k}" if path else str(k))


def _group_files(group: str) -> list[str]:
    return valid_options(group)


@pytest.mark.parametrize("group", (*ENV_GROUPS, "map", *TRAIN_GROUPS, "eval", "experiment"))
def test_every_group_has_options(group):
    assert _group_files(group), f"config group {group} ships no option"


@pytest.mark.parametrize(
    "override",
    [f"{g}={o}" for g in ENV_GROUPS for o in valid_options(g)],
)
def test_every_env_option_builds_and_steps(override):
    # physics=custom / obs=custom name a component defined elsewhere (the target is mandatory)
    extra = {
        "physics=custom": ["physics.model.target=selfplaydrive.physics:JerkBicycleModel"],
        "obs=custom": ["obs.target=selfplaydrive.obs:PartialObsEncoder"],
    }
    cfg = compose("sim", [override, "env.num_worlds=1", *extra.get(override, [])])
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


def test_several_maps_option():
    """map=several: one env over the bundled town and a procedural town; each world draws one."""
    cfg = compose(
        "sim",
        ["map=several", "map.specs=[default,'procedural:seed=3,size=500,num_roundabouts=0,shoulder=0.0']"],
    )
    maps = build_maps(cfg.map)
    assert [m.name for m in maps] == ["default_town", "town_3"]
    env = build_env(compose("sim", ["env.num_worlds=8"]), maps=maps)
    env.reset(seed=0)
    assert set(env.state.map_id.tolist()) == {0, 1}  # 8 worlds draw both maps
    with pytest.raises(MapError, match=r"map.specs: expected a non-empty list .* got 'default'"):
        build_maps(compose("sim", ["map=several", "map.specs=default"]).map)
    with pytest.raises(MapError, match="got \\[\\]"):
        build_maps(compose("sim", ["map=several", "map.specs=[]"]).map)


def test_tartu_map_option(monkeypatch):
    from sharedmaps import shared_map

    path = shared_map("tartu_lanelet2/tartu_demo_l.osm")
    monkeypatch.setenv("SELFPLAYDRIVE_SHARED_MAPS", str(path.parents[1]))
    (road_map,) = build_maps(compose("sim", ["map=tartu"]).map)
    assert abs(road_map.vehicle_lane_km() - 15.99) < 0.02 * 15.99


@pytest.mark.parametrize(
    "config,override",
    [("sim", f"{g}={o}") for g in ENV_GROUPS for o in valid_options(g)]
    + [("train", f"{g}={o}") for g in TRAIN_GROUPS for o in valid_options(g)],
)
def test_yaml_keys_are_constructor_arguments(config, override):
    """Parity: every `_target_` node lists exactly its constructor's arguments."""
    cfg = compose(config, [override])
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


@pytest.mark.parametrize(
    "config,override,listed",
    [
        ("train", "logger=nope", "valid options for 'logger': jsonl, none, tensorboard"),
        ("train", "logger.subdirr=x", "valid keys under 'logger': _partial_, _target_, flush_secs, subdir"),
        ("train", "model=nope", "valid options for 'model': deepsets, deepsets_laptop, deepsets_small"),
        ("train", "trainer=nope", "valid options for 'trainer': ppo, ppo_laptop, sb3"),
        ("train", "experiment=nope", "valid options for 'experiment': ablate_collision, ablate_friction"),
        ("eval", "eval=nope", "valid options for 'eval': diversity, paper, quick"),
        ("render", "drivr=random", "valid keys under '<root>': deterministic, driver, env"),
        (
            "render",
            "physics=nope",
            "valid options for 'physics': bicycle, custom, delta, friction, jerk, pymunk",
        ),
        ("bench", "thread=[1]", "valid keys under '<root>':.*stages, steps, threads, warmup"),
        ("bench", "env/actions=nope", "valid options for 'env/actions': continuous, discrete"),
    ],
)
def test_unknown_option_or_key_of_every_config_lists_choices(config, override, listed):
    with pytest.raises(ConfigError, match=listed):
        compose(config, [override])


def test_unknown_key_lists_valid_keys():
    with pytest.raises(ConfigError, match=r"valid keys under 'reward':.*collision"):
        compose("sim", ["reward.colision.high=0.5"])


def test_sweep_syntax_reaches_the_sampler():
    """`reward.collision.high=0.5` (the documented sweep key) changes the drawn coefficients."""
    from selfplaydrive.builder import instantiate

    lo = instantiate(compose("sim", ["reward.collision.high=0.5"]).reward).conditioning
    hi = instantiate(compose("sim", ["reward.collision.high=1.0"]).reward).conditioning
    assert lo.collision == (0.0, 0.5) and hi.collision == (0.0, 1.0)
    spawner = build_spawner(compose("sim", ["reward.collision.high=0.5"]))
    assert spawner.conditioning.collision == (0.0, 0.5)


def test_component_catalogue_is_current():
    """docs/components.md is generated from the shipped configs; regenerate it when they change."""
    from pathlib import Path

    from selfplaydrive.catalogue import HANDWRITTEN, catalogue, generated_part

    page = (Path(__file__).resolve().parents[1] / "docs" / "components.md").read_text()
    assert generated_part(page) == catalogue(), "run: python -m selfplaydrive.catalogue docs/components.md"
    assert HANDWRITTEN in page and "## Write a reward term" in page.partition(HANDWRITTEN)[2]


@pytest.fixture(scope="module")
def default_maps():
    return build_maps(compose("sim").map)


# -- every option of the groups beyond the env: model, trainer, logger, eval, experiment --------
def _stub_env(cfg):
    """What `build_model` reads of an env: the observation layout and the action space."""
    from types import SimpleNamespace

    from gymnasium.spaces import MultiDiscrete

    from selfplaydrive.obs.layout import ObsLayout

    layout = ObsLayout(cfg.obs.max_objects, cfg.obs.max_road, 0)
    return SimpleNamespace(layout=layout, action_space=MultiDiscrete([7, 13]))


@pytest.mark.parametrize("option", valid_options("model"))
def test_every_model_option_instantiates(option):
    import torch

    from selfplaydrive.builder import build_model

    cfg = compose("train", [f"model={option}"])
    model = build_model(cfg, _stub_env(cfg))
    assert type(model).__name__ == cfg.model._target_.rsplit(".", 1)[1]
    params = sum(p.numel() for p in model.parameters())
    expected = {
        "deepsets": 596_757,
        "deepsets_laptop": 151_957,
        "deepsets_small": 39_381,
        "transformer": 638_229,
    }
    assert params == expected[option]  # the configs' comments
    tiny = compose("train", [f"model={option}", "obs.max_objects=3", "obs.max_road=5"])
    model = build_model(tiny, _stub_env(tiny))
    obs = torch.zeros(2, 19 + 3 * 9 + 5 * 8)  # ego, 3 objects, 5 road segments
    logits, value, _ = model(obs, model.initial_state(2), torch.ones(2, dtype=torch.bool))
    assert logits.shape == (2, 7 + 13) and value.shape == (2,)


@pytest.mark.parametrize("option", valid_options("trainer"))
def test_every_trainer_option_instantiates(option):
    from selfplaydrive.builder import instantiate

    cfg = compose("train", [f"trainer={option}", "seed=7"])
    trainer = instantiate(cfg.trainer)
    used = trainer.to_dict()
    expected = OmegaConf.to_container(cfg.trainer, resolve=True)
    expected.pop("_target_")
    # to_dict names each callback by its class (its settings are in the resolved config)
    callbacks = expected.pop("callbacks", [])
    assert used.get("callbacks", []) == [c["_target_"] for c in callbacks]
    assert {k: used[k] for k in expected} == expected
    assert used["seed"] == 7  # follows the top-level seed


@pytest.mark.parametrize("option", valid_options("logger"))
def test_every_logger_option_instantiates(option, tmp_path):
    from selfplaydrive.builder import instantiate

    factory = instantiate(compose("train", [f"logger={option}"]).logger)
    logger = factory(run_dir=tmp_path, total_updates=1, progress_bar=False, enabled=False, initial=0)
    for method in ("scalars", "progress", "text", "close"):
        assert callable(getattr(logger, method))
    logger.close()


@pytest.mark.parametrize("option", valid_options("eval"))
def test_every_eval_option_is_valid(option):
    """The eval group has no `_target_`: its keys are what `run_eval` reads."""
    from selfplaydrive.eval.app import ANALYSES
    from selfplaydrive.eval.diversity import run_diversity
    from selfplaydrive.eval.longform import run_longform
    from selfplaydrive.eval.suites.report import PAPER_COUNTS, default_suites

    cfg = compose("eval", [f"eval={option}"])
    assert set(cfg.eval) == {"analyses", "batch_size", "suites", "longform", "completion", "diversity"}
    assert set(cfg.eval.analyses) <= set(ANALYSES)
    assert set(PAPER_COUNTS) <= set(cfg.eval.suites) <= set(default_suites())
    assert all(v >= 1 for v in cfg.eval.suites.values())
    assert set(cfg.eval.longform) <= set(inspect.signature(run_longform).parameters)
    assert set(cfg.eval.diversity) <= set(inspect.signature(run_diversity).parameters)
    assert cfg.eval.batch_size >= 1


def _experiment_file(option):
    return OmegaConf.load(str(resources.files("selfplaydrive.conf") / "experiment" / f"{option}.yaml"))


@pytest.mark.parametrize("option", valid_options("experiment"))
def test_every_experiment_instantiates(option, default_maps):
    """Compose train.yaml with the experiment and build its parts: trainer config, model,
    logger, and the env with one world on the bundled map (the paper experiments use 512 or
    128 worlds on the Tartu map). Every key of its sweep is a valid override."""
    from selfplaydrive.builder import build_model, instantiate

    cfg = compose("train", [f"experiment={option}"])
    assert cfg.trainer.total_steps >= 1_000_000  # the experiment's budget, not the laptop default
    instantiate(cfg.trainer)
    build_model(cfg, _stub_env(cfg))
    instantiate(cfg.logger)
    small = compose("train", [f"experiment={option}", "env.num_worlds=1"])
    env = build_env(small, maps=default_maps)
    assert env.num_worlds == 1 and np.all(np.isfinite(env.reset()))
    sweep = OmegaConf.select(_experiment_file(option), "hydra.sweeper.params") or {}
    for key, values in sweep.items():
        compose("train", [f"experiment={option}", f"{key}={str(values).split(',')[0]}"])


@pytest.mark.parametrize("config", PRIMARY)
def test_every_primary_config_composes_and_builds_its_env(config, default_maps):
    cfg = compose(config, ["env.num_worlds=1"] if config != "eval" else [])
    if config == "eval":
        assert build_maps(cfg.map)
        return
    env = build_env(cfg, maps=default_maps)
    assert env.num_worlds == 1 and np.all(np.isfinite(env.reset()))


def test_render_and_bench_keys_are_arguments():
    """The keys of render.yaml and bench.yaml outside the env groups are the arguments of
    `render_episode` and `run_bench` (so none is ignored), and bench's default is the paper
    configuration with about 1,000 agents at 1 and 2 threads."""
    from selfplaydrive.render.video import render_episode
    from selfplaydrive.sim.bench import run_bench

    groups = {"map", "spawner", "physics", "reward", "obs", "env"}
    # policy: read by the CLI (hydra_app.render_driver), which passes it on as render_episode's driver
    render = set(compose("render")) - groups - {"policy"}
    assert render == set(inspect.signature(render_episode).parameters) - {"map_spec", "num_worlds", "env"}
    cfg = compose("bench")
    bench = set(cfg) - groups - {"json"}  # json: print format
    assert bench == set(inspect.signature(run_bench).parameters) - {"make_env", "map_name"}
    assert cfg.env.num_worlds * cfg.spawner.num_agents == 1024 and list(cfg.threads) == [1, 2]
