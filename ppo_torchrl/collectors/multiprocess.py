"""One run on several processes: TorchRL's `MultiSyncCollector` (`collector.workers` > 1) or
`RayCollector` (`collector.distributed=ray`), over the env of the torchrl backend.

Each worker steps `make_torchrl_env(...)` (`collector.num_envs` envs, `env.transforms.extra`
included). `collect()` first sends the learner's weights to every worker (`update_policy_weights_()`);
each worker then collects frames_per_batch / workers frames with them, and the batch is all of them,
[workers x num_envs, steps]: synchronous, exactly frames_per_batch on-policy frames.

Statistics, one set for the run: while collecting, each worker's VecNorm and ReturnNormalization
update as in one process. After each batch the main process reads every worker's transform state
(the collector's `state_dict()`), pools what each worker added since the last merge into one set
(counts, first and second moments: the exact mean and variance of every observation, and of every
discounted return, that any worker saw, whatever the workers' timing), keeps it in its own copy of
the env's transforms (`self.env`, never stepped: `obs_stats()`, checkpoints) and loads it into every
worker (`load_state_dict()`). Within a batch a worker normalizes with the merged set plus its own
new frames. Each env's running discounted return stays in its worker.
"""

from __future__ import annotations

import functools
import os
import signal
import socket
import sys
import threading
from typing import List, Optional, Tuple

import torch
from omegaconf import OmegaConf
from tensordict import TensorDict
from torchrl.envs import ObservationNorm, VecNormV2

from ppo_torchrl.collectors.torchrl_collector import TorchRLCollector
from ppo_torchrl.envs import make_torchrl_env, torchrl_obs_stats
from ppo_torchrl.errors import ConfigError, EnvironmentFault
from ppo_torchrl.loggers import quiet_mujoco
from ppo_torchrl.models import ActorCritic
from ppo_torchrl.normalization import ReturnNormalization

Moments = Tuple[torch.Tensor, torch.Tensor, torch.Tensor]  # count, mean, mean of squares


def is_ray_running() -> bool:
    import ray

    return ray.is_initialized()


def worker_env(env_cfg: dict, clip_actions: bool, gamma: float, num_envs: int, obs_stats: Optional[dict]):
    """A worker's env, built in the worker: a plain dict config so that it pickles (under
    functools.partial). The main process alone answers signals: a Ctrl-C reaches the whole process
    group, and the workers must finish the batch the main process saves."""
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)
    quiet_mujoco()  # a spawned worker is a fresh process: MuJoCo's deprecation notices would print again here
    return make_torchrl_env(OmegaConf.create(env_cfg), clip_actions=clip_actions, gamma=gamma,
                            obs_stats=obs_stats, train=True, device="cpu", num_envs=num_envs)


def pool(base: Optional[Moments], parts: List[Moments]) -> Moments:
    """Each part is `base` plus what one worker added; the result is `base` plus all of it."""
    c0, m0, s0 = base if base is not None else (0.0, 0.0, 0.0)
    count = c0 + sum(c - c0 for c, _, _ in parts)
    mean = (c0 * m0 + sum(c * m - c0 * m0 for c, m, _ in parts)) / count
    square = (c0 * s0 + sum(c * s - c0 * s0 for c, _, s in parts)) / count
    return count, mean, square


def vecnorm_moments(state: dict) -> Moments:
    """VecNorm's extra state: its `loc` is the mean, its `var` the mean of squares (decay=1)."""
    td = TensorDict(state).unflatten_keys(VecNormV2.SEP)
    return td["count", "observation"].double(), td["loc", "observation"], td["var", "observation"]


def vecnorm_state(moments: Moments, like: dict) -> dict:
    count, mean, square = moments
    td = TensorDict(like).unflatten_keys(VecNormV2.SEP).clone()
    td["count", "observation"] = count.round().to(td["count", "observation"].dtype)
    td["loc", "observation"], td["var", "observation"] = mean, square
    return td.flatten_keys(VecNormV2.SEP).to_dict()


def return_moments(state: dict) -> Moments:
    mean = torch.as_tensor(state["mean"], dtype=torch.float64)
    return torch.as_tensor(state["count"], dtype=torch.float64), mean, torch.as_tensor(state["var"]) + mean**2


def return_state(moments: Moments, like: dict) -> dict:
    count, mean, square = moments
    return {**like, "count": count, "mean": mean, "var": square - mean**2}


class MultiProcessCollector(TorchRLCollector):
    """The torchrl backend's batches, stats and checkpoints, collected by several processes."""

    RESUMES_EPISODES = False  # the envs live in the workers: a resume starts new episodes there

    def __init__(self, cfg, ac: ActorCritic, seed: int, device: torch.device):
        c, t = cfg.collector, cfg.env.transforms
        warn_if_oversubscribed(c)
        env_kwargs = dict(clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma)
        # The main process's copy of the transforms: it holds the merged statistics, and is never stepped.
        self.env = make_torchrl_env(cfg.env, train=True, device="cpu", **env_kwargs)
        self.env.reset()  # VecNorm takes its shapes from a first observation (merges then overwrite it)
        self.epsilon = t.norm_epsilon
        # obs_norm=fixed: the statistics fitted here, frozen in every worker (not fitted once per worker)
        fixed = torchrl_obs_stats(next(self._stats_modules(ObservationNorm)), 0) if t.obs_norm == "fixed" else None
        make_env = functools.partial(worker_env, OmegaConf.to_container(cfg.env, resolve=True),
                                     num_envs=c.num_envs, obs_stats=fixed, **env_kwargs)
        self.workers = c.workers
        self.started_ray = c.distributed == "ray" and not c.ray_address and not is_ray_running()
        # Workers start with SIGINT blocked (inherited): a Ctrl-C while they import is the main process's
        # alone (one line), not a traceback from each worker; here it waits until they have started.
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            self.collector = self._make(c, [make_env] * c.workers, ac, device)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        self.collector.set_seed(seed)
        self._base = None  # the merged moments the workers started the batch from (None: nothing seen)
        self._start(c.workers * c.num_envs)

    @staticmethod
    def _make(c, make_env: list, ac: ActorCritic, device: torch.device):
        kwargs = dict(frames_per_batch=c.frames_per_batch, total_frames=-1, policy_device=device, env_device="cpu",
                      storing_device=device)
        if c.distributed == "ray":
            return make_ray_collector(c, make_env, ac, kwargs)
        from torchrl.collectors import MultiSyncCollector

        return MultiSyncCollector(make_env, ac.actor, cat_results="stack", **kwargs)

    def _stats_modules(self, kind):
        return (module for module in self.env.transform.modules() if isinstance(module, kind))

    def collect(self) -> TensorDict:
        try:
            self.collector.update_policy_weights_()  # every worker collects with the weights of the last update
            batch = super().collect()
            self._merge_stats()
        except Exception:
            self._raise_if_a_worker_died()
            raise
        return batch

    def _raise_if_a_worker_died(self) -> None:
        """A worker killed (kill -9, out of memory) is one line naming it and what is on disk, not TorchRL's error."""
        from ppo_torchrl.signals import ON_DISK

        dead = [(i, p) for i, p in enumerate(getattr(self.collector, "procs", []) or []) if not p.is_alive()]
        if dead:  # the one a signal killed first (the others may have been shut down after it)
            i, proc = min(dead, key=lambda d: (d[1].exitcode or 0) >= 0)
            code = proc.exitcode or 0
            how = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
            raise EnvironmentFault(f"collector worker {i} (pid {proc.pid}) died ({how}); {ON_DISK.describe()}") from None

    # ---------------------------------------------------------------- statistics
    def _stat_keys(self) -> dict:
        """State-dict keys of the transforms that hold statistics, by kind."""
        keys = {}
        for name, module in self.env.transform.named_modules():
            if isinstance(module, (VecNormV2, ReturnNormalization)):
                keys[f"{name}._extra_state"] = type(module)
            elif isinstance(module, ObservationNorm):  # fixed: the same in every worker, loaded on resume
                keys.update({f"{name}.loc": ObservationNorm, f"{name}.scale": ObservationNorm})
        return keys

    def _worker_states(self) -> Tuple[object, list]:
        """The collector's state (MultiSyncCollector: {"worker0": ..., "frames": ...}; Ray: a list),
        and each worker's part of it, whose `env_state_dict` is its env's transform state."""
        whole = self.collector.state_dict()
        return whole, [whole[f"worker{i}"] for i in range(self.workers)] if isinstance(whole, dict) else list(whole)

    def _merge_stats(self) -> None:
        """Pool every worker's statistics into `self.env` and load that one set into every worker."""
        keys = self._stat_keys()
        if not any(kind is not ObservationNorm for kind in keys.values()):
            return
        whole, workers = self._worker_states()
        mine = self.env.transform.state_dict()
        base = self._base or {}
        for key, kind in keys.items():
            if kind is VecNormV2:
                moments = pool(base.get(key), [vecnorm_moments(w["env_state_dict"][key]) for w in workers])
                mine[key] = vecnorm_state(moments, mine[key])
            elif kind is ReturnNormalization:  # every worker starts from the same prior, as the copy here
                prior = base.get(key, return_moments(mine[key]))
                mine[key] = return_state(pool(prior, [return_moments(w["env_state_dict"][key]) for w in workers]),
                                         mine[key])
        self.env.transform.load_state_dict(mine)
        self._push(whole, workers)

    def _push(self, whole=None, workers: Optional[list] = None) -> None:
        """Load the statistics of `self.env` into every worker (each keeps its envs' running returns)."""
        keys, mine = self._stat_keys(), self.env.transform.state_dict()
        if whole is None:
            whole, workers = self._worker_states()
        for w in workers:
            env_state = w["env_state_dict"]
            for key, kind in keys.items():
                env_state[key] = ({**mine[key], "returns": env_state[key]["returns"]} if kind is ReturnNormalization
                                  else mine[key])
        self.collector.load_state_dict(whole)
        self._base = {key: (vecnorm_moments if kind is VecNormV2 else return_moments)(mine[key])
                      for key, kind in keys.items() if kind is not ObservationNorm}

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)  # into self.env
        self._push()

    def close(self) -> None:
        self.collector.shutdown()
        if self.started_ray:  # the local Ray instance of this run (a cluster joined stays up)
            import ray

            ray.shutdown()


def warn_if_oversubscribed(collector_cfg) -> None:
    """More local worker processes than cores runs, only slower: one line on stderr, once per run."""
    cores = os.cpu_count() or 1
    if collector_cfg.workers > cores and not collector_cfg.ray_address:
        print(f"warning: collector.workers={collector_cfg.workers} is more than this machine's {cores} cores; "
              "the workers will share them (and run no faster than with fewer)", file=sys.stderr, flush=True)


def check_reachable(address: Optional[str], timeout_s: float = 5.0) -> None:
    """A host:port that nothing answers on is one line in seconds (ray.init would retry for minutes)."""
    if not address or address == "auto" or "://" in address:
        return  # auto: Ray reads the address `ray start` wrote on this node, and says so when there is none
    host, _, port = address.rpartition(":")
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout_s).close()
    except (OSError, ValueError) as exc:
        raise ConfigError(f"collector.ray_address={address}: no Ray head answers there ({exc}); start one with "
                          "`ray start --head` and give its address (or auto on its node)") from None


def make_ray_collector(c, make_env: list, ac: ActorCritic, kwargs: dict):
    """TorchRL's RayCollector, synchronous: one batch is frames_per_batch / workers from each remote
    collector, all collected with the same weights."""
    import ray
    from torchrl.collectors.distributed import RayCollector

    where = f"collector.ray_address={c.ray_address}" if c.ray_address else "a local Ray instance"
    if not ray.is_initialized():
        check_reachable(c.ray_address)
        try:
            ray.init(address=c.ray_address, include_dashboard=False, log_to_driver=False,
                     configure_logging=True, logging_level="warning")
        except (ConnectionError, RuntimeError, ValueError) as exc:
            detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ConfigError(f"cannot start or join {where}: {detail}") from None
    print(f"ray: {len(ray.nodes())} node(s), {int(ray.cluster_resources().get('CPU', 0))} CPUs", file=sys.stderr)
    kwargs["total_frames"] = sys.maxsize  # RayCollector reads -1 (endless) as "nothing to collect"
    return RayCollector(make_env, ac.actor, sync=True, num_collectors=c.workers,
                        remote_configs={"num_cpus": 1, "memory": 1024**3}, **kwargs)
