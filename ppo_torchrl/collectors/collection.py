"""The app's view of collection, over any TorchRL collector: one process, `MultiSyncCollector` or
`RayCollector`, each stepping `FastCollector` or TorchRL's `Collector`. It collects and pools; the env-side
state (statistics, episode counters, env metrics, positions) is the env's `EnvState` (env_state.py).

- batches: TorchRL's, reshaped to [envs, steps];
- finished episodes: read from the batch (`episode_reward`, `step_count`: Gymnasium's episode counters, as
  EnvState writes them), wherever the envs live;
- with several workers each worker's EnvState grows during a batch; after it, the workers' snapshots are
  merged (`EnvState.merge`: exact pooled statistics, every env's metrics) into `self.state` (the
  main process's EnvState, never stepped) and loaded back into every worker (`EnvState.shared`), through
  the collectors' public `state_dict()` / `load_state_dict()` (their layout: internals.py);
- state for resume: the collector's, which holds each EnvState's snapshot (positions included) and the
  collector's own RNG; one path loads it for every collector and scale, each collector putting its envs
  back where they were (`EnvState.continue_episodes`).

A new collector class touches two files: its own, and its line in `collectors/choice.py` (`BACKENDS`). The
contract: a `torchrl.collectors.Collector` that TorchRL's multi-process and Ray collectors can build
(`collector_class=`, their arguments); it steps the env of `envs.make_torchrl_env` through its EnvState
(the statistics through `EnvState.obs_norm` / `reward_norm` when it bypasses the transforms, the episodes
through Gymnasium's counters); its `state_dict()` holds the env's transforms' state (`env_state_dict`, as
TorchRL's Collector's does), its own entry beside it (internals.OWN: the RNG it samples with, dropped from the
statistics pushed between batches), and its `load_state_dict()` takes a saved one back and calls
`EnvState.continue_episodes()` (collectors/fast.py and collectors/torchrl_path.py are the two).
"""

from __future__ import annotations

import functools
import signal
from typing import Dict, List, Optional, Tuple

import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from ppo_torchrl.collectors.choice import collector_class as collector_class_of, resolve_backend
from ppo_torchrl.internals import env_snapshot, env_state_key, shared_part, with_worker_parts, worker_parts
from ppo_torchrl.collectors.multiprocess import (
    WorkerWatch,
    make_multi_collector,
    shutdown_ray,
    warn_if_oversubscribed,
    worker_env,
)
from ppo_torchrl.envs.state import EnvState, env_state_of, mean_metrics
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.envs.make import make_torchrl_env
from ppo_torchrl.envs.layout import PRIVILEGED
from ppo_torchrl.rl.models import sampling_policy

BATCH_KEYS = ["observation", "action", ("next", "observation"), ("next", "reward"), ("next", "done"),
              ("next", "terminated"), ("next", "truncated")]
PRIVILEGED_KEYS = [PRIVILEGED, ("next", PRIVILEGED)]  # policy.critic_obs=privileged: the critic's input
# the collectors that write them (env_rows.py: how another env kind feeds the critic)
PRIVILEGED_WRITERS = ("fast", "playground")


class Collection:
    def __init__(self, cfg, ac, seed: int, device: torch.device, first_env=None):
        c = cfg.collector
        backend = resolve_backend(cfg)
        self.fast = backend != "torchrl"  # FastCollector or its subclass (envpool): seeded here
        self.multi = c.workers > 1 or bool(c.distributed)
        collector_class, steps = collector_class_of(backend)  # the classes registered in collectors/choice.py
        policy = ac.actor if steps == "actor" else sampling_policy(ac)  # FastCollector reads the actor's net
        self.privileged = cfg.policy.get("critic_obs", "observation") == "privileged"
        if self.privileged and backend not in PRIVILEGED_WRITERS:  # an env may declare one its collector cannot write
            raise ConfigError(f"policy.critic_obs=privileged: collector.backend={backend} writes no privileged "
                              f"observation into its batches (those that do: {', '.join(PRIVILEGED_WRITERS)})")
        self._keys = BATCH_KEYS + (PRIVILEGED_KEYS if self.privileged else [])
        env_kwargs = dict(clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma, privileged=self.privileged)
        common = dict(frames_per_batch=c.frames_per_batch, total_frames=-1, policy_device=device,
                      env_device="cpu", storing_device=device)
        # In one process, the env the collector steps; with workers, the main process's copy of the
        # transforms that holds the merged statistics (never stepped).
        # (a Playground task's main copy is not reset: its EnvPool, seconds and ~55 MB an env, is built in the workers)
        main_seed = None if self.multi and cfg.env.get("playground") is not None else seed
        self.env = make_torchrl_env(cfg.env, num_envs=c.num_envs, seed=main_seed, first_env=first_env,
                                    threads=c.physics_threads if not self.multi else 1, **env_kwargs)
        self.state = env_state_of(self.env)
        self._key = env_state_key(self.env)
        self._watch: Optional[WorkerWatch] = None  # with worker processes: a death ends the run at once
        if not self.multi:
            self.collector = collector_class(self.env, policy=policy, auto_register_policy_transforms=False, **common)
            if self.fast:
                self.collector.set_seed(seed)
        else:
            warn_if_oversubscribed(c)
            env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
            fixed = self.state.obs_norm.state_dict() if self.state.obs_norm.frozen else None  # fitted once, here
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
        self._base: Optional[dict] = None  # the merged snapshot the workers started the batch from
        self._metrics: Dict[str, float] = {}
        self._iterator = iter(self.collector)
        self._finished: List[Tuple[float, int]] = []

    # ---------------------------------------------------------------- collecting
    def collect(self) -> TensorDict:
        try:
            if self.multi:
                self.collector.update_policy_weights_()  # every worker collects with the weights of the last update
            batch = next(self._iterator)
            # the env metrics: over every env (of every worker), averaged once
            self._metrics = mean_metrics(self._merge_stats() if self.multi else self.state.env_metrics())
        except Exception:
            self._raise_if_a_worker_died()
            raise
        # one env: [steps]; batched envs: [num_envs, steps]; workers add a leading dim: all -> [envs, steps]
        batch = batch.reshape(-1, batch.shape[-1])
        self._record_episodes(batch)
        return batch.select(*self._keys)

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

    def metric_keys(self) -> List[str]:
        """The env's metrics beyond loggers.COLUMNS (a task's eval figures, curriculum and reward terms), for
        metrics.csv."""
        return self.state.rows.metric_keys()

    def env_metrics(self) -> Dict[str, float]:
        """A step env's curriculum level and recent success rate; {} where the envs say nothing."""
        return self._metrics

    def obs_stats(self) -> Optional[dict]:
        """Observation statistics {"mean", "var", "count", "layout"} (None without normalization): the layout they
        scale the observation with (layout.py) travels with them, to checkpoints, evaluation and export."""
        state = self.state.obs_norm.state_dict()
        return None if state is None else {k: state[k] for k in ("mean", "var", "count", "layout")}

    # ---------------------------------------------------------------- the workers' EnvStates, pooled
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
        """The collector's state and each worker's part of it, opened (internals.worker_parts)."""
        whole = self._collector_state()
        return whole, worker_parts(whole)

    def _merge_stats(self) -> List[Dict[str, float]]:
        """Pool the workers' EnvStates into `self.state` and load the result back into every worker; returns
        every env's metrics."""
        whole, workers = self._worker_states()
        # before the first merge the workers share only the return statistics' prior
        base = self._base or {"obs": None, "reward": self.state.snapshot(positions=False)["reward"]}
        merged = EnvState.merge(base, [env_snapshot(w, self._key) for w in workers])
        self.state.restore(merged, returns=False)
        self._push(whole, workers)
        return merged["metrics"]

    def _push(self, whole=None, workers: Optional[list] = None) -> None:
        """Load the statistics of `self.state` into every worker (each keeps its envs and their returns)."""
        if whole is None:
            whole, workers = self._worker_states()
        merged = self.state.snapshot(positions=False)
        parts = [shared_part(w, self._key, EnvState.shared(merged, env_snapshot(w, self._key))) for w in workers]
        self.collector.load_state_dict(with_worker_parts(whole, parts))
        self._base = merged

    # ---------------------------------------------------------------- checkpoints
    def state_dict(self) -> dict:
        """The statistics in the shared format (evaluation, export and init_from read "obs"), and the
        collector's state for an exact resume."""
        reward = self.state.reward_norm.state_dict()
        state = {"obs": self.obs_stats(), "obs_frozen": self.state.obs_norm.frozen,
                 "return": {k: reward[k] for k in ("mean", "var", "count")}}
        if self.state.privileged_norm is not None:  # the critic's input's statistics (policy.critic_obs=privileged)
            state["privileged"] = self.state.privileged_norm.state_dict()
        # TorchRL's Collector keeps its policy's weights in it (its load_state_dict needs them); FastCollector not
        state["collector"] = self._collector_state()
        return state

    def load_state_dict(self, state: dict) -> None:
        """init_from: the statistics only; resume (a "collector" entry): all of it, on every path and scale."""
        obs, norm = state.get("obs"), self.state.obs_norm
        if obs is not None and norm.enabled:
            norm.load_state_dict({**obs, "frozen": bool(state.get("obs_frozen", norm.frozen))})
        if state.get("return") is not None:
            self.state.reward_norm.load_state_dict(state["return"], running=False)
        if state.get("privileged") is not None and self.state.privileged_norm is not None:
            self.state.privileged_norm.load_state_dict(state["privileged"])
        if state.get("collector") is not None:
            if any(env_snapshot(part, self._key) is None for part in worker_parts(state["collector"])):
                raise ConfigError("this checkpoint was written by an earlier version of ppo_torchrl, before the env's "
                                  "state had one owner; resume it with that version, or start a new run from its "
                                  "weights and statistics with init_from=<its run dir>")
            self.collector.load_state_dict(state["collector"])  # each EnvState's snapshot, in every worker
        if self.multi:
            self._push()

    def close(self) -> None:
        if self._watch is not None:
            self._watch.stop()
        self.collector.shutdown()
        shutdown_ray(self.collector)  # the local Ray instance this run started, if any

