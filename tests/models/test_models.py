"""Tests of the policy models (paper section 3): sizes, shapes, set invariances, masking,
recurrence, the MultiDiscrete distribution helpers and a small overfit check."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from selfplaydrive.models import (
    DeepSetsModel,
    PolicyModel,
    TransformerModel,
    count_parameters,
    entropy,
    log_prob,
    masked_max,
    sample_actions,
)
from selfplaydrive.models.common import ObsSplitter
from selfplaydrive.models.pooling import compact_sets
from selfplaydrive.obs.layout import EGO_FEATURES, ObsLayout

SMALL = ObsLayout(max_objects=6, max_road=10)
MODELS = [DeepSetsModel, TransformerModel]


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    # Tiny batches gain nothing from intra-op threads, and on a shared 2-core machine torch's
    # spinning OpenMP workers made the overfit test 20x slower.
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def make_obs(layout: ObsLayout, batch: int, seed: int = 0, fill: float = 0.6) -> torch.Tensor:
    """Random observations shaped like the kernel's: values in [-1, 1], valid slots scattered
    among zero padding (not only at the end), road `type` a multiple of 1/4."""
    rng = np.random.default_rng(seed)
    obs = rng.uniform(-1, 1, (batch, layout.obs_dim)).astype(np.float32)
    parts = layout.split(obs)
    for key, block in (("objects", "object"), ("road", "road")):
        arr = parts[key]
        valid = rng.random(arr.shape[:2]) < fill
        arr[..., layout.feature_index(block, "valid")] = valid
        arr[~valid] = 0.0
    road = parts["road"]
    types = rng.integers(0, 5, road.shape[:2]) / 4.0
    road[..., layout.feature_index("road", "type")] = np.where(road[..., 0] > 0, types, 0.0)
    return torch.from_numpy(obs)


def step(model: torch.nn.Module, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    state = model.initial_state(obs.shape[0])
    start = torch.ones(obs.shape[0], dtype=torch.bool)
    logits, value, _ = model(obs, state, start)
    return logits, value


def slot_view(obs: torch.Tensor, layout: ObsLayout, key: str) -> torch.Tensor:
    """(B, N, F) view of the object or road block of `obs`."""
    lo, hi, width = {
        "objects": (layout.objects_offset, layout.road_offset, layout.object_dim),
        "road": (layout.road_offset, layout.extra_offset, layout.road_dim),
    }[key]
    return obs[:, lo:hi].view(obs.shape[0], -1, width)


def test_parameter_counts_match_paper() -> None:
    # Paper section 4: 596K (Deep Sets) and 638K (Transformer); docs/models.md has the sums.
    ds = count_parameters(DeepSetsModel(ObsLayout(), (7, 13)))
    tf = count_parameters(TransformerModel(ObsLayout(), (7, 13)))
    assert ds == 596_757
    assert tf == 638_229
    assert abs(ds - 596_000) / 596_000 < 0.05
    assert abs(tf - 638_000) / 638_000 < 0.05


@pytest.mark.parametrize("cls", MODELS)
@pytest.mark.parametrize("nvec", [(7, 13), (3, 5, 2)])
def test_output_shapes(cls: type, nvec: tuple[int, ...]) -> None:
    model = cls(SMALL, nvec)
    assert isinstance(model, PolicyModel)
    obs = make_obs(SMALL, 5)
    state = model.initial_state(5)
    logits, value, new_state = model(obs, state, torch.zeros(5, dtype=torch.bool))
    assert logits.shape == (5, sum(nvec)) and value.shape == (5,)
    assert len(new_state) == (2 if model.is_recurrent else 0)
    assert all(s.shape == (5, 256) for s in new_state)
    seq = make_obs(SMALL, 3 * 5).view(3, 5, -1)
    logits, value, _ = model.forward_sequence(seq, state, torch.zeros(3, 5, dtype=torch.bool))
    assert logits.shape == (3, 5, sum(nvec)) and value.shape == (3, 5)
    actions = sample_actions(logits, nvec)
    assert actions.shape == (3, 5, len(nvec))
    assert all(int(actions[..., i].max()) < n for i, n in enumerate(nvec))


@pytest.mark.parametrize("cls", MODELS)
@pytest.mark.parametrize("compact", [True, False])
def test_permutation_invariance(cls: type, compact: bool) -> None:
    torch.manual_seed(0)
    model = cls(SMALL, compact=compact)
    obs = make_obs(SMALL, 8, seed=1)
    permuted = obs.clone()
    gen = torch.Generator().manual_seed(2)
    for key in ("objects", "road"):
        view = slot_view(permuted, SMALL, key)
        for row in range(obs.shape[0]):
            view[row] = view[row, torch.randperm(view.shape[1], generator=gen)]
    assert not torch.equal(obs, permuted)
    with torch.no_grad():
        a, b = step(model, obs), step(model, permuted)
    torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("cls", MODELS)
@pytest.mark.parametrize("compact", [True, False])
def test_padding_is_ignored(cls: type, compact: bool) -> None:
    torch.manual_seed(0)
    model = cls(SMALL, compact=compact)
    obs = make_obs(SMALL, 8, seed=3, fill=0.5)
    noisy = obs.clone()
    for key in ("objects", "road"):
        view = slot_view(noisy, SMALL, key)
        pad = view[..., 0] == 0
        noise = torch.rand(view.shape) * 2 - 1
        noise[..., 0] = 0.0  # keep valid = 0: the slots stay padding
        view[pad] = noise[pad]
    assert not torch.equal(obs, noisy)
    with torch.no_grad():
        a, b = step(model, obs), step(model, noisy)
    torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize("cls", MODELS)
@pytest.mark.parametrize("compact", [True, False])
def test_empty_sets_give_finite_outputs_and_gradients(cls: type, compact: bool) -> None:
    model = cls(SMALL, compact=compact)
    obs = make_obs(SMALL, 4, seed=4)
    for key in ("objects", "road"):
        slot_view(obs, SMALL, key)[:2] = 0.0  # rows 0-1: no objects and no road segments
    logits, value = step(model, obs)
    assert torch.isfinite(logits).all() and torch.isfinite(value).all()
    (logits.sum() + value.sum()).backward()
    assert all(torch.isfinite(p.grad).all() for p in model.parameters() if p.grad is not None)


def test_masked_max_hand_computed() -> None:
    x = torch.tensor([[[1.0, -5.0], [3.0, -7.0], [9.0, 9.0]], [[2.0, 2.0], [4.0, 4.0], [6.0, 6.0]]])
    valid = torch.tensor([[True, True, False], [False, False, False]])
    torch.testing.assert_close(masked_max(x, valid), torch.tensor([[3.0, -5.0], [0.0, 0.0]]))


def test_compact_sets_keeps_valid_elements_in_order() -> None:
    x = torch.arange(8.0).view(2, 4, 1)
    valid = torch.tensor([[False, True, False, True], [False, False, True, False]])
    out, v = compact_sets(x, valid)
    # Row 1 keeps its valid slot 2 first, then the first padding slot (0) to fill K = 2.
    assert out.squeeze(-1).tolist() == [[1.0, 3.0], [6.0, 4.0]]
    assert v.tolist() == [[True, True], [True, False]]


@pytest.mark.parametrize("cls", MODELS)
def test_compaction_does_not_change_outputs(cls: type) -> None:
    torch.manual_seed(0)
    full = cls(SMALL, compact=False)
    compact = cls(SMALL, compact=True)
    compact.load_state_dict(full.state_dict())
    obs = make_obs(SMALL, 6, seed=5, fill=0.3)
    with torch.no_grad():
        torch.testing.assert_close(step(full, obs), step(compact, obs), atol=1e-5, rtol=1e-5)


def test_lstm_state_resets_at_episode_start() -> None:
    torch.manual_seed(0)
    model = DeepSetsModel(SMALL)
    obs = make_obs(SMALL, 2, seed=6)
    state = model.initial_state(2)
    no_start = torch.zeros(2, dtype=torch.bool)
    with torch.no_grad():
        for t in range(3):
            _, _, state = model(make_obs(SMALL, 2, seed=10 + t), state, no_start)
        assert state[0].abs().max() > 0
        fresh_logits, fresh_value, _ = model(obs, model.initial_state(2), no_start)
        logits, value, _ = model(obs, state, torch.tensor([True, False]))
    torch.testing.assert_close(logits[0], fresh_logits[0])
    torch.testing.assert_close(value[0], fresh_value[0])
    assert not torch.allclose(logits[1], fresh_logits[1])


@pytest.mark.parametrize("cls", MODELS)
def test_sequence_equals_step_by_step(cls: type) -> None:
    torch.manual_seed(0)
    model = cls(SMALL)
    t_len, batch = 7, 4
    obs = make_obs(SMALL, t_len * batch, seed=7).view(t_len, batch, -1)
    starts = torch.zeros(t_len, batch, dtype=torch.bool)
    starts[0, 1] = starts[3, 0] = starts[3, 2] = starts[5, 1] = True
    state0 = model.initial_state(batch)
    if model.is_recurrent:  # start from a non-trivial state
        state0 = tuple(torch.randn_like(s) * 0.5 for s in state0)
    with torch.no_grad():
        seq_logits, seq_values, seq_state = model.forward_sequence(obs, state0, starts)
        state, logits, values = state0, [], []
        for t in range(t_len):
            lg, v, state = model(obs[t], state, starts[t])
            logits.append(lg)
            values.append(v)
    torch.testing.assert_close(seq_logits, torch.stack(logits), atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(seq_values, torch.stack(values), atol=1e-5, rtol=1e-5)
    for a, b in zip(seq_state, state, strict=True):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)


def test_multidiscrete_log_prob_and_entropy_hand_computed() -> None:
    nvec = (2, 3)
    logits = torch.log(torch.tensor([[0.25, 0.75, 0.5, 0.25, 0.25]]))
    actions = torch.tensor([[1, 2]])
    assert log_prob(logits, actions, nvec).item() == pytest.approx(math.log(0.75 * 0.25), abs=1e-6)
    h = -(0.25 * math.log(0.25) + 0.75 * math.log(0.75)) - (0.5 * math.log(0.5) + 0.5 * math.log(0.25))
    assert entropy(logits, nvec).item() == pytest.approx(h, abs=1e-6)  # 0.5623 + 1.0397 nats
    assert sample_actions(logits, nvec, deterministic=True).tolist() == [[1, 0]]


def test_sampling_follows_the_distribution() -> None:
    nvec = (2, 3)
    logits = torch.log(torch.tensor([0.25, 0.75, 0.5, 0.25, 0.25])).expand(20000, -1)
    draws = sample_actions(logits, nvec, generator=torch.Generator().manual_seed(0))
    assert draws[:, 0].float().mean().item() == pytest.approx(0.75, abs=0.02)
    assert (draws[:, 1] == 0).float().mean().item() == pytest.approx(0.5, abs=0.02)


def test_bad_inputs_raise_clear_errors() -> None:
    model = DeepSetsModel(SMALL)
    with pytest.raises(ValueError, match=rf"obs: expected shape \(B, {SMALL.obs_dim}\)"):
        step(model, torch.zeros(2, SMALL.obs_dim + 1))
    with pytest.raises(ValueError, match="state: expected"):
        model(make_obs(SMALL, 2), model.initial_state(3), torch.zeros(2, dtype=torch.bool))
    with pytest.raises(ValueError, match=r"episode_start: expected shape \(2,\)"):
        model(make_obs(SMALL, 2), model.initial_state(2), torch.zeros(3, dtype=torch.bool))
    with pytest.raises(ValueError, match="floating-point"):
        step(model, torch.zeros(2, SMALL.obs_dim, dtype=torch.long))
    with pytest.raises(ValueError, match="action_nvec"):
        TransformerModel(SMALL, (7, 0))
    with pytest.raises(ValueError, match="num_heads"):
        TransformerModel(SMALL, embed_size=130, num_heads=4)
    with pytest.raises(ValueError, match=r"actions: expected last dimension len\(nvec\) = 2"):
        log_prob(torch.zeros(1, 20), torch.zeros(1, 3, dtype=torch.long), (7, 13))
    with pytest.raises(TypeError, match="layout"):
        DeepSetsModel([63, 200])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"layout: unknown keys \['max_objetcs'\]"):
        DeepSetsModel({"max_objetcs": 63})


def test_splitter_reads_the_layout() -> None:
    layout = ObsLayout(max_objects=3, max_road=4, extra_dim=2)
    obs = make_obs(layout, 2, seed=8)
    parts = ObsSplitter(layout)(obs)
    coef_cols = [i for i, n in enumerate(EGO_FEATURES) if n.startswith("coef_")]
    assert len(coef_cols) == 8  # the 8 conditioned reward coefficients (section 2.3)
    torch.testing.assert_close(parts["coef"], obs[:, coef_cols])
    assert parts["ego"].shape == (2, layout.ego_dim + 2)  # hook columns join the ego input
    torch.testing.assert_close(parts["ego"][:, -2:], obs[:, -2:])
    assert parts["road"].shape == (2, 4, layout.road_dim - 1 + 5)
    # One-hot of the segment type: type 0.75 (traffic light) -> class 3.
    road = slot_view(obs, layout, "road")
    tcol = layout.feature_index("road", "type")
    for r, k in np.argwhere(road[..., 0].numpy() > 0):
        assert parts["road"][r, k, -5:].argmax().item() == round(road[r, k, tcol].item() * 4)
    for model in (DeepSetsModel(layout), TransformerModel(layout)):
        logits, _ = step(model, obs)
        assert logits.shape == (2, 20)


def test_film_conditions_on_reward_coefficients() -> None:
    torch.manual_seed(0)
    model = TransformerModel(SMALL)
    torch.nn.init.normal_(model.film[-1].weight, std=0.1)  # leave the identity initialisation
    obs = make_obs(SMALL, 2, seed=9)
    tokens, _ = model.tokens(obs)
    changed = obs.clone()
    changed[:, EGO_FEATURES.index("coef_collision")] += 0.5
    tokens2, _ = model.tokens(changed)
    # Object and road tokens do not read the coefficients except through FiLM.
    assert not torch.allclose(tokens[:, 1:], tokens2[:, 1:])


@pytest.mark.parametrize("cls", MODELS)
def test_critic_overfits_a_small_batch(cls: type) -> None:
    torch.manual_seed(0)
    model = cls(SMALL)
    obs = make_obs(SMALL, 16, seed=11)
    target = torch.linspace(-1.0, 1.0, 16)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    losses = []
    for _ in range(200):
        _, value = step(model, obs)
        loss = torch.mean((value - target) ** 2)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.01 * losses[0] and losses[-1] < 1e-3  # measured ~1e-7 (Transformer)


def test_torch_stays_out_of_the_simulator() -> None:
    # DESIGN.md: the simulator core imports no torch; only models/ and trainers/ (and code paths
    # that load a checkpoint, lazily) do. Import every non-torch module and check.
    import subprocess
    import sys

    modules = [
        "selfplaydrive",
        "selfplaydrive.builder",
        "selfplaydrive.cli",
        "selfplaydrive.maps.loader",
        "selfplaydrive.scenario.spawner",
        "selfplaydrive.sim.vec_env",
        "selfplaydrive.drivers",
        "selfplaydrive.env.gym_vector",
        "selfplaydrive.env.pettingzoo_env",
        "selfplaydrive.render.policies",
        "selfplaydrive.render.episode",
        "selfplaydrive.eval.longform",
        "selfplaydrive.eval.suites",
    ]
    code = "import sys\n" + "".join(f"import {m}\n" for m in modules) + "print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("cls", MODELS)
def test_built_from_config_by_target(cls: type) -> None:
    from hydra.utils import instantiate

    cfg = {"_target_": f"{cls.__module__}.{cls.__name__}", "action_nvec": [3, 4], "compact": False}
    model = instantiate(cfg, layout=SMALL, _convert_="all")
    assert isinstance(model, cls) and model.nvec == (3, 4)
    assert model.splitter.layout == SMALL
    logits, _ = step(model, make_obs(SMALL, 2))
    assert logits.shape == (2, 7)


@pytest.mark.shared_maps
def test_models_drive_the_real_env() -> None:
    """End to end on Tartu: env observations in, sampled actions back into the env."""
    from sharedmaps import shared_map

    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.scenario.spawner import PaperSpawner
    from selfplaydrive.sim import VecEnv

    road_map = load_map(str(shared_map("tartu_lanelet2/tartu_demo_l.osm")))
    env = VecEnv(road_map, PaperSpawner(num_agents=8), 2, seed=0)
    env.reset(0)
    nvec = tuple(int(n) for n in env.action_space.nvec)
    parts = ObsSplitter(env.layout)(torch.from_numpy(env.observations.copy()))
    assert parts["road_valid"].any(dim=1).all()  # every agent sees road segments
    for cls in MODELS:
        torch.manual_seed(0)
        model = cls(env.layout, nvec)
        state = model.initial_state(env.num_agents)
        start = torch.ones(env.num_agents, dtype=torch.bool)
        for _ in range(5):
            with torch.no_grad():
                logits, value, state = model(torch.from_numpy(env.observations.copy()), state, start)
            assert torch.isfinite(logits).all() and torch.isfinite(value).all()
            env.step(sample_actions(logits, nvec).numpy())
            start = torch.from_numpy(env.terminations | env.truncations)


@pytest.mark.parametrize("cls", MODELS)
def test_initial_weights_do_not_depend_on_the_thread_count(cls: type) -> None:
    """The same seed builds the same model whatever `torch.set_num_threads` the caller chose
    (the orthogonal initialisation's QR rounded differently on 2 threads: up to 2e-7, enough to
    change a PPO learning curve)."""
    weights = []
    for threads in (2, 1):
        torch.set_num_threads(threads)
        torch.manual_seed(0)
        model = cls(SMALL, (7, 13))
        weights.append(torch.cat([p.detach().flatten() for p in model.parameters()]))
        assert torch.get_num_threads() == threads  # the caller's setting is restored
    torch.set_num_threads(1)
    assert torch.equal(weights[0], weights[1])
