"""Policy loading (`selfplaydrive.policies`): where a checkpoint's run config is found, which env
settings it fixes, and the errors for files that are not checkpoints or run configs."""

from __future__ import annotations

import pytest

from selfplaydrive.builder import compose
from selfplaydrive.errors import CheckpointError
from selfplaydrive.policies import (
    find_run_config,
    is_builtin,
    load_checkpoint,
    load_run_config,
    make_policy,
    trained_env_kwargs,
    trained_obs_dim,
)


def test_render_module_re_exports_the_same_objects():
    import selfplaydrive.policies as moved
    import selfplaydrive.render.policies as old

    for name in old.__all__:
        assert getattr(old, name) is getattr(moved, name), name


def test_run_config_is_found_next_to_the_checkpoints_folder(tmp_path):
    ckpt = tmp_path / "run" / "checkpoints" / "final.pt"
    ckpt.parent.mkdir(parents=True)
    assert find_run_config(ckpt) is None
    (tmp_path / "run" / ".hydra").mkdir()
    (tmp_path / "run" / ".hydra" / "config.yaml").write_text("obs: {}\nenv: {}\n")
    assert find_run_config(ckpt) == tmp_path / "run" / ".hydra" / "config.yaml"
    # the resolved copy written by `selfplaydrive train` wins over Hydra's own
    (tmp_path / "run" / "resolved_config.yaml").write_text("obs: {}\nenv: {}\n")
    assert find_run_config(ckpt) == tmp_path / "run" / "resolved_config.yaml"
    # a checkpoint kept in the run folder itself
    assert find_run_config(tmp_path / "run" / "model.pt") == tmp_path / "run" / "resolved_config.yaml"


def test_trained_env_kwargs_take_obs_actions_scales_and_physics(tmp_path):
    from omegaconf import OmegaConf

    cfg = compose(
        "train",
        [
            "obs.max_objects=12",
            "obs.max_road=40",
            "env.actions.steer_deg=[-10,0,10]",
            "env.params.wp_scale=25.0",
            "physics=bicycle",
        ],
    )
    path = tmp_path / "resolved_config.yaml"
    path.write_text(OmegaConf.to_yaml(cfg, resolve=True))
    kw = trained_env_kwargs(load_run_config(path))
    assert (kw["obs"].max_objects, kw["obs"].max_road) == (12, 40)
    assert len(kw["actions"].steer) == 3 and len(kw["actions"].accel) == 7
    assert kw["params"].wp_scale == 25.0
    assert type(kw["physics"]).__name__ != "FrictionBicycleModel"
    assert "spawner" not in kw and "num_worlds" not in kw  # evaluations set their own


@pytest.mark.parametrize(
    ("text", "match"),
    [("model: {}\n", "no 'obs' and no 'env' node"), ("obs: [\n", "not a YAML config")],
)
def test_bad_run_config_names_the_file(tmp_path, text, match):
    path = tmp_path / "resolved_config.yaml"
    path.write_text(text)
    with pytest.raises(CheckpointError, match=match) as info:
        load_run_config(path)
    assert info.value.path == str(path)


def test_missing_checkpoint_and_unknown_driver(tmp_path):
    missing = tmp_path / "nope.pt"
    with pytest.raises(CheckpointError, match="no such file") as info:
        load_checkpoint(missing)
    assert info.value.path == str(missing)
    assert is_builtin("rule_based") and not is_builtin(str(missing))
    with pytest.raises(CheckpointError, match=r"driver 'rule_base'.*rule_based, random, static"):
        make_policy("rule_base", env=None)


def test_trained_obs_dim_reads_the_saved_env_buffer():
    assert trained_obs_dim({"model": {}}) is None
    assert trained_obs_dim({"env": {"buffers": {"obs": _Shaped((6, 123))}}}) == 123
    assert trained_obs_dim({"env": {"buffers": {"obs": _Shaped((123,))}}}) is None


class _Shaped:
    """Stands in for an array: only `.shape` is read."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.shape = shape
