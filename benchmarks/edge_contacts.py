"""Where does a policy touch road edges? Drives it in the shipped policy's env under the paper's
fixed evaluation coefficients and classifies every road-edge contact onset by the road around
the car (`selfplaydrive.eval.edge_contacts`: a dead-end lane's end, an edge crossing the car's
path, a junction lane, an ordinary lane). docs/analyses.md "Where road-edge contacts happen"
records the result for the shipped policy.

    python benchmarks/edge_contacts.py                                   # pretrained, town and Tartu
    python benchmarks/edge_contacts.py --policy rule_based --maps tartu
    python benchmarks/edge_contacts.py --policy runs/x/checkpoints/final.pt --steps 3000 --json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any


def run(
    policy: str, map_name: str, steps: int, seed: int, agents: int | None, greedy: bool
) -> dict[str, Any]:
    """Classified road-edge onsets of `policy` on `map_name` (the shipped run's env otherwise)."""
    from selfplaydrive import pretrained
    from selfplaydrive.builder import build_env
    from selfplaydrive.eval.edge_contacts import edge_contacts
    from selfplaydrive.policies import find_run_config, is_builtin, make_policy
    from selfplaydrive.pretrained import resolve_spec

    builtin = is_builtin(resolve_spec(policy))
    own = None if builtin or policy == pretrained.NAME else find_run_config(policy)
    cfg = pretrained.evaluation_config(map_name, agents, sizes_from=own)  # a candidate: its own obs and model
    env = build_env(cfg)
    driver = make_policy(policy, env, **({} if builtin else {"deterministic": greedy}))
    start = time.perf_counter()
    table = edge_contacts(env, driver, steps, seed=seed)
    return {
        "policy": policy,
        "map": map_name,
        "steps": steps,
        "seed": seed,
        "worlds": int(cfg.env.num_worlds),
        "agents_per_world": int(cfg.spawner.num_agents),
        "actions": "the driver's own" if builtin else ("greedy" if greedy else "sampled"),
        "wall_s": round(time.perf_counter() - start, 1),
        "table": table.markdown(),
        **table.to_dict(),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--policy", default="pretrained", help="pretrained, rule_based or a checkpoint path")
    parser.add_argument("--maps", nargs="+", default=["default", "tartu"])
    parser.add_argument("--steps", type=int, default=1500, help="env steps (0.1 s each)")
    parser.add_argument("--seed", type=int, default=1234)
    parser.add_argument("--agents", type=int, default=None, help="agents per world (default: the run's)")
    parser.add_argument("--sampled", action="store_true", help="sample actions instead of the greedy ones")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    out = [run(args.policy, m, args.steps, args.seed, args.agents, not args.sampled) for m in args.maps]
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    for r in out:
        print(
            f"## {r['policy']} on map={r['map']}: {r['worlds']} worlds x {r['agents_per_world']} agents, "
            f"{r['steps']} steps, seed {r['seed']}, actions: {r['actions']} ({r['agent_steps']} agent-steps, "
            f"{r['wall_s']} s)\n"
        )
        print(r["table"] + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
