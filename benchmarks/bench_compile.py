"""The most `torch.compile` can give one PPO minibatch on this machine (issue #16 item 1).

Trains a few updates of any train config, then times forward + backward of one fixed minibatch
(`PPOTrainer.minibatch_loss`, the first of the last update's shuffled split) eagerly and under
`torch.compile`, alternated, medians. The minibatch never changes, so the compiled code never
recompiles: an upper bound for training, where every minibatch has other sizes (active
entries, set sizes, winners of the max pooling) and `trainer.compile=true` runs dynamic-shape
kernels (docs/benchmarks.md, "Trainer").

    python benchmarks/bench_compile.py model=deepsets_laptop spawner.num_agents=32 env.num_worlds=4
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_train import build_trainer


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the train config")
    parser.add_argument("--warmup-updates", type=int, default=3, help="updates trained before timing")
    parser.add_argument("--rounds", type=int, default=15, help="timed minibatches per variant")
    args = parser.parse_args()

    import torch

    from selfplaydrive.trainers.run import seed_everything

    trainer, _ = build_trainer([*args.overrides, "trainer.overlap_collection=false"], seed_everything)
    trainer.train(num_updates=args.warmup_updates)
    slots = torch.tensor_split(trainer._live_slots(), trainer.config.num_minibatches)[0]

    def step(loss_fn) -> float:
        start = time.perf_counter()
        trainer.optimizer.zero_grad(set_to_none=True)
        loss, _ = loss_fn(slots)
        loss.backward()
        return time.perf_counter() - start

    eager = trainer.minibatch_loss
    compiled = torch.compile(trainer.minibatch_loss)
    first = step(compiled)
    for _ in range(3):  # warm both
        step(compiled)
        step(eager)
    times: dict[str, list[float]] = {"eager": [], "compiled": []}
    for _ in range(args.rounds):
        times["eager"].append(step(eager))
        times["compiled"].append(step(compiled))
    e, c = (statistics.median(times[k]) for k in ("eager", "compiled"))
    active = int(trainer.storage.active.index_select(1, slots).sum())
    print(
        f"minibatch of {len(slots)} slots ({active} active entries): eager {e * 1e3:.1f} ms, "
        f"compiled {c * 1e3:.1f} ms (first call, compiling: {first:.1f} s); eager / compiled {e / c:.2f}"
    )


if __name__ == "__main__":
    main()
