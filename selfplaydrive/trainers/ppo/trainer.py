"""`PPOTrainer`: PPO-clip on a `VecEnv`, read straight from the env's buffers (paper section 3).

One update = collect `rollout_length` env steps of every agent slot of every world, compute
GAE (bootstrapping truncated agents from V(final observation)), then `num_epochs` passes of
`num_minibatches` minibatches of whole agent-slot sequences (truncated BPTT for the LSTM).
Layout of the file, CleanRL style: setup, ROLLOUT, ADVANTAGES, UPDATE, bookkeeping.
"""

from __future__ import annotations

import copy
import inspect
import time
import warnings
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import numpy as np

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import CheckpointError
from selfplaydrive.models.common import log_prob, log_prob_and_entropy, sample_actions
from selfplaydrive.trainers.callbacks import build_callbacks, callback_name
from selfplaydrive.trainers.ppo import checkpoint as ckpt
from selfplaydrive.trainers.ppo.advantage import compute_gae
from selfplaydrive.trainers.ppo.config import PPOConfig
from selfplaydrive.trainers.ppo.device import compile_model, resolve_device, warn_spinning_threads
from selfplaydrive.trainers.ppo.dist import all_reduce_mean, init_distributed, wrap
from selfplaydrive.trainers.ppo.episodes import EpisodeTracker, summarize
from selfplaydrive.trainers.ppo.logging import RunLogger
from selfplaydrive.trainers.ppo.losses import (
    advantage_stats,
    masked_mean,
    normalize_advantages,
    policy_loss,
    value_loss,
)
from selfplaydrive.trainers.ppo.overlap import Prefetch, make_actor
from selfplaydrive.trainers.ppo.parallel import PartWorkers, balanced_parts
from selfplaydrive.trainers.ppo.returns import ReturnScaler
from selfplaydrive.trainers.ppo.storage import RolloutStorage, State
from selfplaydrive.trainers.ppo.uploads import Uploader

with requires_extra("torch"):
    import torch
    from torch import Tensor, nn


# The progress bar and the `recent/*` scalars summarise a sliding window of the last finished
# world-episodes: with a laptop's handful of worlds, one update often ends none or one episode,
# and the per-update numbers alone are too noisy to see learning in.
RECENT_WORLD_EPISODES = 32
# a minibatch's count of active entries and advantage (mean, std + eps), for its parts
MinibatchStats = tuple["Tensor", tuple["Tensor", "Tensor"]]
RECENT_KEYS = ("waypoint_completion", "return_mean", "collision_rate", "offroad_rate", "km")


def _index(state: State, idx: Tensor) -> State:
    return tuple(s[idx] for s in state)


class PPOTrainer:
    """PPO trainer over every agent slot of a `VecEnv`.

    Args:
        env: A `selfplaydrive.sim.VecEnv` with discrete (MultiDiscrete) actions.
        model: A `selfplaydrive.models.PolicyModel` (e.g. `DeepSetsModel`, `TransformerModel`).
        config: Hyperparameters (`PPOConfig`).
        run_dir: Folder for TensorBoard files and checkpoints (None: neither is written).

    Callbacks (`config.callbacks`, contract in `selfplaydrive.trainers.callbacks`) are built
    once here and called from `collect` (`on_rollout`, `on_step`) and `train` (`on_start`, `on_update`,
    `on_end`); their `state_dict` travels in the checkpoints.

    Raises:
        ValueError: The env has continuous actions, or the model's action sizes do not match.
    """

    def __init__(self, env, model: nn.Module, config: PPOConfig, run_dir: str | Path | None = None) -> None:
        if not getattr(env.action_table, "discrete", False):
            raise ValueError("env: PPOTrainer needs DiscreteActions (MultiDiscrete); got continuous actions")
        nvec = tuple(int(n) for n in env.action_space.nvec)
        if tuple(model.nvec) != nvec:
            raise ValueError(f"model.nvec = {tuple(model.nvec)}: expected the env's action sizes {nvec}")
        self.env, self.config, self.nvec = env, config, nvec
        self.run_dir = None if run_dir is None else Path(run_dir)
        self.dist = init_distributed()
        self.device = resolve_device(config.device, self.dist)
        if config.torch_threads:
            torch.set_num_threads(config.torch_threads)
        warn_spinning_threads(self.device)
        if config.deterministic:
            torch.use_deterministic_algorithms(True)
        self.model = model.to(self.device)
        # the main job sets overlap_collection: under torchrun it is switched off, not refused
        self.overlap = self._single_process_only(
            "overlap_collection",
            config.overlap_collection,
            False,
            "the collector's collectives would race the update's",
        )
        # the policy that collects: the model itself, or with overlap_collection its copy, taken
        # when an update's last epoch starts (ppo/overlap.py)
        self.actor = make_actor(self.model) if self.overlap else self.model
        self.update_threads = self._single_process_only(
            "update_threads", config.update_threads, 1, "the ranks already split the batch"
        )
        self.evaluator = wrap(self.model, self.dist, self.device)
        self.compiled = config.compile and compile_model(self.model)
        # Models whose forward_sequence takes `active` skip the entries that carry no loss. Not
        # under DDP: a rank whose minibatch has no active entry would leave the encoders without
        # gradients, and DDP expects every parameter's gradient on every rank.
        accepts = "active" in inspect.signature(model.forward_sequence).parameters
        self.skip_inactive = accepts and not self.dist.enabled
        # the fused kernel: one op per step instead of a dozen per parameter (0.5 -> 0.14 ms a
        # step for the laptop model on the CPU, the same update up to float rounding)
        fused = self.device.type in ("cpu", "cuda")
        self.optimizer = torch.optim.Adam(
            model.parameters(), lr=config.learning_rate, eps=config.adam_eps, fused=fused
        )
        self.amp_dtype = self._amp_dtype()
        seed = config.seed + self.dist.rank
        self.sample_gen = torch.Generator(device=self.device).manual_seed(seed)
        self.shuffle_gen = torch.Generator().manual_seed(seed + 7919)
        self.num_slots = env.num_agents
        self.slots_per_update = config.rollout_length * self.num_slots
        self.total_updates = max(1, config.total_steps // self.slots_per_update)
        sizes = (config.rollout_length, self.num_slots, env.layout.obs_dim, len(nvec), self.device)
        self.storage = RolloutStorage.allocate(*sizes)
        # overlap_collection: the rollout being collected while `storage` trains, and the state
        # of the pipeline between updates (see _overlapped_update)
        self.spare = RolloutStorage.allocate(*sizes) if self.overlap else None
        self._pending = False  # `storage` holds a collected rollout not trained on yet
        self._snapshot: dict[str, object] | None = None  # collector state before that rollout
        self._recollect = False  # resumed: the next collection repeats one counted and logged
        self._eval_gen: torch.Generator | None = None  # evaluate()'s while a rollout is in hand
        self.return_scaler = (
            ReturnScaler(self.num_slots, config.gamma, self.device) if config.norm_returns else None
        )
        self.tracker = EpisodeTracker(env)
        self.recent: deque[dict[str, object]] = deque(maxlen=RECENT_WORLD_EPISODES)
        self.recent_returns: deque[float] = deque(maxlen=RECENT_WORLD_EPISODES * env.agents_per_world)
        self.update_idx = 0
        self.ent_coef = config.ent_coef  # this update's entropy weight (`update` sets it)
        self.global_step = 0  # slot-steps collected by this rank
        self.agent_steps = 0  # active agent-steps collected by this rank
        self.needs_reset = True
        self.state: State = ()
        self.next_start = torch.ones(self.num_slots, dtype=torch.bool, device=self.device)
        self._to_device = Uploader(self.device, config.host_register)  # (array, key) -> Tensor
        self.callbacks = build_callbacks(config.callbacks)
        # update_threads: replicas that compute the other parts of each minibatch (ppo/parallel.py)
        extra = self.update_threads - 1
        self._parallel = PartWorkers(self.model, extra, self.minibatch_loss) if extra else None

    # ---------------------------------------------------------------------------------------
    # setup helpers
    def _single_process_only(self, key: str, value: object, off: object, why: str) -> object:
        """`value`, or `off` with a RuntimeWarning under torchrun (an option for one process)."""
        if value == off or not self.dist.enabled:
            return value
        warnings.warn(
            f"trainer.{key} = {value!r} is {off!r} under torchrun (world size {self.dist.world_size}): {why}",
            RuntimeWarning,
            stacklevel=3,
        )
        return off

    def _amp_dtype(self) -> torch.dtype | None:
        p = self.config.precision
        if p == "bf16" or (p == "auto" and self.device.type == "cuda"):
            return torch.bfloat16
        return None

    def autocast(self):
        """bf16 autocast of forward passes when configured; a no-op otherwise (CPU default)."""
        if self.amp_dtype is None:
            return nullcontext()
        return torch.autocast(device_type=self.device.type, dtype=self.amp_dtype)

    def reset_env(self, seed: int) -> None:
        """Reset the env and every slot's recurrent state (a new episode everywhere)."""
        self.env.reset(seed=seed)
        self.tracker.on_reset()
        self.state = self.model.initial_state(self.num_slots, self.device)
        self.next_start = torch.ones(self.num_slots, dtype=torch.bool, device=self.device)
        self.needs_reset = False

    # ---------------------------------------------------------------------------------------
    # ROLLOUT: act in every slot of every world, straight from the env's buffers
    @torch.inference_mode()
    def act(
        self,
        deterministic: bool = False,
        net: nn.Module | None = None,
        generator: torch.Generator | None = None,
    ) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
        """Policy step of `net` (default: the actor) on the current observations, sampling from
        `generator` (default: `sample_gen`); advances the recurrent state.

        Only the slots that act (`env.masks`) are evaluated: with a third of the slots acting
        (experiment=laptop) the others would cost two thirds of the inference for outputs that
        nothing reads. Their actions are 0 (the env ignores them), their log-probs and values 0,
        and their recurrent state is left as it is (an agent's next acting step is an episode
        start, which resets it).

        Returns:
            obs (N, obs_dim), actions (N, A), log-probs (N,), values (N,), acted mask (N,).
        """
        obs = self._to_device(self.env.observations, "obs")
        acted = self._to_device(self.env.masks, "acted")
        actions = torch.zeros(self.num_slots, len(self.nvec), dtype=torch.int64, device=self.device)
        logprobs = torch.zeros(self.num_slots, device=self.device)
        values = torch.zeros(self.num_slots, device=self.device)
        acting = np.flatnonzero(self.env.masks)  # on the host: no wait for the device
        rows = torch.from_numpy(acting).to(self.device)
        if len(acting):
            state = _index(self.state, rows)
            with self.autocast():
                logits, value, state = (net or self.actor)(obs[rows], state, self.next_start[rows])
            logits = logits.float()
            sampled = sample_actions(logits, self.nvec, deterministic, generator=generator or self.sample_gen)
            actions[rows] = sampled
            logprobs[rows] = log_prob(logits, sampled, self.nvec)
            values[rows] = value.float()
            for full, part in zip(self.state, state, strict=True):
                full[rows] = part.to(full.dtype)
        return obs, actions, logprobs, values, acted

    @torch.inference_mode()
    def env_step(
        self, actions: Tensor, acted: Tensor, net: nn.Module | None = None
    ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Step the env with `actions`; returns rewards, terminated, truncated (masked by `acted`)
        and V(final observation) of the truncated slots (0 elsewhere; `net`'s value, default the
        actor's)."""
        acted_np = self.env.masks.copy()
        # the only synchronisation per step; GPU work queued before it (storage writes) and
        # after it (uploads) overlaps the env step, which runs nogil on the CPU
        self.env.step(actions.to("cpu").numpy())
        self.tracker.on_step(acted_np)
        rewards = self._to_device(self.env.rewards, "rewards") * acted
        term = self._to_device(self.env.terminations, "term") & acted
        trunc = self._to_device(self.env.truncations, "trunc") & acted & ~term
        final_values = torch.zeros_like(rewards)
        ended = np.flatnonzero(self.env.truncations & acted_np & ~self.env.terminations)
        if len(ended):  # found on the host: no device sync, and only these rows are uploaded
            idx = torch.from_numpy(ended).to(self.device)
            final_obs = torch.from_numpy(self.env.final_observations[ended]).to(self.device)
            no_start = torch.zeros(len(idx), dtype=torch.bool, device=self.device)
            with self.autocast():  # the state after step t continues into the final obs
                _, v, _ = (net or self.actor)(final_obs, _index(self.state, idx), no_start)
            final_values[idx] = v.float()
        masks = self._to_device(self.env.masks, "masks")
        self.next_start = masks & (~acted | term | trunc)
        return rewards, term, trunc, final_values

    def collect(self, storage: RolloutStorage | None = None) -> None:
        """Fill `storage` (default: `self.storage`) with one rollout of the actor."""
        s, cfg = storage or self.storage, self.config
        if self.needs_reset:
            self.reset_env(cfg.seed + self.dist.rank)
        s.initial_state = tuple(x.clone() for x in self.state)
        # before the rollout's first step, at the same point of every run (also in the collector
        # thread of overlap_collection): what a callback sets here follows the rollout's index
        self._call("on_rollout")
        for t in range(cfg.rollout_length):
            s.episode_start[t] = self.next_start
            s.obs[t], s.actions[t], s.logprobs[t], s.values[t], s.active[t] = self.act()
            s.rewards[t], s.terminated[t], s.truncated[t], s.final_values[t] = self.env_step(
                s.actions[t], s.active[t]
            )
            self.agent_steps += int(self.env.reward_mask.sum())
            self._call("on_step")
        self.global_step += self.slots_per_update

    # ---------------------------------------------------------------------------------------
    # ADVANTAGES: GAE with V(final obs) at truncations, 0 at terminations, nothing across slots
    @torch.inference_mode()
    def compute_advantages(self, storage: RolloutStorage | None = None) -> None:
        """GAE of `storage` (default: `self.storage`), bootstrapped by the actor's value."""
        s, cfg = storage or self.storage, self.config
        obs = self._to_device(self.env.observations, "obs")
        with self.autocast():
            _, next_value, _ = self.actor(obs, self.state, self.next_start)
        rewards = s.rewards
        if self.return_scaler is not None:
            rewards = self.return_scaler.scale(s.rewards, s.active, s.episode_start, self.dist)
        s.advantages, s.returns = compute_gae(
            rewards,
            s.values,
            next_value.float(),
            s.active,
            s.terminated,
            s.truncated,
            s.final_values,
            cfg.gamma,
            cfg.gae_lambda,
        )

    # ---------------------------------------------------------------------------------------
    # UPDATE: epochs x minibatches of whole slot sequences (BPTT), clipped PPO losses
    def minibatch_loss(
        self, slots: Tensor, net: nn.Module | None = None, whole: MinibatchStats | None = None
    ) -> tuple[Tensor, dict[str, Tensor]]:
        """Total loss of the agent slots `slots` and its parts.

        Args:
            slots: (K,) agent slots, whole (T,) sequences each.
            net: The sequence evaluator that computes it (default: the model's, DDP-wrapped
                under torchrun); `update_threads` hands the other parts to replicas.
            whole: (count of active entries, advantage statistics) of the minibatch that `slots`
                is a part of (`minibatch_step`): the means are then divided by that count and
                advantages normalised by those statistics, so that the parts' losses add up to
                the minibatch's.
        """
        cfg, mb = self.config, self.storage.minibatch(slots)
        with self.autocast():
            active = mb["active"] if self.skip_inactive else None
            evaluator = net or self.evaluator
            logits, values, _ = evaluator(mb["obs"], mb["initial_state"], mb["episode_start"], active)
        logits, values, mask = logits.float(), values.float(), mb["active"]
        count, stats = (None, None) if whole is None else whole
        new_logprob, entropies = log_prob_and_entropy(logits, mb["actions"], self.nvec)
        adv = normalize_advantages(mb["advantages"], mask, stats=stats) if cfg.norm_adv else mb["advantages"]
        pg, info = policy_loss(new_logprob, mb["logprobs"], adv, mask, cfg.clip_coef, count)
        vl = value_loss(values, mb["values"], mb["returns"], mask, cfg.clip_value, cfg.value_clip_coef, count)
        ent = masked_mean(entropies, mask, count)
        loss = pg - self.ent_coef * ent + cfg.vf_coef * vl
        return loss, dict(info, policy=pg.detach(), value=vl.detach(), entropy=ent.detach())

    def minibatch_step(self, slots: Tensor, threads: int) -> dict[str, Tensor]:
        """Gradient of the minibatch `slots` into the model's `.grad` (set, not accumulated);
        returns the loss parts. With `threads` > 1 the slots are dealt into that many parts, and
        part k > 0 runs forward and backward on replica k in a pool thread while this thread
        runs part 0; the replicas' gradients are then added in order (the same sum up to float
        rounding, and the same bits on every run)."""
        self.optimizer.zero_grad(set_to_none=True)
        if threads <= 1 or len(slots) < threads:
            loss, info = self.minibatch_loss(slots)
            loss.backward()
            return info
        mask = self.storage.active.index_select(1, slots)
        per_slot = mask.sum(dim=0)
        parts = balanced_parts(slots, per_slot, threads)
        # the whole minibatch's count of active entries and advantage statistics
        whole = per_slot.sum().float(), advantage_stats(self.storage.advantages.index_select(1, slots), mask)
        self._parallel.sync(self.model)
        jobs = [self._parallel.submit(k, part, whole) for k, part in enumerate(parts[1:])]
        loss, info = self.minibatch_loss(parts[0], whole=whole)
        loss.backward()
        for job in jobs:
            for k, v in job.result().items():  # re-raises a part's exception here
                info[k] = info[k] + v
        self._parallel.add_gradients(self.model)
        return info

    def update(self, hook: Callable[[], None] | None = None, hook_at: int = 0) -> dict[str, float]:
        """PPO epochs over the stored rollout; returns mean losses and diagnostics.

        Args:
            hook: Called once, after `hook_at` optimizer steps (or at the end when the update
                takes fewer): overlap_collection starts the next rollout's collection there.
            hook_at: Optimizer steps before `hook`.
        """
        cfg = self.config
        frac = 1.0 - self.update_idx / self.total_updates
        if cfg.anneal_lr:
            self.optimizer.param_groups[0]["lr"] = frac * cfg.learning_rate
        self.ent_coef = cfg.entropy_weight(frac)
        live = self._live_slots()
        sums: dict[str, float] = {}
        count = 0
        # once the hook has started the next rollout's collection, the collector has a core:
        # the minibatches that follow run on one thread
        threads = self.update_threads
        if hook is not None and hook_at <= 0:
            hook()
            hook, threads = None, 1
        for _epoch in range(cfg.num_epochs):
            order = live[torch.randperm(len(live), generator=self.shuffle_gen).to(self.device)]
            for slots in torch.tensor_split(order, cfg.num_minibatches):
                if not len(slots):  # more minibatches than agent slots
                    continue
                info = self.minibatch_step(slots, threads)
                if cfg.max_grad_norm > 0:
                    info["grad_norm"] = nn.utils.clip_grad_norm_(self.model.parameters(), cfg.max_grad_norm)
                self.optimizer.step()
                for k, v in info.items():
                    sums[k] = sums.get(k, 0.0) + float(v)
                count += 1
                if hook is not None and count == hook_at:
                    hook()
                    hook, threads = None, 1
            kl = all_reduce_mean(info["approx_kl"], self.dist)  # same decision on every rank
            if cfg.target_kl is not None and float(kl) > cfg.target_kl:
                break
        if hook is not None:
            hook()
        out = {f"losses/{k}": v / max(count, 1) for k, v in sums.items()}
        out["losses/explained_variance"] = self._explained_variance()
        out["charts/learning_rate"] = self.optimizer.param_groups[0]["lr"]
        out["charts/ent_coef"] = self.ent_coef
        if self.return_scaler is not None:
            out["charts/return_scale"] = self.return_scaler.std
        return out

    def _live_slots(self) -> Tensor:
        """The agent slots the minibatches are cut from, (K,) int64 on the device: those that
        acted at some step of the rollout.

        The others carry no loss: with experiment=laptop, where every contact ends an agent
        until its world resets, about half the slots stay empty for a whole rollout, and their
        BPTT would be half an update's work. Every slot is kept when fewer than
        `num_minibatches` acted (each minibatch needs one), and under DDP, whose ranks must
        take the same steps with gradients for every parameter."""
        live = torch.nonzero(self.storage.active.any(dim=0)).flatten()
        if self.dist.enabled or len(live) < self.config.num_minibatches:
            return torch.arange(self.num_slots, device=self.device)
        return live

    def _explained_variance(self) -> float:
        s = self.storage
        m = s.active
        if int(m.sum()) < 2:
            return float("nan")
        y, pred = s.returns[m], s.values[m]
        var = torch.var(y)
        return float(1.0 - torch.var(y - pred) / var) if var > 0 else float("nan")

    # ---------------------------------------------------------------------------------------
    # the loop
    def train(self, num_updates: int | None = None, logger: RunLogger | None = None) -> dict[str, float]:
        """Run updates until `total_updates` (or `num_updates` more); returns the last metrics."""
        cfg = self.config
        stop = self.total_updates
        if num_updates is not None:
            stop = min(stop, self.update_idx + num_updates)
        metrics: dict[str, float] = {}
        ran = False
        self._call("on_start")
        while self.update_idx < stop:
            ran = True
            t0, steps0 = time.perf_counter(), self.agent_steps
            if self.overlap:
                metrics, t_collect = self._overlapped_update()
            else:
                self._collect_first()
                t_collect = time.perf_counter() - t0
                metrics = self.update()
            self.update_idx += 1
            t_total = time.perf_counter() - t0
            metrics.update(self._rates(self.agent_steps - steps0, t_collect, t_total))
            records, returns = self.tracker.pop()
            metrics.update(summarize(records, returns))
            metrics.update(self._recent(records, returns))
            for extra in self._call("on_update", metrics):
                if isinstance(extra, Mapping):
                    metrics.update(extra)
            if logger is not None:
                if self.update_idx % cfg.log_interval == 0:
                    logger.scalars(metrics, self.trained_steps)
                logger.progress(1, metrics)
            if cfg.checkpoint_interval and self.update_idx % cfg.checkpoint_interval == 0:
                self.save_periodic()
        if ran and self.update_idx >= self.total_updates:
            self._call("on_end", metrics)
        return metrics

    @property
    def trained_steps(self) -> int:
        """Slot-steps of all ranks that the updates so far trained on: the x axis of the logs.
        With overlap_collection `global_step` also counts the rollout in hand (or, after a
        resume, the one about to be collected again), which no update has trained on yet."""
        ahead = self.slots_per_update if self._pending or self._recollect else 0
        return (self.global_step - ahead) * self.dist.world_size

    def _overlapped_update(self) -> tuple[dict[str, float], float]:
        """One update with `overlap_collection`; returns its metrics and the collection seconds.

        Update k trains on rollout k. When its last epoch starts, the actor takes the model's
        weights of that moment and a second thread collects rollout k+1 with them while the
        epoch runs (ppo/overlap.py). Between updates, also between `train()` calls, the
        pipeline holds rollout k+1 (`_pending`). The run's last update collects one too, so
        that a run extended later (a resume with a larger `total_steps`) continues as one that
        never stopped. Without a rollout in hand (the first update, a resume) the update
        collects its own first, with the actor's weights.
        """
        t_collect = 0.0
        if not self._pending:
            start = time.perf_counter()
            if not self._recollect:  # a fresh start (or init_from): the model's own weights
                self.actor.load_state_dict(self.model.state_dict())
            self._collect_first()
            t_collect = time.perf_counter() - start
        prefetch: list[Prefetch] = []

        def start_next() -> None:
            self._eval_gen = None
            self.actor.load_state_dict(self.model.state_dict())
            self._snapshot = self._collector_state()  # what a checkpoint after this update holds
            prefetch.append(Prefetch(lambda: (self.collect(self.spare), self.compute_advantages(self.spare))))

        last_epoch = self.config.num_minibatches * (self.config.num_epochs - 1)
        try:
            metrics = self.update(start_next, hook_at=last_epoch)
        except BaseException:
            for p in prefetch:
                p.wait()  # never leave the collector writing behind a raised exception
            raise
        t_collect += prefetch[0].result()
        self.storage, self.spare = self.spare, self.storage
        self._pending = True
        return metrics, t_collect

    def _collect_first(self) -> None:
        """Collect the rollout of the coming update before it. After a resume from a
        checkpoint written with a rollout in flight (overlap_collection, resumed with or
        without it), that rollout is collected again from the state saved before it: its
        steps were counted and its episodes logged before the checkpoint, so they are not
        counted or logged twice."""
        counters = (self.global_step, self.agent_steps)
        self.collect()
        self.compute_advantages()
        if self._recollect:
            self.global_step, self.agent_steps = counters
            self.tracker.pop()
            self._recollect = False

    def _call(self, hook: str, *args: object) -> list[object]:
        """Call `hook(self, *args)` on every callback that defines it; returns the results."""
        out = []
        for callback in self.callbacks:
            method = getattr(callback, hook, None)
            if method is not None:
                out.append(method(self, *args))
        return out

    def _recent(self, records: list[dict[str, object]], returns: list[float]) -> dict[str, float]:
        """`recent/<key>` over the last `RECENT_WORLD_EPISODES` finished world-episodes."""
        self.recent.extend(records)
        self.recent_returns.extend(returns)
        window = summarize(list(self.recent), list(self.recent_returns))
        return {f"recent/{k}": window[k] for k in RECENT_KEYS if k in window}

    def _rates(self, agent_steps: int, t_collect: float, t_total: float) -> dict[str, float]:
        return {
            "sps": agent_steps * self.dist.world_size / t_total,
            "collect_sps": agent_steps / t_collect,
            "slot_sps": self.slots_per_update * self.dist.world_size / t_total,
            "active_share": agent_steps / self.slots_per_update,
        }

    # ---------------------------------------------------------------------------------------
    # evaluation and checkpoints
    @torch.no_grad()
    def evaluate(
        self, episodes: int, max_steps: int, deterministic: bool, seed: int, recorders: Sequence[Any] = ()
    ) -> dict[str, float]:
        """Run the policy on fresh episodes (env reset with `seed`) until every world finished
        its share of `episodes` world-episodes (its first ones: `eval.sampling`, an unbiased
        sample of episode lengths) or `max_steps` env steps; returns `episodes.summarize` of
        them. Training afterwards starts from a fresh reset. Each of `recorders` has its
        `record()` called after every env step (e.g. `eval.collisions.CollisionRecorder`).

        Sampled actions come from `sample_gen`; with a rollout in hand (overlap_collection),
        from a copy of its state before that rollout, which later evaluations continue: an
        evaluation then draws what it would have drawn had the rollout not been collected yet."""
        self.tracker.count_first(episodes)
        try:
            self.reset_env(seed)
            generator = self._evaluation_generator()
            records: list[dict[str, object]] = []
            returns: list[float] = []
            for _ in range(max_steps):
                _, actions, _, _, acted = self.act(deterministic, net=self.model, generator=generator)
                self.env_step(actions, acted, net=self.model)
                for rec in recorders:
                    rec.record()
                r, g = self.tracker.pop()
                records += r
                returns += g
                if self.tracker.quota_met:
                    break
        finally:
            self.tracker.count_first(None)
        self.needs_reset = True
        return summarize(records, returns)

    def _evaluation_generator(self) -> torch.Generator:
        if not self._pending:
            return self.sample_gen
        if self._eval_gen is None:
            self._eval_gen = torch.Generator(device=self.device)
            self._eval_gen.set_state(self._snapshot["sample_gen"])
        return self._eval_gen

    def state_dict(self) -> dict[str, object]:
        """Everything `load_state_dict` needs to continue exactly (see checkpoint.py).

        With overlap_collection the pipeline holds the next rollout between updates: the
        collecting side's state is then the one saved before that rollout, and
        `pending_rollout` says so; a resume collects it again (with the saved actor weights
        under overlap_collection, with the model's without it) and does not count it twice.
        """
        payload: dict[str, object] = {
            "config": self.config.to_dict(),
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "counters": {
                "update": self.update_idx,
                "global_step": self.global_step,
                "agent_steps": self.agent_steps,
            },
            "shuffle_gen": self.shuffle_gen.get_state(),
            "recent": (list(self.recent), list(self.recent_returns)),
        }
        payload.update(self._snapshot if self._pending else self._collector_state())
        # the counters include a rollout that the saved state has not collected yet: one in
        # hand, or one a resume has yet to collect again
        payload["pending_rollout"] = self._pending or self._recollect
        if self.overlap:
            payload["actor"] = copy.deepcopy(self.actor.state_dict())
        return payload

    def _collector_state(self) -> dict[str, object]:
        """A copy of what collecting a rollout changes: env, recurrent state, generator of the
        actions, episode tracker, return scaler and callbacks (`on_step`)."""
        state = {
            "sample_gen": self.sample_gen.get_state(),
            "recurrent": [s.cpu() for s in self.state],
            "next_start": self.next_start.cpu(),
            "needs_reset": self.needs_reset,
            "tracker": self.tracker.state_dict(),
            "return_scaler": None if self.return_scaler is None else self.return_scaler.state_dict(),
            "callbacks": [
                {"name": callback_name(c), "state": c.state_dict() if hasattr(c, "state_dict") else None}
                for c in self.callbacks
            ],
        }
        state = copy.deepcopy(state)  # on the CPU some entries are the live tensors
        state["env"] = ckpt.env_state(self.env)  # a copy already
        return state

    def load_state_dict(self, payload: dict[str, object]) -> None:
        self.model.load_state_dict(payload["model"])
        self.optimizer.load_state_dict(payload["optimizer"])
        c = payload["counters"]
        self.update_idx, self.global_step, self.agent_steps = c["update"], c["global_step"], c["agent_steps"]
        self.sample_gen.set_state(payload["sample_gen"])
        self.shuffle_gen.set_state(payload["shuffle_gen"])
        self.state = tuple(s.to(self.device) for s in payload["recurrent"])
        self.next_start = payload["next_start"].to(self.device)
        self.needs_reset = payload["needs_reset"]
        ckpt.load_env_state(self.env, payload["env"])
        self.tracker.load_state_dict(payload["tracker"])
        if "recent" in payload:
            self.recent.clear()
            self.recent_returns.clear()
            self.recent.extend(payload["recent"][0])
            self.recent_returns.extend(payload["recent"][1])
        if self.return_scaler is not None and payload.get("return_scaler") is not None:
            self.return_scaler.load_state_dict(payload["return_scaler"])
        if "rng" in payload:
            ckpt.set_rng_state(payload["rng"])
        self._load_callbacks(payload.get("callbacks", []))
        self._pending = False
        if self.overlap:  # a checkpoint of a run without overlap has no actor: the model's weights
            self.actor.load_state_dict(payload.get("actor", payload["model"]))
        self._recollect = bool(payload.get("pending_rollout", False))

    def _load_callbacks(self, saved: list[dict[str, object]]) -> None:
        """Restore the callbacks' states by position where the saved name matches (a callback
        added on resume starts fresh; one dropped is ignored)."""
        for callback, entry in zip(self.callbacks, saved, strict=False):
            if entry["name"] == callback_name(callback) and entry["state"] is not None:
                if hasattr(callback, "load_state_dict"):
                    callback.load_state_dict(entry["state"])

    def save(self, path: str | Path) -> Path:
        """Write a checkpoint of `state_dict()` to `path` atomically (`checkpoint.save`)."""
        return ckpt.save(path, self.state_dict(), self.dist.rank)

    def load(self, path: str | Path) -> None:
        """Continue from the checkpoint at `path` (exactly, see checkpoint.py).

        Raises:
            CheckpointError: The file is missing, unreadable or foreign (`checkpoint.load`), or
                was written for another env or model configuration.
        """
        payload = ckpt.load(path, map_location="cpu")
        try:
            self.load_state_dict(payload)
        except CheckpointError:
            raise
        except (ValueError, RuntimeError, KeyError, TypeError) as exc:
            # a model of other sizes (RuntimeError), an env of another shape (ValueError) ...
            detail = " ".join(str(exc).split())[:300]
            raise CheckpointError(f"does not fit this trainer: {detail}", path) from exc

    def save_periodic(self) -> Path | None:
        """Checkpoint into `<run_dir>/checkpoints` (every rank its own file) and prune old ones."""
        if self.run_dir is None:
            return None
        folder = self.run_dir / "checkpoints"
        path = self.save(folder / ckpt.checkpoint_name(self.update_idx, self.dist.rank))
        ckpt.prune(folder, self.config.keep_checkpoints, self.dist.rank)
        return path
