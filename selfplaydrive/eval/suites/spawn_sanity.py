"""Suite "spawn sanity" (paper section 5.2): does the spawner start agents inside or right in
front of another body?

A fifth of the paper's Waymax failures (20 %) were "a vehicle spawns in front or inside of the
ego vehicle, and the policy collides with it": an initial state no policy can rescue. This suite
checks a spawner's own scenarios for that, without driving them (no policy).

Generation: `count` scenarios of the spawner (default `PaperSpawner()`, the paper's).

Classification (`classify_spawn`, pure): every valid agent's box is tested against every other
body at its initial pose: the other agents, the static vehicles and the pedestrians (a
pedestrian's box at the first point of its path, heading along its first leg). An agent
*overlaps* when its box intersects another body by more than `MIN_AREA` m^2, and is *close
ahead* when the box swept `HORIZON` s straight ahead at its initial speed (the box stretched
forward by v x `HORIZON`) does so instead: it would touch that body within a second unless it
or the body moved away. Per episode: "overlap" when any agent overlaps, else "close_ahead"
when any agent is close ahead, else "clear".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import shapely

from selfplaydrive.eval.stats import proportion
from selfplaydrive.eval.suites.base import SuiteScenario, Trajectory
from selfplaydrive.eval.suites.shapes import box_polygons, swept_boxes
from selfplaydrive.maps.roadmap import RoadMap

OUTCOMES = ("clear", "close_ahead", "overlap")
BODIES = ("agent", "static", "pedestrian")
HORIZON = 1.0  # [s] look-ahead at the initial speed
MIN_AREA = 0.01  # [m^2] intersection that counts (not a touch of two edges)
EXAMPLES = 10  # offending agents listed in the summary


class SpawnSanitySuite:
    """Generator and classifier of the spawn-sanity suite.

    Args:
        spawner: Any spawner with `sample(road_map, rng, map_index) -> Scenario`; default the
            paper's `PaperSpawner()`.
    """

    name = "spawn_sanity"
    needs_policy = False  # `run_all_suites` classifies the scenarios without driving them

    def __init__(self, spawner: Any = None) -> None:
        if spawner is None:
            from selfplaydrive.scenario.spawner import PaperSpawner

            spawner = PaperSpawner()
        self.spawner = spawner

    def generate(
        self, road_map: RoadMap, rng: np.random.Generator, count: int, map_index: int = 0
    ) -> list[SuiteScenario]:
        """`count` scenarios of the spawner on `road_map`."""
        out = []
        for i in range(int(count)):
            sc = self.spawner.sample(road_map, rng, map_index)
            info = {"map": road_map.name, "episode": i, "agents": int(np.sum(sc.agent_valid))}
            out.append(SuiteScenario(self.name, sc, {}, info))
        return out

    def classify(self, item: SuiteScenario, traj: Trajectory | None = None) -> dict[str, Any]:
        return classify_spawn(item)

    def summarise(self, outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
        return summarise_spawn(outcomes)


def bodies(sc) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every body of a scenario at its initial pose.

    Returns:
        polygons (m,), kind (m,) index into `BODIES`, slot (m,) within its kind.
    """
    a = np.flatnonzero(sc.agent_valid)
    s = np.flatnonzero(sc.static_valid)
    p = np.flatnonzero(sc.ped_valid)
    leg = sc.ped_path[p, 1] - sc.ped_path[p, 0]
    ped_heading = np.arctan2(leg[:, 1], leg[:, 0])
    polys = np.concatenate(
        [
            box_polygons(sc.agent_xy[a], sc.agent_heading[a], sc.agent_length[a], sc.agent_width[a]),
            box_polygons(sc.static_xy[s], sc.static_heading[s], sc.static_length[s], sc.static_width[s]),
            box_polygons(sc.ped_path[p, 0], ped_heading, sc.ped_size[p, 0], sc.ped_size[p, 1]),
        ]
    )
    kind = np.repeat(np.arange(3), [len(a), len(s), len(p)])
    return polys, kind, np.concatenate([a, s, p])


def classify_spawn(item: SuiteScenario) -> dict[str, Any]:
    """Outcome of one spawned scenario (see the module docstring); a pure function.

    Returns:
        outcome, map, episode, agents (valid agents), overlap / close_ahead (agent slots flagged), hits
        ([{slot, what, body, body_slot, speed_mps}] per flagged agent, its first offender).
    """
    sc = item.scenario
    polys, kind, slot = bodies(sc)
    tree = shapely.STRtree(polys)
    a = np.flatnonzero(sc.agent_valid)
    reach = sc.agent_speed[a].astype(np.float64) * HORIZON
    swept = swept_boxes(sc.agent_xy[a], sc.agent_heading[a], sc.agent_length[a], sc.agent_width[a], reach)
    hits = []
    for i, agent in enumerate(a):
        for what, shape in (("overlap", polys[i]), ("close_ahead", swept[i])):
            others = [j for j in tree.query(shape, predicate="intersects") if j != i]
            areas = shapely.area(shapely.intersection(shape, polys[others])) if others else np.zeros(0)
            found = [j for j, ar in zip(others, areas, strict=True) if ar > MIN_AREA]
            if found:
                j = int(found[0])
                hits.append(
                    {
                        "slot": int(agent),
                        "what": what,
                        "body": BODIES[int(kind[j])],
                        "body_slot": int(slot[j]),
                        "speed_mps": float(sc.agent_speed[agent]),
                    }
                )
                break
    over = [h["slot"] for h in hits if h["what"] == "overlap"]
    ahead = [h["slot"] for h in hits if h["what"] == "close_ahead"]
    outcome = "overlap" if over else "close_ahead" if ahead else "clear"
    return {
        "outcome": outcome,
        "map": item.info.get("map"),
        "episode": item.info.get("episode"),
        "agents": len(a),
        "overlap": over,
        "close_ahead": ahead,
        "hits": hits,
    }


def summarise_spawn(outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Shares of episodes and of agents flagged, by what they were flagged against, and the
    first `EXAMPLES` offending agents (map, episode, slot, body) to reproduce them."""
    n = len(outcomes)
    agents = sum(o["agents"] for o in outcomes)
    res: dict[str, Any] = {"n": n, "agents": agents}
    for name in OUTCOMES:
        res[name] = proportion(sum(o["outcome"] == name for o in outcomes), n).to_dict()
    flagged = [h for o in outcomes for h in o["hits"]]
    res["agents_flagged"] = proportion(len(flagged), agents).to_dict()
    res["agents_overlap"] = proportion(sum(h["what"] == "overlap" for h in flagged), agents).to_dict()
    res["agents_by_body"] = {b: sum(h["body"] == b for h in flagged) for b in BODIES}
    res["examples"] = [
        {"map": o.get("map"), "episode": o.get("episode"), **h} for o in outcomes for h in o["hits"]
    ][:EXAMPLES]
    return res
