"""Example 02: write your own reward term in NumPy and see it in the per-term logs.

`SpeedingPenalty` is a `RewardHook` (selfplaydrive/rewards/registry.py): after the kernels have
stepped the worlds, the env calls it with read-only views of its state and adds its (N,) output
to the reward under its own name. Here it penalises driving faster than the speed limit of the
lane the vehicle is on: R = -coef * max(v - limit, 0) per 0.1 s step.

The term then shows up wherever the eight built-in terms do:
- `env.term_names` and `env.extra_terms` (per step);
- the per-world episode statistics `env.pop_episode_stats()[i]["terms"]["speeding"]`;
- the trainer's TensorBoard scalars, tag `term/speeding` (a short PPO run at the end).

Run: python examples/02_reward_term.py [--tiny] [--no-train]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import warnings

import numpy as np
from scipy.spatial import cKDTree

from selfplaydrive import make_env
from selfplaydrive.maps.procedural import ProceduralTownLoader
from selfplaydrive.maps.roadmap import RoadMap, SegmentType
from selfplaydrive.scenario.spawner import PaperSpawner

NEAREST = 6  # lane segments looked at per vehicle


class SpeedingPenalty:
    """Reward term -coef * max(speed - limit, 0) where `limit` is the speed limit [m/s] of the
    nearest lane segment pointing the way the vehicle heads (within 90 degrees).

    Args:
        maps: The env's maps, in the env's order (`env.maps`); `state.map_id` indexes them.
        coef: Penalty per m/s over the limit per step.
        tolerance: Speed [m/s] allowed above the limit before the penalty starts.
    """

    name = "speeding"

    def __init__(self, maps: list[RoadMap], coef: float = 0.01, tolerance: float = 0.0) -> None:
        if coef < 0 or tolerance < 0:
            raise ValueError(
                f"SpeedingPenalty: expected coef >= 0 and tolerance >= 0, got {coef}, {tolerance}"
            )
        self.coef = coef
        self.tolerance = tolerance
        self.tables = [self._table(m) for m in maps]

    @staticmethod
    def _table(road_map: RoadMap) -> tuple[cKDTree, np.ndarray, np.ndarray]:
        seg = road_map.segments
        lane = np.flatnonzero(seg.type == SegmentType.LANE_CENTER)
        limits = road_map.lanes.speed_limit[seg.owner[lane]].astype(np.float32)
        return cKDTree(seg.mid[lane]), seg.dir[lane], limits

    def limits(self, state) -> np.ndarray:
        """(N,) speed limit [m/s] of each slot's lane (inf where no lane is near)."""
        x, y = np.asarray(state.x), np.asarray(state.y)
        map_id = np.repeat(np.asarray(state.map_id), len(x) // len(state.map_id))
        out = np.full(len(x), np.inf, dtype=np.float32)
        for m, (tree, direction, limit) in enumerate(self.tables):
            rows = np.flatnonzero(map_id == m)
            if len(rows) == 0:
                continue
            k = min(NEAREST, len(limit))
            dist, idx = tree.query(np.stack([x[rows], y[rows]], axis=1), k=k)
            idx, dist = idx.reshape(len(rows), k), dist.reshape(len(rows), k)
            heading = np.stack([np.asarray(state.hcos)[rows], np.asarray(state.hsin)[rows]], axis=1)
            ahead = np.einsum("nkd,nd->nk", direction[idx], heading) > 0.0
            # the nearest segment heading the same way; far or opposite lanes are skipped
            dist = np.where(ahead & (dist < 10.0), dist, np.inf)
            best = np.argmin(dist, axis=1)
            found = np.isfinite(dist[np.arange(len(rows)), best])
            out[rows] = np.where(found, limit[idx[np.arange(len(rows)), best]], np.inf)
        return out

    def __call__(self, state) -> np.ndarray:
        over = np.asarray(state.speed) - self.limits(state) - self.tolerance
        return (-self.coef * np.clip(over, 0.0, None)).astype(np.float32)  # inf limit -> 0


def drive(env, steps: int) -> None:
    """Half of the agents floor it straight ahead, the others act at random."""
    rng = np.random.default_rng(0)
    floor_it = np.arange(env.num_agents) % 2 == 0
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        for _ in range(steps):
            actions = np.stack([rng.integers(0, 7, env.num_agents), rng.integers(0, 13, env.num_agents)], 1)
            actions[floor_it] = (6, 6)  # +4 m/s^2, zero steering
            env.step(actions)


def print_episode_logs(env) -> None:
    """The per-world episode records: every term summed over the episode's agents."""
    stats = env.pop_episode_stats()
    print(f"per-term episode sums ({len(stats)} world episodes finished):")
    print("  world  " + " ".join(f"{n:>10s}" for n in env.term_names))
    for rec in stats[:6]:
        terms = rec["terms"]
        print(f"  {rec['world']:5d}  " + " ".join(f"{terms[n]:+10.3f}" for n in env.term_names))


def train_and_read_logs(env, tiny: bool) -> None:
    """A short run of the library's PPO; the hook's term is logged as `term/speeding`."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from selfplaydrive.models import DeepSetsModel
    from selfplaydrive.trainers.run import train_run

    model = DeepSetsModel(env.layout, env.action_space.nvec, input_size=16, hidden_size=32, lstm_size=32)
    steps = env.num_agents * (32 if tiny else 640)
    cfg = dict(total_steps=steps, rollout_length=16, eval_episodes=0, progress_bar=False, seed=0)
    with tempfile.TemporaryDirectory() as run_dir:
        train_run(env, model, cfg, run_dir)
        acc = EventAccumulator(f"{run_dir}/tb")
        acc.Reload()
        tags = sorted(t for t in acc.Tags()["scalars"] if t.startswith("term/"))
        print("trainer TensorBoard tags: " + ", ".join(tags))
        for tag in ("term/speeding", "term/velocity"):
            if tag in tags:
                values = [e.value for e in acc.Scalars(tag)]
                print(f"  {tag}: last {values[-1]:+.4f} (mean per agent-episode, {len(values)} points)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="a few seconds (CI)")
    parser.add_argument("--no-train", action="store_true", help="skip the short PPO run")
    args = parser.parse_args()
    tiny = args.tiny or os.environ.get("SELFPLAYDRIVE_EXAMPLE_TINY") == "1"

    road_map = ProceduralTownLoader(seed=1, size=400.0, num_roundabouts=0).load()
    spawner = PaperSpawner(
        num_agents=8, num_static=4, num_pedestrians=2, min_region_lane_length=300.0, episode_lengths=[2.0]
    )
    hook = SpeedingPenalty([road_map], coef=0.01)
    env = make_env(road_map, spawner=spawner, num_worlds=2 if tiny else 8, reward_hooks=[hook], seed=0)
    env.reset(seed=0)
    print(f"term names: {', '.join(env.term_names)}")
    limits = hook.limits(env.state)[env.masks]
    print(f"lane speed limits under the agents [m/s]: {sorted({round(float(v), 2) for v in limits})}")
    drive(env, 60 if tiny else 400)
    print_episode_logs(env)
    if not args.no_train:
        train_and_read_logs(env, tiny)


if __name__ == "__main__":
    main()
