"""The initial actor bias towards the middle action choices (`action_prior`)."""

import pytest
import torch

from selfplaydrive.models import DeepSetsModel, TransformerModel
from selfplaydrive.models.common import middle_prior_bias
from selfplaydrive.obs.layout import ObsLayout


def test_bias_values_by_hand():
    # n = 5: c = 2, offsets -1, -0.5, 0, 0.5, 1 -> logits -2 * offset^2
    bias = middle_prior_bias((5, 3), 2.0)
    expected = torch.tensor([-2.0, -0.5, 0.0, -0.5, -2.0, -2.0, 0.0, -2.0])
    assert torch.allclose(bias, expected)


def test_zero_gives_uniform_and_negative_is_refused():
    assert torch.count_nonzero(middle_prior_bias((7, 13), 0.0)) == 0
    with pytest.raises(ValueError, match="action_prior"):
        middle_prior_bias((7, 13), -1.0)


@pytest.mark.parametrize("model_cls", [DeepSetsModel, TransformerModel])
def test_untrained_policy_prefers_zero_acceleration_and_steering(model_cls):
    layout = ObsLayout(max_objects=4, max_road=6)
    torch.manual_seed(0)
    model = model_cls(layout, (7, 13), action_prior=3.0)
    obs = torch.rand(64, layout.obs_dim) * 0.2
    state = model.initial_state(64)
    logits, _, _ = model(obs, state, torch.ones(64, dtype=torch.bool))
    accel = torch.softmax(logits[:, :7], dim=-1).mean(0)
    steer = torch.softmax(logits[:, 7:], dim=-1).mean(0)
    assert accel.argmax() == 3 and steer.argmax() == 6
    # exp(3) = 20x more likely than the outermost choices
    assert accel[3] > 10 * accel[0] and steer[6] > 10 * steer[12]
