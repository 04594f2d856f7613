"""The app's view of collection, over any TorchRL collector: one process, `MultiSyncCollector` or
`RayCollector`, each stepping `FastCollector` or TorchRL's `Collector`.

- batches: TorchRL's, reshaped to [envs, steps];
- finished episodes: read from the batch (`episode_reward`, `step_count`: Gymnasium's episode counters,
  positions.GymEnvs), wherever the envs live;
- statistics: the env's normalization transforms (normalization.py) own them. With several workers
  each worker's set grows during a batch; after it, what every worker added since the last merge is
  pooled exactly (`normalization.pool`) into `self.env` (the main process's copy, never stepped) and
  loaded back into every worker, read and written through the collectors' public
  `state_dict()` / `load_state_dict()` (each transform's own extra state; each env keeps its running
  discounted return);
- state for resume: the statistics, and the collector's own state: where each env is, in every worker
  (FastCollector), or in the one process (TorchRL's Collector restarts on the saved positions).
"""

from __future__ import annotations

import functools
import signal
from typing import Dict, List, Optional, Tuple

import numpy as np
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict
from torchrl.collectors import Collector

from ppo_torchrl.collectors.choice import resolve_backend
from ppo_torchrl.collectors.fast import FastCollector, open_state, packed_state
from ppo_torchrl.collectors.multiprocess import (
    WorkerWatch,
    make_multi_collector,
    warn_if_oversubscribed,
    worker_env,
)
from ppo_torchrl.envs import make_torchrl_env
from ppo_torchrl.models import sampling_policy
from ppo_torchrl.normalization import ObservationNormalization, RewardNormalization, pooled, stats_of
from ppo_torchrl.positions import GymEnvs

BATCH_KEYS = ["observation", "action", ("next", "observation"), ("next", "reward"), ("next", "done"),
              ("next", "terminated"), ("next", "truncated")]


class Collection:
    def __init__(self, cfg, ac, seed: int, device: torch.device):
        c = cfg.collector
        self.fast = resolve_backend(cfg) == "fast"
        self.multi = c.workers > 1 or bool(c.distributed)
        collector_class = FastCollector if self.fast else Collector
        # FastCollector reads the actor's net, distribution and bounds; TorchRL's Collector steps the lean draw
        policy = ac.actor if self.fast else sampling_policy(ac)
        env_kwargs = dict(clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma)
        common = dict(frames_per_batch=c.frames_per_batch, total_frames=-1, policy_device=device,
                      env_device="cpu", storing_device=device)
        # In one process, the env the collector steps; with workers, the main process's copy of the
        # transforms that holds the merged statistics (never stepped).
        self.env = make_torchrl_env(cfg.env, num_envs=c.num_envs, seed=seed, **env_kwargs)
        transforms = list(self.env.transform)
        self.obs_norm, self.reward_norm = stats_of(transforms)
        self.gym = next(t for t in transforms if isinstance(t, GymEnvs))
        self._watch: Optional[WorkerWatch] = None  # with worker processes: a death ends the run at once
        if not self.multi:
            self._new_collector = functools.partial(collector_class, policy=policy,
                                                    auto_register_policy_transforms=False, **common)
            self.collector = self._new_collector(self.env)
            if self.fast:
                self.collector.set_seed(seed)
        else:
            warn_if_oversubscribed(c)
            env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
            fixed = self.obs_norm.state_dict() if cfg.env.transforms.obs_norm == "fixed" else None  # fitted once
            make_env = [functools.partial(worker_env, env_cfg, num_envs=c.num_envs, obs_stats=fixed,
                                          seed=seed + 7919 * (i + 1), **env_kwargs) for i in range(c.workers)]
            # Workers start with SIGINT blocked (inherited): a Ctrl-C while they import is the main process's
            # alone (one line), not a traceback from each worker; here it waits until they have started.
            blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            try:
                self.collector = make_multi_collector(c, make_env, policy, collector_class, common)
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
            self._watch = WorkerWatch.of(self.collector)
            self.collector.set_seed(seed)
        self._keys = self._stat_keys()
        self._base: Dict[str, Optional[dict]] = {}  # the merged stats the workers started the batch from
        self._metrics: Dict[str, float] = {}
        self._iterator = iter(self.collector)
        self._finished: List[Tuple[float, int]] = []

    # ---------------------------------------------------------------- collecting
    def collect(self) -> TensorDict:
        try:
            if self.multi:
                self.collector.update_policy_weights_()  # every worker collects with the weights of the last update
            batch = next(self._iterator)
            if self.multi:
                self._merge_stats()
        except Exception:
            self._raise_if_a_worker_died()
            raise
        # one env: [steps]; batched envs: [num_envs, steps]; workers add a leading dim: all -> [envs, steps]
        batch = batch.reshape(-1, batch.shape[-1])
        self._record_episodes(batch)
        return batch.select(*BATCH_KEYS)

    def _record_episodes(self, batch: TensorDict) -> None:
        done = batch.get(("next", "done")).squeeze(-1)
        returns = batch.get(("next", "episode_reward")).squeeze(-1)
        lengths = batch.get(("next", "step_count")).squeeze(-1)
        for i in range(batch.shape[0]):  # episodes in env order, as they ended
            for t in done[i].nonzero().squeeze(-1).tolist():
                self._finished.append((float(returns[i, t]), int(lengths[i, t])))

    def pop_episodes(self) -> List[Tuple[float, int]]:
        """(raw return, length) of the episodes finished since the last call."""
        finished, self._finished = self._finished, []
        return finished

    def env_metrics(self) -> Dict[str, float]:
        """A step env's curriculum level and recent success rate; {} where the envs say nothing."""
        return self._metrics if self.multi else self.gym.env_metrics()

    def obs_stats(self) -> Optional[dict]:
        """Observation statistics {"mean", "var", "count"} (None without normalization)."""
        state = self.obs_norm.state_dict()
        return None if state is None else {k: state[k] for k in ("mean", "var", "count")}

    # ---------------------------------------------------------------- statistics across workers
    def _stat_keys(self) -> Dict[str, str]:
        """The transforms' state-dict keys of the statistics ("obs", "reward"): the same in every worker."""
        names = list(self.env.transform.state_dict())  # each normalization module holds one entry: its state
        keys = {}
        for name, module in self.env.transform.named_modules():
            kind = "obs" if isinstance(module, ObservationNormalization) else \
                "reward" if isinstance(module, RewardNormalization) else None
            if kind is not None:
                keys[kind] = next(key for key in names if key.startswith(f"{name}."))
        return keys

    def _collector_state(self):
        """The collector's `state_dict()`; with workers, a dead one is one line naming it (WorkerWatch)."""
        try:
            return self.collector.state_dict()
        except Exception:
            self._raise_if_a_worker_died()
            raise

    def _raise_if_a_worker_died(self) -> None:
        error = self._watch.error() if self._watch is not None else None
        if error is not None:
            raise error from None

    def _worker_states(self) -> Tuple[object, list]:
        """The collector's state (MultiSyncCollector: {"worker0": ..., "frames": ...}; Ray: a list),
        and each worker's part of it, opened (fast.open_state)."""
        whole = self._collector_state()
        return whole, [open_state(part) for part in self._parts(whole)]

    def _parts(self, whole) -> list:
        """Each worker's part of a collector state (MultiSyncCollector: {"worker0": ..., "frames": ...};
        Ray: a list); in one process, the state itself."""
        if not self.multi:
            return [whole]
        return [whole[f"worker{i}"] for i in range(self.collector.num_workers)] if isinstance(whole, dict) \
            else list(whole)

    def _merge_stats(self) -> None:
        whole, workers = self._worker_states()
        metrics = [w["env_metrics"] for w in workers if w.get("env_metrics")]
        self._metrics = {k: float(np.mean([m[k] for m in metrics])) for k in metrics[0]} if metrics else {}
        if "obs" in self._keys:
            obs = pooled(self._base.get("obs"), [to_numpy(w["env_state_dict"][self._keys["obs"]]) for w in workers])
            self.obs_norm.load_state_dict(obs)
        if "reward" in self._keys:
            parts = [to_numpy(w["env_state_dict"][self._keys["reward"]]) for w in workers]
            base = self._base.get("reward") or self.reward_norm.state_dict()  # every worker starts from this prior
            self.reward_norm.load_state_dict(pooled(base, parts), running=False)
        self._push(whole, workers)

    def _push(self, whole=None, workers: Optional[list] = None) -> None:
        """Load the statistics of `self.env` into every worker (each keeps its envs' running returns)."""
        if whole is None:
            whole, workers = self._worker_states()
        obs, reward = self.obs_norm.state_dict(), self.reward_norm.state_dict()
        for w in workers:
            env_state = w["env_state_dict"]
            if "obs" in self._keys:
                env_state[self._keys["obs"]] = obs
            if "reward" in self._keys:
                own = to_numpy(env_state[self._keys["reward"]])
                env_state[self._keys["reward"]] = {**reward, "returns": own["returns"]}
            w.pop("positions", None)  # each env stays where it is
            w.pop("env_metrics", None)
        parts = [packed_state(w) if self.fast else w for w in workers]
        self.collector.load_state_dict({**whole, **{f"worker{i}": p for i, p in enumerate(parts)}}
                                       if isinstance(whole, dict) else parts)
        self._base = {"obs": obs, "reward": reward}

    # ---------------------------------------------------------------- checkpoints
    def state_dict(self) -> dict:
        """The statistics in the shared format (evaluation, export and init_from read "obs"), and the
        collector's state for an exact resume (policy weights left out: the checkpoint has them)."""
        reward = self.reward_norm.state_dict()
        state = {"obs": self.obs_stats(), "obs_frozen": self.obs_norm.frozen,
                 "return": {k: reward[k] for k in ("mean", "var", "count")}}
        whole = self._collector_state()
        if not self.fast:  # FastCollector's state leaves the weights out itself
            for part in self._parts(whole):
                part.pop("policy_state_dict", None)
        state["collector"] = whole
        if not self.fast and not self.multi:
            state["positions"] = self.gym.positions()
        return state

    def load_state_dict(self, state: dict) -> None:
        """init_from: the statistics only; resume (a "collector" entry): all of it."""
        obs = state.get("obs")
        if obs is not None and self.obs_norm.enabled:
            self.obs_norm.load_state_dict({**obs, "frozen": bool(state.get("obs_frozen", self.obs_norm.frozen))})
        if state.get("return") is not None:
            self.reward_norm.load_state_dict(state["return"], running=False)
        saved = state.get("collector")
        if saved is not None and (self.fast or self.multi):
            self.collector.load_state_dict(saved)  # the transforms' stats and each env's position, in every worker
            if self.multi:
                self._push()
        elif saved is not None:
            self.env.transform.load_state_dict(saved["env_state_dict"], strict=False)
            self._continue_episodes(state)
        elif self.multi:
            self._push()

    def _continue_episodes(self, state: dict) -> None:
        """TorchRL's Collector: a new one, whose first reset restores each env's saved position; the saved
        observation is not counted again by the statistics (frozen for that reset)."""
        if not self.gym.continue_from(state.get("positions"), now=False):
            return
        was_frozen = self.obs_norm.frozen
        self.obs_norm.freeze()
        self.collector.shutdown(close_env=False)
        self.collector = self._new_collector(self.env)
        self.obs_norm.freeze(was_frozen)
        self._iterator = iter(self.collector)

    def close(self) -> None:
        if self._watch is not None:
            self._watch.stop()
        self.collector.shutdown()
        if self.multi:
            from ppo_torchrl.collectors.multiprocess import shutdown_ray

            shutdown_ray(self.collector)


def to_numpy(state) -> dict:
    """A transform's extra state as it comes back from a worker (tensors) in numpy."""
    if state is None:
        return None
    if hasattr(state, "to_dict"):
        state = state.to_dict()
    return {k: (v.numpy() if isinstance(v, torch.Tensor) else v) for k, v in dict(state).items()}
