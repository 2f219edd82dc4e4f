"""`obs=custom obs.target=...`: an encoder defined outside the package selected in one Hydra
override (obs/loading.py `load_encoder`), and the errors of a bad target."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.builder import build_env, compose
from selfplaydrive.errors import ConfigError
from selfplaydrive.obs import KernelEncoder, ObsLayout, PaperEncoder, PartialObsEncoder, load_encoder

ENCODER_FILE = '''
import numpy as np

from selfplaydrive.obs import ObsLayout


class Speeds:
    """A Python encoder: the ego block only, each agent's speed / scale in its first column."""

    name = "speeds"
    radius = 50.0

    def __init__(self, scale=100.0):
        self.scale = scale
        self.layout = ObsLayout(max_objects=0, max_road=0)

    def __call__(self, state):
        out = np.zeros((len(state.speed), self.layout.obs_dim), np.float32)
        out[:, 0] = np.clip(state.speed / self.scale, -1.0, 1.0)
        return out


speeds = Speeds()
'''


def test_a_factory_in_the_package_is_called_with_the_keys():
    enc = load_encoder("selfplaydrive.obs:PartialObsEncoder", max_objects=8)
    assert isinstance(enc, PartialObsEncoder) and enc.layout.max_objects == 8


def test_an_encoder_instance_is_returned_as_it_is(tmp_path):
    path = tmp_path / "my_encoder.py"
    path.write_text(ENCODER_FILE)
    enc = load_encoder(f"{path}:speeds")
    assert enc.name == "speeds" and not isinstance(enc, KernelEncoder)
    with pytest.raises(ConfigError, match="an encoder, not a factory; it takes no"):
        load_encoder(f"{path}:speeds", scale=2.0)
    assert load_encoder(f"{path}:Speeds", scale=2.0).scale == 2.0


@pytest.mark.parametrize(
    ("target", "match"),
    [
        ("no_colon", r"obs.target: expected 'module:attr' or 'file.py:attr'"),
        ("selfplaydrive.obs:Nope", r"'selfplaydrive.obs' has no 'Nope'; it has \[.*'PaperEncoder'"),
        ("no_such_file.py:x", "no file"),
        ("selfplaydrive.no_such_module:x", "cannot import 'selfplaydrive.no_such_module'"),
        ("selfplaydrive.obs:EGO_FEATURES", "expected an observation encoder .* got tuple"),
    ],
)
def test_a_bad_target_is_named(target, match):
    with pytest.raises(ConfigError, match=match):
        load_encoder(target)


def test_one_override_selects_it_and_the_env_steps(tmp_path):
    path = tmp_path / "my_encoder.py"
    path.write_text(ENCODER_FILE)
    cfg = compose("sim", ["obs=custom", f"obs.target={path}:Speeds", "+obs.scale=50.0", "env.num_worlds=1"])
    env = build_env(cfg)
    assert env.encoder.name == "speeds"
    assert env.observation_space.shape == (ObsLayout(max_objects=0, max_road=0).obs_dim,)
    env.reset(seed=0)
    env.step(np.zeros((env.num_agents, 2), np.int64))
    m = env.masks
    np.testing.assert_allclose(env.observations[m, 0], np.clip(env.state.speed[m] / 50.0, -1, 1), rtol=1e-6)
    assert isinstance(load_encoder("selfplaydrive.obs:PaperEncoder"), PaperEncoder)
