"""A simple driving task for trainer tests: a straight one-way three-lane road, a few agents
per world on the middle lane, waypoints ahead on its centre, and a tiny policy for fast tests."""

from __future__ import annotations

from types import ModuleType

import numpy as np
import torch
from torch import nn

from selfplaydrive.maps import LaneElement, MapElements, PolylineElement, compile_map
from selfplaydrive.models import DeepSetsModel
from selfplaydrive.models.common import reset_state
from selfplaydrive.obs.config import ObsConfig
from selfplaydrive.scenario.types import COEFF_NAMES, Scenario
from selfplaydrive.sim import VecEnv
from selfplaydrive.trainers import PPOConfig, PPOTrainer

ROAD_LENGTH = 600.0  # [m]
LANE_WIDTH = 3.5  # [m]
# waypoints count within 2 m; collisions and road-edge contacts end the agent (C >= 0.5)
COEFFS = dict(
    waypoint_radius=3.0,
    collision=0.5,
    offroad=0.5,
    red_light=0.0,
    comfort=0.0,
    center=1e-3,
    center_bias=0.0,
    align=1e-3,
)


def straight_road():
    """One-way road along +x: three eastbound lanes (centres y = -3.5, 0, 3.5 m), road edges
    at y = -5.25 and 5.25 m."""
    L, w = ROAD_LENGTH, LANE_WIDTH
    lanes = [
        LaneElement(np.array([[0.0, y], [L, y]]), width=w, speed_limit=13.9, source_id=f"lane{k}")
        for k, y in enumerate((-w, 0.0, w))
    ]
    edges = [
        PolylineElement(np.array([[0.0, -1.5 * w], [L, -1.5 * w]]), source_id="south"),
        PolylineElement(np.array([[0.0, 1.5 * w], [L, 1.5 * w]]), source_id="north"),
    ]
    return compile_map(MapElements(name="straight_600", lanes=lanes, road_edges=edges))


class LaneSpawner:
    """Agents on the middle lane, heading roughly east, waypoints every `spacing` m ahead.

    Args:
        num_agents: Agent slots A (at most 8); each world gets 2..A agents at least 50 m apart.
        num_waypoints: Waypoints per agent (K).
        spacing: Distance between waypoints along the lane [m].
        episode_length: [s].
        initial_speed: (low, high) uniform initial speed [m/s].
        coeffs: Reward coefficients overriding `COEFFS` (names of `COEFF_NAMES`).
        heading_noise: Initial heading U(-h, h) [rad] around the lane direction.
    """

    def __init__(
        self,
        num_agents: int = 4,
        num_waypoints: int = 6,
        spacing: float = 12.0,
        episode_length: float = 8.0,
        initial_speed: tuple[float, float] = (4.0, 8.0),
        coeffs: dict[str, float] | None = None,
        heading_noise: float = 0.1,
    ) -> None:
        self.A, self.K, self.spacing, self.episode_length = num_agents, num_waypoints, spacing, episode_length
        self.initial_speed = initial_speed
        self.heading_noise = heading_noise
        c = dict(COEFFS, **(coeffs or {}))
        self.coeffs = np.array([c[name] for name in COEFF_NAMES], np.float32)

    def sample(self, road_map, rng: np.random.Generator, map_index: int = 0) -> Scenario:
        A, K, f4 = self.A, self.K, np.float32
        n = int(rng.integers(2, A + 1))
        x = 20.0 + 60.0 * rng.permutation(8)[:n] + rng.uniform(0, 10, n)
        xy = np.zeros((A, 2), f4)
        xy[:n, 0] = x
        xy[:n, 1] = rng.uniform(-0.3, 0.3, n)
        wps = np.zeros((A, K, 2), f4)
        wps[:n, :, 0] = x[:, None] + self.spacing * np.arange(1, K + 1)
        valid = np.arange(A) < n
        heading = np.where(valid, rng.uniform(-self.heading_noise, self.heading_noise, A), 0.0).astype(f4)
        speed = np.where(valid, rng.uniform(*self.initial_speed, A), 0.0).astype(f4)
        return Scenario(
            map_index=map_index,
            region=np.array([0, -50, ROAD_LENGTH, 50], f4),
            agent_valid=valid,
            agent_xy=xy,
            agent_heading=heading,
            agent_speed=speed,
            agent_length=np.full(A, 4.5, f4),
            agent_width=np.full(A, 2.0, f4),
            agent_parked=np.zeros(A, bool),
            agent_lane=np.where(valid, 0, -1).astype(np.int32),
            waypoints=wps,
            num_waypoints=np.where(valid, K, 0).astype(np.int32),
            coeffs=np.tile(self.coeffs, (A, 1)),
            hidden=np.ones((A, 3), f4),
            static_valid=np.zeros(1, bool),
            static_xy=np.zeros((1, 2), f4),
            static_heading=np.zeros(1, f4),
            static_length=np.full(1, 4.5, f4),
            static_width=np.full(1, 2.0, f4),
            ped_valid=np.zeros(1, bool),
            ped_path=np.zeros((1, 2, 2), f4),
            ped_num_points=np.zeros(1, np.int32),
            ped_speed=np.zeros(1, f4),
            ped_start_time=np.zeros(1, f4),
            ped_size=np.full((1, 2), 0.5, f4),
            lights_enabled=False,
            light_state=np.zeros(0, np.int8),
            light_time_left=np.zeros(0, f4),
            episode_length=self.episode_length,
        )


def lane_env(num_worlds: int = 8, seed: int = 0, road_map=None, **spawner_args) -> VecEnv:
    """VecEnv on `straight_road()` with `LaneSpawner` and a small observation (4 objects, 16
    road segments within 50 m)."""
    return VecEnv(
        road_map if road_map is not None else straight_road(),
        LaneSpawner(**spawner_args),
        num_worlds,
        obs=ObsConfig(max_objects=4, max_road=16, radius=50.0),
        seed=seed,
    )


class TinyPolicy(nn.Module):
    """MLP + GRU-cell policy with the `PolicyModel` interface (fast tests of the trainer)."""

    is_recurrent = True

    def __init__(self, obs_dim: int, nvec=(7, 13), hidden: int = 32) -> None:
        super().__init__()
        self.nvec = tuple(nvec)
        self.hidden = hidden
        self.encoder = nn.Sequential(nn.Linear(obs_dim, hidden), nn.Tanh())
        self.cell = nn.GRUCell(hidden, hidden)
        self.actor = nn.Linear(hidden, sum(self.nvec))
        self.critic = nn.Linear(hidden, 1)
        nn.init.orthogonal_(self.actor.weight, 0.01)

    def initial_state(self, batch_size: int, device=None):
        return (torch.zeros(batch_size, self.hidden, device=device),)

    def forward(self, obs, state, episode_start):
        (h,) = reset_state(state, episode_start)
        h = self.cell(self.encoder(obs), h)
        return self.actor(h), self.critic(h).squeeze(-1), (h,)

    def forward_sequence(self, obs, state, episode_start):
        logits, values = [], []
        for t in range(obs.shape[0]):
            lg, v, state = self.forward(obs[t], state, episode_start[t])
            logits.append(lg)
            values.append(v)
        return torch.stack(logits), torch.stack(values), state


class SpeedValueModel(nn.Module):
    """Feed-forward stub: uniform logits and V(obs) = 10 * the ego speed feature, so a test can
    tell which observation a value was computed from."""

    is_recurrent = False
    speed_col = 2  # EGO_FEATURES.index("speed")

    def __init__(self, nvec=(7, 13)) -> None:
        super().__init__()
        self.nvec = tuple(nvec)
        self.scale = nn.Parameter(torch.tensor(10.0))

    def initial_state(self, batch_size: int, device=None):
        return ()

    def forward(self, obs, state=(), episode_start=None):
        logits = torch.zeros(obs.shape[0], sum(self.nvec), device=obs.device)
        return logits, self.scale * obs[:, self.speed_col], ()

    def forward_sequence(self, obs, state=(), episode_start=None):
        lg, v, _ = self.forward(obs.reshape(-1, obs.shape[-1]))
        return lg.reshape(*obs.shape[:2], -1), v.reshape(obs.shape[:2]), ()


def load_benchmark(name: str) -> ModuleType:
    """The script benchmarks/<name>.py as a module (the benchmarks are no package)."""
    # imported here: torchrun workers (ddp_worker.py) import this module with only
    # tests/trainers on sys.path, where tests/loadfile.py is not found
    from loadfile import ROOT, load_file

    return load_file(ROOT / "benchmarks" / f"{name}.py", name)


# small PPO settings for the checkpoint and resume tests: a checkpoint every 2 updates
RESUME_CFG = dict(
    total_steps=10_000,
    rollout_length=12,
    num_minibatches=2,
    num_epochs=2,
    device="cpu",
    progress_bar=False,
    checkpoint_interval=2,
    keep_checkpoints=1,
    torch_threads=1,
)


def resume_trainer(run_dir, init_seed: int, **overrides) -> PPOTrainer:
    """A small Deep Sets trainer on the lane task whose init depends on `init_seed`, for
    checkpoint and resume tests (a load must override all of it)."""
    torch.manual_seed(init_seed)  # another init: the checkpoint must override all of it
    env = lane_env(num_worlds=3, seed=init_seed, episode_length=1.5)
    model = DeepSetsModel(env.layout, input_size=16, hidden_size=32, lstm_size=32)
    return PPOTrainer(env, model, PPOConfig(**dict(RESUME_CFG, **overrides)), run_dir)


def assert_same_run(a: PPOTrainer, b: PPOTrainer) -> None:
    """Two trainers are at the same point of the same run, bit for bit: weights, env buffers,
    recurrent state, counters and the window of recent episodes."""
    for (name, pa), pb in zip(a.model.state_dict().items(), b.model.state_dict().values(), strict=True):
        assert torch.equal(pa, pb), name
    for name, buf in a.env.buffers.items():
        np.testing.assert_array_equal(buf, b.env.buffers[name], err_msg=name)
    for sa, sb in zip(a.state, b.state, strict=True):
        assert torch.equal(sa, sb)
    assert (a.update_idx, a.global_step, a.agent_steps) == (b.update_idx, b.global_step, b.agent_steps)
    assert list(a.recent) == list(b.recent) and list(a.recent_returns) == list(b.recent_returns)
