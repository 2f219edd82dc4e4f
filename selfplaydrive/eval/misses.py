"""Where the missed waypoints go: each agent of each finished world-episode gets one outcome,
and the waypoints it did not reach are charged to it, so the shares add up to
1 - waypoint completion.

Outcomes (first match wins; `ever` bits are the episode's SD_EV_* events):

- `all_reached`: no waypoint pending at the end;
- `vehicle_collision`: touched a vehicle (another agent or a parked one);
- `pedestrian`: touched a pedestrian (and no vehicle);
- `road_edge`: touched a road edge (and neither of the above);
- `off_route`: none of those, and the pending waypoint lies behind the car (it drove past it
  outside the reach radius: a wrong turn, the wrong lane, or a miss by a few metres);
- `pending_ahead`: none of those, and the pending waypoint is still ahead when time ran out
  (too slow, stopped, blocked, or waiting at lights).

With `reward.terminate_threshold: 0` (the main job) every contact ends the agent, so the three
contact outcomes are the agents ended by that contact; under the paper's thresholds an agent
with a small coefficient drives on after a contact and is still charged to it.

Example:
    >>> from selfplaydrive.eval.misses import completion_breakdown
    >>> table = completion_breakdown(env, policy, world_episodes=16)  # doctest: +SKIP
    >>> print(table.markdown())  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from selfplaydrive.eval.sampling import FirstEpisodes
from selfplaydrive.sim.vec_env import EVER_BITS

OUTCOMES = ("all_reached", "vehicle_collision", "pedestrian", "road_edge", "off_route", "pending_ahead")


def classify(ever: np.ndarray, reached: np.ndarray, assigned: np.ndarray, ahead_m: np.ndarray) -> np.ndarray:
    """Outcome index (into `OUTCOMES`) of each agent (arrays of one length, see module docstring)."""
    ever = np.asarray(ever).astype(np.int64)
    done = np.asarray(reached) >= np.asarray(assigned)
    behind = np.nan_to_num(np.asarray(ahead_m, dtype=np.float64), nan=1.0) < 0.0
    return np.select(
        [
            done,
            (ever & EVER_BITS["collision"]) != 0,
            (ever & EVER_BITS["pedestrian_collision"]) != 0,
            (ever & EVER_BITS["offroad"]) != 0,
            behind,
        ],
        [0, 1, 2, 3, 4],
        default=5,
    )


@dataclass
class MissBreakdown:
    """Agents, waypoints reached and waypoints assigned per outcome, summed over episodes."""

    agents: dict[str, int] = field(default_factory=lambda: dict.fromkeys(OUTCOMES, 0))
    reached: dict[str, int] = field(default_factory=lambda: dict.fromkeys(OUTCOMES, 0))
    assigned: dict[str, int] = field(default_factory=lambda: dict.fromkeys(OUTCOMES, 0))
    episodes: int = 0

    def add(self, outcomes: Mapping[str, Any]) -> None:
        """Count one episode record's "agents" entry (`VecEnv.record_agents`)."""
        kind = classify(outcomes["ever"], outcomes["reached"], outcomes["assigned"], outcomes["ahead_m"])
        reached = np.minimum(outcomes["reached"], outcomes["assigned"])
        for i, name in enumerate(OUTCOMES):
            sel = kind == i
            self.agents[name] += int(sel.sum())
            self.reached[name] += int(reached[sel].sum())
            self.assigned[name] += int(np.asarray(outcomes["assigned"])[sel].sum())
        self.episodes += 1

    @property
    def completion(self) -> float:
        """Waypoints reached / assigned over every agent (the paper's waypoint completion)."""
        total = sum(self.assigned.values())
        return sum(self.reached.values()) / total if total else float("nan")

    def missed_share(self, name: str) -> float:
        """Waypoints missed by agents of outcome `name`, as a share of all assigned waypoints."""
        total = sum(self.assigned.values())
        return (self.assigned[name] - self.reached[name]) / total if total else float("nan")

    def to_dict(self) -> dict[str, Any]:
        n = sum(self.agents.values())
        return {
            "episodes": self.episodes,
            "agents": n,
            "waypoint_completion": self.completion,
            "outcomes": {
                name: {
                    "agents": self.agents[name],
                    "agent_share": self.agents[name] / n if n else float("nan"),
                    "reached": self.reached[name],
                    "assigned": self.assigned[name],
                    "missed_share": self.missed_share(name),
                }
                for name in OUTCOMES
            },
        }

    def markdown(self) -> str:
        """A table: outcome, agents (share), waypoints reached / assigned, missed share of all."""
        n = max(sum(self.agents.values()), 1)
        lines = [
            f"waypoint completion {self.completion:.1%} over {self.episodes} world-episodes, "
            f"{sum(self.agents.values())} agents",
            "",
            "| outcome | agents | waypoints reached / assigned | missed (share of all waypoints) |",
            "|---|---|---|---|",
        ]
        for name in OUTCOMES:
            lines.append(
                f"| {name} | {self.agents[name]} ({self.agents[name] / n:.1%}) | {self.reached[name]} / "
                f"{self.assigned[name]} | {self.missed_share(name):.1%} |"
            )
        return "\n".join(lines)


def breakdown_of(records: Iterable[Mapping[str, Any]]) -> MissBreakdown:
    """`MissBreakdown` of episode records that carry "agents" (`VecEnv.record_agents = True`)."""
    out = MissBreakdown()
    for rec in records:
        if "agents" not in rec:
            raise ValueError(
                "episode record without 'agents': set env.record_agents = True before stepping "
                "(selfplaydrive.eval.misses)"
            )
        out.add(rec["agents"])
    return out


def completion_breakdown(
    env: Any,
    policy: Callable[[np.ndarray, Any], np.ndarray],
    world_episodes: int,
    seed: int | None = None,
    max_steps: int = 20_000,
    recorders: Sequence[Any] = (),
) -> MissBreakdown:
    """Drive `env` with `policy(observations, env)` (e.g. `policies.make_policy`) from a reset
    until every world has finished its share of `world_episodes` world-episodes (its first ones,
    `eval.sampling`; or `max_steps` env steps) and break their
    missed waypoints down by outcome.

    Args:
        env: A `VecEnv`; its `record_agents` flag is set for the run and restored after.
        policy: Maps the env's observations to actions.
        world_episodes: Finished world-episodes to count (at least 1).
        seed: Reset seed (None: the env's own).
        max_steps: Env steps at most.
        recorders: Objects whose `record()` reads the env after every step (e.g.
            `eval.collisions.CollisionRecorder`), so one rollout feeds several analyses.
    """
    if int(world_episodes) < 1:
        raise ValueError(f"world_episodes: expected >= 1, got {world_episodes!r}")
    before = env.record_agents
    env.record_agents = True
    first = FirstEpisodes(int(world_episodes), env.num_worlds)  # each world's first ones
    try:
        env.reset(seed=seed)
        if hasattr(policy, "reset"):
            policy.reset()
        for _ in range(int(max_steps)):
            env.step(policy(env.observations, env))
            for rec in recorders:
                rec.record()
            first.add(env.pop_episode_stats())
            if first.done:
                break
    finally:
        env.record_agents = before
    return breakdown_of(first.kept)
