"""PPO training throughput: agent-steps/s of whole updates (collection + learning) and of
collection alone, for any train config (docs/benchmarks.md, "Models and training").

    python benchmarks/bench_train.py                                  # the main job's settings
    python benchmarks/bench_train.py experiment=null                  # paper-size Deep Sets
    python benchmarks/bench_train.py experiment=null model=transformer --updates 2
    python benchmarks/bench_train.py --json trainer.torch_threads=2 env.num_threads=2

The first update is a warm-up and is not counted. Prints one line per update and a summary
(JSON with --json): model, parameters, agent slots, torch threads, env threads, and the mean
active agent-steps/s (overall and collection only) and slot-steps/s over the counted updates.
"""

from __future__ import annotations

import argparse
import json
import time

import torch

from selfplaydrive.builder import build_env, build_model, compose
from selfplaydrive.trainers.ppo.config import PPOConfig
from selfplaydrive.trainers.ppo.trainer import PPOTrainer


def measure(overrides: list[str], updates: int) -> dict[str, object]:
    """Run `updates` + 1 PPO updates; returns the throughput summary."""
    cfg = compose("train", overrides)
    env = build_env(cfg)
    model = build_model(cfg, env)
    fields = {k: v for k, v in dict(cfg.trainer).items() if k != "_target_"}
    fields.update(progress_bar=False, checkpoint_interval=0, total_steps=10**12)
    trainer = PPOTrainer(env, model, PPOConfig.from_dict(fields), None)
    trainer.train(num_updates=1)  # warm-up: allocations, first reset
    steps = collect_time = total_time = 0.0
    for _ in range(updates):
        steps0 = trainer.agent_steps
        t0 = time.perf_counter()
        trainer.collect()
        trainer.compute_advantages()
        t1 = time.perf_counter()
        trainer.update()
        trainer.update_idx += 1
        t2 = time.perf_counter()
        n = trainer.agent_steps - steps0
        print(f"update: {n} agent-steps, collect {t1 - t0:.2f} s, learn {t2 - t1:.2f} s", flush=True)
        steps += n
        collect_time += t1 - t0
        total_time += t2 - t0
    return {
        "model": type(model).__name__,
        "parameters": sum(p.numel() for p in model.parameters()),
        "obs_dim": env.layout.obs_dim,
        "agent_slots": env.num_agents,
        "rollout_length": trainer.config.rollout_length,
        "torch_threads": torch.get_num_threads(),
        "env_threads": int(cfg.env.num_threads),
        "updates": updates,
        "agent_steps_per_s": steps / total_time,
        "collect_agent_steps_per_s": steps / collect_time,
        "slot_steps_per_s": updates * trainer.slots_per_update / total_time,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the train config")
    parser.add_argument("--updates", type=int, default=5, help="counted updates (after one warm-up)")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    args = parser.parse_args()
    result = measure(args.overrides, args.updates)
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"{result['model']} ({result['parameters']:,} params, obs {result['obs_dim']}), "
            f"{result['agent_slots']} slots, torch threads {result['torch_threads']}, env threads "
            f"{result['env_threads']}: {result['agent_steps_per_s']:,.0f} agent-steps/s overall, "
            f"{result['collect_agent_steps_per_s']:,.0f} collecting; "
            f"{result['slot_steps_per_s']:,.0f} slot-steps/s (padding and ended agents included)"
        )


if __name__ == "__main__":
    main()
