"""Learning smoke tests of the PPO trainer with a fixed seed on the CPU (issue item 3).

Task (ppo_helpers): a straight one-way three-lane road; 2-4 agents per world start on the
middle lane at 6-9 m/s, heading up to 0.2 rad off the lane direction; each has 6 waypoints
15 m apart on the lane centre, reached within 2 m; an episode lasts 10 s; a road-edge contact
or a collision ends the agent. A uniform random policy reaches under 10 % of the waypoints (it
wanders off the road or misses the first waypoint); straightening up, keeping the lane centre
and holding or gaining speed reaches nearly all of them.

Waypoint completion = waypoints reached / waypoints assigned, summed over the world-episodes
that ended during the evaluation (`trainers.ppo.episodes`). Both evaluations sample actions
from the policy (the untrained policy is near uniform: its actor is initialised at gain 0.01).
"""

from __future__ import annotations

import time

import torch
from ppo_helpers import lane_env

from selfplaydrive.models import DeepSetsModel
from selfplaydrive.trainers import PPOConfig, PPOTrainer

TASK = dict(num_waypoints=6, spacing=15.0, episode_length=10.0, initial_speed=(6.0, 9.0), heading_noise=0.2)
TASK_COEFFS = dict(waypoint_radius=2.0)
EVAL_SEED = 123


def make_trainer(
    num_worlds: int, updates: int, task: dict, coeffs: dict, anneal_lr: bool = True
) -> PPOTrainer:
    torch.manual_seed(0)
    env = lane_env(num_worlds=num_worlds, seed=0, coeffs=coeffs, **task)
    model = DeepSetsModel(env.layout, input_size=32, hidden_size=64, lstm_size=64)
    rollout = 32
    cfg = PPOConfig(
        total_steps=updates * rollout * env.num_agents,
        rollout_length=rollout,
        learning_rate=2e-3,
        anneal_lr=anneal_lr,
        ent_coef=0.0,
        device="cpu",
        torch_threads=1,
        progress_bar=False,
        seed=0,
    )
    return PPOTrainer(env, model, cfg)


def evaluate(trainer: PPOTrainer, episodes: int) -> dict[str, float]:
    return trainer.evaluate(episodes, 3000, deterministic=False, seed=EVAL_SEED)


# About 30 s on the development machine (65 s before issue #16): in the default suite, since
# it is issue #5's acceptance test for learning.
def test_waypoint_completion_rises_from_under_10_to_over_60_percent():
    t0 = time.perf_counter()
    trainer = make_trainer(num_worlds=32, updates=100, task=TASK, coeffs=TASK_COEFFS)
    # The random policy completes 7-11 % of its waypoints over 64 world-episodes, depending on
    # the sampling seed (0.070-0.109 for seeds 0 and 6-8, before and after issue #16's trainer
    # changed which random numbers acting draws); 256 episodes measure its mean, about 9 %.
    before = evaluate(trainer, 256)
    trainer.train()
    after = evaluate(trainer, 64)
    print(
        f"waypoint completion {before['waypoint_completion']:.3f} -> {after['waypoint_completion']:.3f}, "
        f"return {before['return_mean']:.3f} -> {after['return_mean']:.3f}, "
        f"{trainer.agent_steps} agent-steps, {time.perf_counter() - t0:.0f} s"
    )
    assert before["episodes"] >= 256 and after["episodes"] >= 64
    assert before["waypoint_completion"] < 0.10
    assert after["waypoint_completion"] > 0.60
    assert after["offroad_rate"] < before["offroad_rate"]


def test_return_and_completion_improve_within_a_few_updates():
    """Fast variant on an easier task (the helper's defaults: 6 waypoints 12 m apart reached
    within 3 m, start at 4-8 m/s, random completion about 20 %): after 16 updates (66k
    slot-steps) the mean return rises by more than 0.3 (more than one extra waypoint worth 0.25,
    or no road-edge penalty of 0.5) and the completion by half.

    Six updates were too few to pass on every CPU: the same seed gave +0.19 on an AVX-512 Xeon and
    +0.38 on an AVX2 EPYC (float rounding of the kernels steers the short run), and torch seeds
    1-2 gave +0.45/+0.77 with completion gains of 1.4x/2.5x. With 16 updates, torch seeds 0-4 gave
    +0.75 to +1.25 and 2.3x to 4.2x on the Xeon (session 28)."""
    trainer = make_trainer(num_worlds=32, updates=16, task={}, coeffs={}, anneal_lr=False)
    before = evaluate(trainer, 32)
    trainer.train()
    after = evaluate(trainer, 32)
    print(
        f"return {before['return_mean']:.3f} -> {after['return_mean']:.3f}, waypoint completion "
        f"{before['waypoint_completion']:.3f} -> {after['waypoint_completion']:.3f}"
    )
    assert after["return_mean"] > before["return_mean"] + 0.3
    assert after["waypoint_completion"] > 1.5 * before["waypoint_completion"]
