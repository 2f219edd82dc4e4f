"""Does a policy turn from the wrong lane for want of information or of skill? The turn-lane
suite (paper section 5.3, docs/suites.md) twice on the same sites: as the paper builds it (the
ego's waypoints lie after the junction only) and with a first waypoint on the correct lane
`--entry` m before the junction (`TurnLaneSuite(entry_waypoint=...)`), which names the lane to
take. docs/training.md "The pretrained policy" records the result for the shipped policy.

    python benchmarks/turn_lane_probe.py                                  # the pretrained policy
    python benchmarks/turn_lane_probe.py --policy rule_based --count 32
    python benchmarks/turn_lane_probe.py --policy runs/x/checkpoints/final.pt --map tartu
    python benchmarks/turn_lane_probe.py --policy runs/x/checkpoints/ckpt_0000400.pt --paper-only --seed 2
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def probe(
    policy: str, map_name: str, count: int, entry: float, seed: int, paper_only: bool = False
) -> dict[str, object]:
    """Outcome counts of both variants (scenarios generated from the same seed), or of the
    paper's variant only."""
    from selfplaydrive.builder import build_maps, compose
    from selfplaydrive.eval.app import EvalEnvFactory, resolve_target
    from selfplaydrive.eval.suites.report import run_all_suites
    from selfplaydrive.eval.suites.turn_lanes import OUTCOMES, TurnLaneSuite

    cfg = compose("eval", [f"policy={policy}", f"map={map_name}", f"seed={seed}"])
    target = resolve_target(cfg)
    maps = build_maps(cfg.map)
    factory = EvalEnvFactory(maps, target)
    out: dict[str, object] = {"policy": policy, "map": map_name, "seed": seed, "entry_waypoint_m": entry}
    variants = [("paper", TurnLaneSuite()), ("entry_waypoint", TurnLaneSuite(entry_waypoint=entry))]
    for label, suite in variants[: 1 if paper_only else 2]:
        start = time.perf_counter()
        res = run_all_suites(
            maps, target.policy.factory, {"turn_lanes": count}, seed, 64, factory, {"turn_lanes": suite}
        )["turn_lanes"]
        rows = [s["result"] for s in res["scenarios"]]
        out[label] = {
            "scenarios": len(rows),
            **{o: sum(r["outcome"] == o for r in rows) for o in OUTCOMES},
            "collided": sum(bool(r["collided"]) for r in rows),
            "wall_s": round(time.perf_counter() - start, 1),
        }
        print(f"{label}: {json.dumps(out[label])}", file=sys.stderr, flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    fmt = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=fmt)
    parser.add_argument("--policy", default="pretrained")
    parser.add_argument("--map", default="default")
    parser.add_argument("--count", type=int, default=128)
    parser.add_argument("--entry", type=float, default=15.0, help="[m] before the junction")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--paper-only", action="store_true", help="skip the variant that names the lane")
    args = parser.parse_args(argv)
    out = probe(args.policy, args.map, args.count, args.entry, args.seed, args.paper_only)
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
