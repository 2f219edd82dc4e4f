"""A checkpoint drives only in an env with the observation width it was trained on. Deep Sets'
weights do not depend on the set sizes (max_road, max_objects), so they would load into an env
with other sizes and drive on features unlike those they learnt from; a full checkpoint records
its env's observation width, and `make_policy` refuses the mismatch (session 10 found the
pretrained report evaluating a max_road=200 candidate in a max_road=64 env without a word)."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.builder import make_env
from selfplaydrive.errors import CheckpointError
from selfplaydrive.obs.config import ObsConfig
from selfplaydrive.policies import make_policy, trained_obs_dim


def test_a_checkpoint_refuses_an_env_with_other_observation_sizes(tmp_path):
    pytest.importorskip("torch")
    from selfplaydrive.models import DeepSetsModel
    from selfplaydrive.trainers.ppo import checkpoint as ckpt

    small = make_env("default", num_worlds=1, seed=0, obs=ObsConfig(max_objects=8, max_road=32))
    wide = make_env("default", num_worlds=1, seed=0, obs=ObsConfig(max_objects=8, max_road=48))
    model = DeepSetsModel(
        small.layout, tuple(small.action_space.nvec), input_size=8, hidden_size=16, lstm_size=12
    )
    wide_model = DeepSetsModel(
        wide.layout, tuple(wide.action_space.nvec), input_size=8, hidden_size=16, lstm_size=12
    )
    assert all(
        a.shape == b.shape
        for a, b in zip(model.state_dict().values(), wide_model.state_dict().values(), strict=True)
    )
    small.reset(seed=0)
    payload = {"model": model.state_dict(), "config": {}, "env": small.get_state()}
    path = ckpt.save(tmp_path / "ckpt_0000001.pt", payload)
    assert trained_obs_dim(payload) == small.layout.obs_dim
    policy = make_policy(path, small)  # its own env: drives
    actions = policy(small.observations, small)
    assert actions.shape == (small.num_agents, 2) and np.all(actions >= 0)
    expected = f"width {small.layout.obs_dim}, this env's are {wide.layout.obs_dim}"
    with pytest.raises(CheckpointError, match=expected):
        make_policy(path, wide)
    # a policy-only checkpoint records no env: its weights still load (the sizes are the caller's)
    bare = ckpt.save(tmp_path / "bare.pt", {"model": model.state_dict(), "config": {}})
    assert make_policy(bare, wide) is not None
