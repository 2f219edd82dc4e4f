"""Episode bookkeeping of a training or evaluation run: returns per agent-episode and the
env's per-world episode statistics (`VecEnv.pop_episode_stats`) turned into summary metrics.

Definitions (docs/training.md, "Reading the logs"):
- waypoint completion = waypoints reached / waypoints assigned, summed over the finished
  world-episodes (assigned = `num_wp` of every valid agent when the world was spawned);
- collision / off-road / red-light rate = agents with at least one such event / agents;
- events per km = event count (agent-steps in contact) / km driven by all agents;
- return = the sum of an agent's rewards over its episode, averaged over agent-episodes.
"""

from __future__ import annotations

import numpy as np

from selfplaydrive.eval.sampling import first_episodes_quota

RATE_EVENTS = {"collision": "collision", "offroad": "offroad", "red_light": "red_light"}
PER_KM_EVENTS = ("collision", "offroad", "red_light", "waypoint")


class EpisodeTracker:
    """Collects finished episodes of a `VecEnv` step by step.

    Args:
        env: The `VecEnv` (read: `state.num_wp`, `state.agent_valid`, `agents_per_world`).
    """

    def __init__(self, env) -> None:
        self.env = env
        self.num_worlds = int(env.num_worlds)
        self.agents_per_world = int(env.agents_per_world)
        self.slot_return = np.zeros(env.num_agents, dtype=np.float64)
        self.assigned = np.zeros(self.num_worlds, dtype=np.int64)
        self.records: list[dict[str, object]] = []
        self.returns: list[float] = []
        self.episode_index = np.zeros(self.num_worlds, dtype=np.int64)
        self.quota: np.ndarray | None = None

    def count_first(self, episodes: int | None) -> None:
        """Keep only each world's first episodes after the next reset, `episodes` in all
        (`eval.sampling.first_episodes_quota`), and only the returns of their agents: an
        evaluation's unbiased sample of episode lengths. None keeps every episode (training)."""
        self.quota = None if episodes is None else first_episodes_quota(episodes, self.num_worlds)

    @property
    def quota_met(self) -> bool:
        """With a quota: every world has finished its quota of episodes since the reset."""
        return self.quota is not None and bool((self.episode_index >= self.quota).all())

    def on_reset(self) -> None:
        """Call after `env.reset`: forget partial returns, read the new waypoint counts."""
        self.slot_return[:] = 0.0
        self.episode_index[:] = 0
        self.env.pop_episode_stats()
        self._read_assigned(np.arange(self.num_worlds))

    def on_step(self, acted: np.ndarray) -> None:
        """Call after `env.step`.

        Args:
            acted: (N,) bool, the slots that acted in this step (`env.masks` before the step).
        """
        env = self.env
        self.slot_return += np.where(acted, env.rewards, 0.0)
        ended = acted & (env.terminations | env.truncations)
        if ended.any():
            slots = np.flatnonzero(ended)
            if self.quota is not None:  # the episode an agent ends in has not been counted yet
                w = slots // self.agents_per_world
                slots = slots[self.episode_index[w] < self.quota[w]]
            self.returns.extend(self.slot_return[slots].tolist())
            self.slot_return[ended] = 0.0
        stats = env.pop_episode_stats()
        if stats:
            worlds = np.array([int(rec["world"]) for rec in stats])
            for rec in stats:
                w = int(rec["world"])
                rec["waypoints_assigned"] = int(self.assigned[w])
                rec["episode_index"] = int(self.episode_index[w])
                if self.quota is None or self.episode_index[w] < self.quota[w]:
                    self.records.append(rec)
                self.episode_index[w] += 1
            # the ended worlds were resampled inside step: their rows now hold the new episode
            self._read_assigned(worlds)

    def _read_assigned(self, worlds: np.ndarray) -> None:
        A = self.agents_per_world
        num_wp = np.asarray(self.env.state.num_wp).reshape(self.num_worlds, A)
        valid = np.asarray(self.env.state.agent_valid).reshape(self.num_worlds, A).astype(bool)
        self.assigned[worlds] = np.where(valid[worlds], num_wp[worlds], 0).sum(axis=1)

    def pop(self) -> tuple[list[dict[str, object]], list[float]]:
        """World-episode records and agent-episode returns collected since the last call."""
        out = (self.records, self.returns)
        self.records, self.returns = [], []
        return out

    def state_dict(self) -> dict[str, object]:
        return {
            "slot_return": self.slot_return.copy(),
            "assigned": self.assigned.copy(),
            "records": list(self.records),
            "returns": list(self.returns),
            "episode_index": self.episode_index.copy(),
        }

    def load_state_dict(self, state: dict[str, object]) -> None:
        self.slot_return[:] = state["slot_return"]
        self.assigned[:] = state["assigned"]
        self.records = list(state["records"])
        self.returns = list(state["returns"])
        if "episode_index" in state:  # checkpoints before session 26 lack it
            self.episode_index[:] = state["episode_index"]


def summarize(records: list[dict[str, object]], returns: list[float]) -> dict[str, float]:
    """Summary metrics of finished episodes (module docstring); empty dict when none.

    Args:
        records: World-episode records from `EpisodeTracker.pop`.
        returns: Agent-episode returns from `EpisodeTracker.pop`.

    Returns:
        Keys: episodes, agent_episodes, return_mean, waypoint_completion, {collision, offroad,
        red_light}_rate, {collision, offroad, red_light, waypoint}_per_km, km, length_s, and
        term/<name> (mean per-agent episode sum of each reward term).
    """
    if not records:
        return {"agent_episodes": float(len(returns))} | (
            {"return_mean": float(np.mean(returns))} if returns else {}
        )
    agents = sum(int(r["num_agents"]) for r in records)
    km = sum(float(r["km"]) for r in records)
    assigned = sum(int(r.get("waypoints_assigned", 0)) for r in records)
    reached = sum(int(r["events"]["waypoint"]) for r in records)
    out: dict[str, float] = {
        "episodes": float(len(records)),
        "agent_episodes": float(len(returns)),
        "km": km,
        "length_s": float(np.mean([float(r["length_s"]) for r in records])),
        "waypoint_completion": reached / assigned if assigned else float("nan"),
    }
    if returns:
        out["return_mean"] = float(np.mean(returns))
    for key, name in RATE_EVENTS.items():
        out[f"{key}_rate"] = sum(int(r["agents_with"][name]) for r in records) / max(agents, 1)
    for name in PER_KM_EVENTS:
        count = sum(int(r["events"][name]) for r in records)
        out[f"{name}_per_km"] = count / km if km > 0 else float("nan")
    for term in records[0]["terms"]:
        out[f"term/{term}"] = sum(float(r["terms"][term]) for r in records) / max(agents, 1)
    return out
