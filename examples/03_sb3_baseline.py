"""Example 03: the quick baseline, stable-baselines3 PPO on `SB3VecEnv`.

Every agent slot of every world is one SB3 env (docs/interfaces/sb3.md). The policy reads the
observation with the Deep Sets feature extractor of `trainer=sb3`
(selfplaydrive/trainers/sb3.py): per-modality MLPs and a masked max over the object and road
sets. The same run from the command line, with a run folder:

    selfplaydrive train trainer=sb3 trainer.total_timesteps=5000 env.num_worlds=2

Run: python examples/03_sb3_baseline.py [--tiny]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings
from dataclasses import asdict

import torch
from stable_baselines3 import PPO

from selfplaydrive import make_env
from selfplaydrive.env import SB3VecEnv
from selfplaydrive.maps.procedural import ProceduralTownLoader
from selfplaydrive.obs.config import ObsConfig
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.trainers.sb3 import DeepSetsExtractor, evaluate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="a few seconds (CI)")
    args = parser.parse_args()
    tiny = args.tiny or os.environ.get("SELFPLAYDRIVE_EXAMPLE_TINY") == "1"
    torch.set_num_threads(1 if tiny else max(torch.get_num_threads(), 1))

    road_map = ProceduralTownLoader(seed=0, size=400.0, num_roundabouts=0).load()
    spawner = PaperSpawner(
        num_agents=8,
        num_static=8,
        num_pedestrians=2,
        min_region_lane_length=300.0,
        episode_lengths=[3.0] if tiny else [20.0, 30.0],
    )
    native = make_env(
        road_map,
        spawner=spawner,
        num_worlds=2 if tiny else 8,
        obs=ObsConfig(max_objects=16, max_road=64, radius=60.0),
        seed=0,
    )
    venv = SB3VecEnv(native, seed=0)
    policy_kwargs = {
        "features_extractor_class": DeepSetsExtractor,
        "features_extractor_kwargs": {"layout": asdict(native.layout), "embed_size": 32, "features_dim": 64},
        "net_arch": {"pi": [64], "vf": [64]},
    }
    n_steps = 16 if tiny else 64
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=n_steps,
        batch_size=128 if tiny else 512,
        n_epochs=2 if tiny else 4,
        learning_rate=3e-4,
        ent_coef=0.005,
        policy_kwargs=policy_kwargs,
        seed=0,
        device="cpu",
    )
    total = (2 if tiny else 8) * n_steps * venv.num_envs
    print(f"SB3 PPO on {venv.num_envs} agent slots ({native.num_worlds} worlds), {total} slot-steps")
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        model.learn(total_timesteps=total)
        print(f"trained {model.num_timesteps} slot-steps in {time.perf_counter() - start:.1f} s")
        summary = evaluate(
            model, venv, episodes=2, max_steps=100 if tiny else 1000, deterministic=False, seed=1_000
        )
    for key in ("episodes", "waypoint_completion", "collision_rate", "offroad_rate", "return_mean"):
        print(f"  eval {key:20s} {summary.get(key, float('nan')):.3f}")
    with tempfile.TemporaryDirectory() as tmp:
        model.save(f"{tmp}/model.zip")
        again = PPO.load(f"{tmp}/model.zip", device="cpu")
        print(f"saved and reloaded: {type(again.policy.features_extractor).__name__}")


if __name__ == "__main__":
    main()
