"""Example 01: compose an env in plain Python from components, with your own spawner and your
own observation feature.

What it shows:
- a procedural map (`ProceduralTownLoader`), the paper's spawner (`PaperSpawner`), a physics
  model (`BicycleModel`) and a custom `ObsConfig`, put together with `VecEnv` (no Hydra);
- `OneLaneSpawner`: a user spawner written in NumPy that wraps `PaperSpawner` and lines every
  agent up on one lane (a platoon), with waypoints along that lane;
- `EpisodeClock`: a user observation feature (`ObsHook`) appended after the kernel columns;
- stepping with random actions and printing the per-term reward sums (paper section 2.3).

Run: python examples/01_custom_env.py [--tiny]   (or SELFPLAYDRIVE_EXAMPLE_TINY=1)
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import warnings

import numpy as np

from selfplaydrive.maps.procedural import ProceduralTownLoader
from selfplaydrive.maps.roadmap import LaneKind, RoadMap
from selfplaydrive.obs.config import ObsConfig
from selfplaydrive.physics import BicycleModel
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.scenario.types import Scenario
from selfplaydrive.sim import VecEnv


class OneLaneSpawner:
    """Spawner wrapper: every agent of the base scenario is moved onto one randomly chosen lane.

    Agents stand `gap` metres apart along the lane's centreline, heading along it, with
    waypoints every `waypoint_gap` metres ahead of them on the same lane. Agents that do not fit
    on the lane are dropped (their slots marked invalid), and static vehicles closer than
    `clearance` to a placed agent are removed. Everything else (pedestrians, lights, reward
    coefficients, episode length) is the base spawner's.

    Args:
        base: Any spawner (`sample(road_map, rng, map_index) -> Scenario`).
        min_lane_length: Only lanes at least this long [m] are chosen.
        gap: Distance between consecutive agents along the lane [m].
        waypoint_gap: Distance between waypoints [m].
        clearance: Static vehicles closer than this to an agent are removed [m].
    """

    def __init__(
        self,
        base: PaperSpawner,
        min_lane_length: float = 40.0,
        gap: float = 15.0,
        waypoint_gap: float = 10.0,
        clearance: float = 5.0,
    ) -> None:
        self.base = base
        self.min_lane_length = min_lane_length
        self.gap = gap
        self.waypoint_gap = waypoint_gap
        self.clearance = clearance

    def sample(self, road_map: RoadMap, rng: np.random.Generator, map_index: int = 0) -> Scenario:
        sc = self.base.sample(road_map, rng, map_index)
        lanes = road_map.lanes
        lengths = lanes.centerlines.lengths()
        ok = (lanes.kind == LaneKind.VEHICLE) & ~lanes.in_junction & (lengths >= self.min_lane_length)
        if not ok.any():
            raise ValueError(f"OneLaneSpawner: map {road_map.name!r} has no lane >= {self.min_lane_length} m")
        lane = int(rng.choice(np.flatnonzero(ok)))
        line = lanes.centerlines[lane].astype(np.float64)
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
        A, K = sc.agent_valid.shape[0], sc.waypoints.shape[1]
        n = min(int(sc.agent_valid.sum()), int((cum[-1] - self.gap) // self.gap) + 1)
        s = self.gap / 2 + self.gap * np.arange(n)  # arc length of each agent [m]
        xy, heading = _along(line, cum, s)
        valid = np.zeros(A, dtype=bool)
        valid[:n] = True
        sc = dataclasses.replace(
            sc,
            agent_valid=valid,
            agent_xy=_pad(xy, A).astype(np.float32),
            agent_heading=_pad(heading, A).astype(np.float32),
            agent_speed=np.where(valid, np.minimum(sc.agent_speed, lanes.speed_limit[lane]), 0).astype(
                np.float32
            ),
            agent_parked=np.zeros(A, dtype=bool),
            agent_lane=np.where(valid, lane, -1).astype(np.int32),
        )
        sc.waypoints, sc.num_waypoints = self._waypoints(line, cum, s, A, K)
        near = np.linalg.norm(sc.static_xy[:, None, :] - xy[None, :, :], axis=2).min(axis=1, initial=np.inf)
        sc.static_valid = sc.static_valid & (near > self.clearance)
        return sc

    def _waypoints(self, line, cum, s, A: int, K: int) -> tuple[np.ndarray, np.ndarray]:
        """(A, K, 2) waypoints ahead on the lane (padded with the last) and their counts."""
        wp = np.zeros((A, K, 2), dtype=np.float32)
        count = np.zeros(A, dtype=np.int32)
        for i, si in enumerate(s):
            ahead = si + self.waypoint_gap * np.arange(1, K + 1)
            ahead = ahead[ahead <= cum[-1]]
            if len(ahead) == 0:
                ahead = np.array([cum[-1]])
            pts, _ = _along(line, cum, ahead)
            wp[i, : len(pts)] = pts
            wp[i, len(pts) :] = pts[-1]
            count[i] = len(pts)
        return wp, count


def _along(line: np.ndarray, cum: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 2) [m] and headings (n,) [rad] at arc lengths `s` along polyline `line`."""
    seg = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(line) - 2)
    d = line[seg + 1] - line[seg]
    t = ((s - cum[seg]) / np.maximum(cum[seg + 1] - cum[seg], 1e-9))[:, None]
    return line[seg] + t * d, np.arctan2(d[:, 1], d[:, 0])


def _pad(values: np.ndarray, size: int) -> np.ndarray:
    out = np.zeros((size, *values.shape[1:]), dtype=values.dtype)
    out[: len(values)] = values
    return out


class EpisodeClock:
    """Observation feature: the share of the world's episode time that is left, in [0, 1]
    (the paper's observation has no clock; this lets a policy see the time limit coming)."""

    name = "episode_clock"
    dim = 1

    def __call__(self, state) -> np.ndarray:
        steps = np.asarray(state.step, dtype=np.float32)
        limit = np.asarray(state.max_steps, dtype=np.float32)
        left = 1.0 - steps / np.maximum(limit, 1.0)  # (W,) per world
        per_agent = np.repeat(left, len(state.x) // len(left))
        return per_agent[:, None].astype(np.float32)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="a few seconds (CI)")
    parser.add_argument("--steps", type=int, default=None, help="env steps (default 400, tiny 40)")
    args = parser.parse_args()
    tiny = args.tiny or os.environ.get("SELFPLAYDRIVE_EXAMPLE_TINY") == "1"
    steps = args.steps or (40 if tiny else 400)

    road_map = ProceduralTownLoader(seed=0, size=400.0 if tiny else 500.0, num_roundabouts=0).load()
    base = PaperSpawner(num_agents=8, num_static=8, num_pedestrians=4, min_region_lane_length=300.0)
    env = VecEnv(
        road_map,
        OneLaneSpawner(base),
        num_worlds=2 if tiny else 8,
        physics=BicycleModel(),
        obs=ObsConfig(max_objects=16, max_road=64, radius=60.0),
        obs_hooks=[EpisodeClock()],
        seed=0,
    )
    obs = env.reset(seed=0)
    lanes = env.state.agent_valid.reshape(env.num_worlds, -1).sum(axis=1)
    print(f"map {road_map.name}: {road_map.vehicle_lane_km():.1f} km of lanes")
    print(f"one-lane spawner: {lanes.tolist()} agents per world, obs_dim {obs.shape[1]}")
    print(f"episode_clock feature at reset: {obs[env.masks, -1].min():.2f} (1 = all time left)")

    rng = np.random.default_rng(0)
    sums = np.zeros(len(env.term_names))
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        for _ in range(steps):
            actions = np.stack([env.action_space.sample() for _ in range(env.num_agents)])
            actions[:, 0] = rng.integers(3, 7, size=env.num_agents)  # mostly forward
            env.step(actions)
            acted = env.reward_mask
            sums += env.reward_terms[acted].sum(axis=0)  # one column per term (term_names)
    print(f"per-term reward sums over {steps} steps (all agents):")
    for name, value in zip(env.term_names, sums, strict=True):
        print(f"  {name:10s} {value:+10.4f}")
    print(f"episodes finished: {len(env.pop_episode_stats())}")


if __name__ == "__main__":
    main()
