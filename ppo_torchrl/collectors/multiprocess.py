"""Several processes for one run: TorchRL's `MultiSyncCollector` (`collector.workers` > 1) or `RayCollector`
(`collector.distributed=ray`), each building `collector_class` (FastCollector or TorchRL's Collector) in
every worker over `make_torchrl_env(...)` (`collector.num_envs` envs each). Synchronous: one batch is
frames_per_batch / workers frames from each worker, all collected with the weights of the last update.
The statistics are merged by collection.py; here: building the workers, and the errors they raise.
"""

from __future__ import annotations

import os
import signal
import socket
import sys
import threading
from typing import Optional

from omegaconf import OmegaConf

from ppo_torchrl.envs import make_torchrl_env
from ppo_torchrl.errors import ConfigError, EnvironmentFault
from ppo_torchrl.loggers import quiet_mujoco


def is_ray_running() -> bool:
    import ray

    return ray.is_initialized()


def worker_env(env_cfg: dict, clip_actions: bool, gamma: float, num_envs: int, obs_stats: Optional[dict],
               seed: int):
    """A worker's env, built in the worker: a plain dict config so that it pickles (under
    functools.partial). The main process alone answers signals: a Ctrl-C reaches the whole process
    group, and the workers must finish the batch the main process saves."""
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)
    quiet_mujoco()  # a spawned worker is a fresh process: MuJoCo's deprecation notices would print again here
    return make_torchrl_env(OmegaConf.create(env_cfg), clip_actions=clip_actions, gamma=gamma, obs_stats=obs_stats,
                            train=True, device="cpu", num_envs=num_envs, seed=seed)


def make_multi_collector(c, make_env: list, policy, collector_class: type, kwargs: dict):
    kwargs = dict(kwargs, collector_class=collector_class)
    if c.distributed == "ray":
        return make_ray_collector(c, make_env, policy, kwargs)
    from torchrl.collectors import MultiSyncCollector

    return MultiSyncCollector(make_env, policy, cat_results="stack", **kwargs)


def dead_worker_error(collector) -> None:
    """A worker killed (kill -9, out of memory) is one line naming it and what is on disk, not TorchRL's error."""
    from ppo_torchrl.signals import ON_DISK

    import time

    procs = getattr(collector, "procs", []) or []
    deadline = time.monotonic() + 2.0  # a pipe can report the end a moment before the process is reaped
    dead = []
    while procs and not dead and time.monotonic() < deadline:
        dead = [(i, p) for i, p in enumerate(procs) if not p.is_alive()]
        if not dead:
            time.sleep(0.05)
    if dead:  # the one a signal killed first (the others may have been shut down after it)
        i, proc = min(dead, key=lambda d: (d[1].exitcode or 0) >= 0)
        code = proc.exitcode or 0
        how = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
        raise EnvironmentFault(f"collector worker {i} (pid {proc.pid}) died ({how}); {ON_DISK.describe()}") from None


def shutdown_ray(collector) -> None:
    """The local Ray instance this run started (a cluster joined stays up)."""
    if getattr(collector, "_ppo_started_ray", False):
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


def make_ray_collector(c, make_env: list, policy, kwargs: dict):
    """TorchRL's RayCollector, synchronous: one batch is frames_per_batch / workers from each remote
    collector, all collected with the same weights."""
    import ray
    from torchrl.collectors.distributed import RayCollector

    started = not c.ray_address and not ray.is_initialized()
    where = f"collector.ray_address={c.ray_address}" if c.ray_address else "a local Ray instance"
    if not ray.is_initialized():
        check_reachable(c.ray_address)
        try:
            ray.init(address=c.ray_address, include_dashboard=False, log_to_driver=False,
                     configure_logging=True, logging_level="error")  # not its notices
        except (ConnectionError, RuntimeError, ValueError) as exc:
            detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ConfigError(f"cannot start or join {where}: {detail}") from None
    print(f"ray: {len(ray.nodes())} node(s), {int(ray.cluster_resources().get('CPU', 0))} CPUs", file=sys.stderr)
    kwargs["total_frames"] = sys.maxsize  # RayCollector reads -1 (endless) as "nothing to collect"
    collector = RayCollector(make_env, policy, sync=True, num_collectors=c.workers,
                             remote_configs={"num_cpus": 1, "memory": 1024**3}, **kwargs)
    collector._ppo_started_ray = started
    return collector
