"""`VecEnv.set_term_weight`: a reward column's weight changed between steps scales that column
from the next step on and leaves the driving and the other columns as they were; bad names and
weights are refused with the env's column names."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive import make_env
from selfplaydrive.errors import ConfigError


def _rollout(weight_at: dict[int, float], steps: int = 60) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    env = make_env("default", num_worlds=2)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    terms, rewards, masks = [], [], []
    for t in range(steps):
        if t in weight_at:
            env.set_term_weight("collision", weight_at[t])
        actions = rng.integers(0, env.action_space.nvec, size=(env.num_agents, 2))
        env.step(actions)
        terms.append(env.reward_terms.copy())
        rewards.append(env.rewards.copy())
        masks.append(env.reward_mask.copy())
    return np.array(terms), np.array(rewards), np.array(masks)


def test_a_new_weight_scales_its_column_from_the_next_step_on():
    base_terms, base_rewards, masks = _rollout({})
    terms, rewards, masks2 = _rollout({20: 2.5})
    k = make_env("default", num_worlds=1).term_names.index("collision")
    np.testing.assert_array_equal(masks, masks2)  # the weights do not change the driving
    np.testing.assert_array_equal(terms[:20], base_terms[:20])
    np.testing.assert_array_equal(terms[20:, :, k], np.float32(2.5) * base_terms[20:, :, k])
    others = [j for j in range(terms.shape[2]) if j != k]
    np.testing.assert_array_equal(terms[..., others], base_terms[..., others])
    hit = base_terms[20:, :, k] != 0
    assert hit.sum() > 0, "no collision in the rollout: the comparison would be empty"
    extra = rewards[20:] - base_rewards[20:]
    np.testing.assert_allclose(extra, 1.5 * base_terms[20:, :, k], atol=1e-5)


def test_bad_names_and_weights_are_refused():
    env = make_env("default", num_worlds=1)
    with pytest.raises(ConfigError, match=r"no reward column 'colision'; columns: waypoint, collision"):
        env.set_term_weight("colision", 2.0)
    for bad in (float("nan"), float("inf"), "2", True):
        with pytest.raises(ConfigError, match="set_term_weight: collision: expected a finite number"):
            env.set_term_weight("collision", bad)
    env.set_term_weight("collision", 3)
    assert env.term_weight("collision") == 3.0
