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

from ppo_torchrl.internals import mark_started_ray, started_ray, worker_processes
from ppo_torchrl.envs.make import make_torchrl_env
from ppo_torchrl.errors import ConfigError, EnvironmentFault
from ppo_torchrl.run.loggers import quiet_mujoco


def is_ray_running() -> bool:
    import ray

    return ray.is_initialized()


def worker_env(env_cfg: dict, clip_actions: bool, gamma: float, num_envs: int, obs_stats: Optional[dict],
               seed: int, privileged: bool = False):
    """A worker's env, built in the worker: a plain dict config so that it pickles (under
    functools.partial). The main process alone answers signals: a Ctrl-C reaches the whole process
    group, and the workers must finish the batch the main process saves."""
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)
    quiet_mujoco()  # a spawned worker is a fresh process: MuJoCo's deprecation notices would print again here
    return make_torchrl_env(OmegaConf.create(env_cfg), clip_actions=clip_actions, gamma=gamma, obs_stats=obs_stats,
                            train=True, device="cpu", num_envs=num_envs, seed=seed, threads=1,  # a core a worker
                            privileged=privileged)


def make_multi_collector(c, make_env: list, policy, collector_class: type, kwargs: dict):
    kwargs = dict(kwargs, collector_class=collector_class)
    if c.distributed == "ray":
        return make_ray_collector(c, make_env, policy, kwargs)
    from torchrl.collectors import MultiSyncCollector

    return MultiSyncCollector(make_env, policy, cat_results="stack", **kwargs)


class WorkerWatch:
    """A worker that dies while the run uses it (kill -9, out of memory) ends the run at once, whatever the
    load, with one line naming it. A thread waits on the workers' process sentinels, which the kernel wakes
    the instant a process ends (no polling, no timeout to tune). It then SIGKILLs the other workers (their
    batch cannot be used: nothing of theirs is saved; they ignore SIGTERM, see worker_env) and sends SIGUSR1
    to the main thread, whose handler raises the error: a signal ends any blocking call the main thread is
    in (a pipe, a queue, a lock), so no wait on a dead worker outlives it. TorchRL's own checks may see
    the death first, and a TorchRL wait may catch the handler's error and log it (its weight-update ack
    wait does) before raising its own: `error()` gives the same line every time it is asked, so the
    collector's catch names the worker whichever error reaches it. `stop()` before a shutdown."""

    def __init__(self, procs: list):
        self.procs = list(procs)
        self.dead: Optional[tuple] = None  # (index, process) of the first worker that ended
        self._raised = False
        self._stop_r, self._stop_w = os.pipe()
        self._previous = signal.signal(signal.SIGUSR1, self._interrupt)
        self._thread = threading.Thread(target=self._watch, name="ppo_torchrl-worker-watch", daemon=True)
        self._thread.start()

    @classmethod
    def of(cls, collector) -> Optional["WorkerWatch"]:
        """A watch over a multi-process collector's workers (None for Ray, or off the main thread)."""
        procs = worker_processes(collector)
        if not procs or threading.current_thread() is not threading.main_thread():
            return None
        return cls(procs)

    def _watch(self) -> None:
        from multiprocessing.connection import wait

        sentinels = {p.sentinel: i for i, p in enumerate(self.procs)}
        ready = wait([*sentinels, self._stop_r])
        if self._stop_r in ready:
            return
        i = min(sentinels[s] for s in ready if s in sentinels)
        self.dead = (i, self.procs[i])
        for j, proc in enumerate(self.procs):
            if j != i:
                try:
                    os.kill(proc.pid, signal.SIGKILL)
                except OSError:
                    pass  # already gone
        signal.pthread_kill(threading.main_thread().ident, signal.SIGUSR1)

    def _interrupt(self, signum, frame) -> None:
        if self.dead is not None and not self._raised:
            self._raised = True
            raise self.error()

    def error(self, timeout_s: float = 2.0) -> Exception:
        """The one line for a dead worker (an EnvironmentFault); None if no worker has died."""
        if self.dead is None:  # TorchRL saw it first: the sentinel wakes the thread at the same instant
            self._thread.join(timeout_s)
        if self.dead is None:
            return None
        from ppo_torchrl.run.signals import ON_DISK

        i, proc = self.dead
        proc.join(timeout_s)  # reaped, for its exit code
        code = proc.exitcode
        how = "exit code unknown" if code is None else \
            f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
        return EnvironmentFault(f"collector worker {i} (pid {proc.pid}) died ({how}); {ON_DISK.describe()}")

    def stop(self) -> None:
        """Before the workers are shut down on purpose: their ends are not deaths."""
        os.write(self._stop_w, b"x")
        self._thread.join()
        signal.signal(signal.SIGUSR1, self._previous)
        for fd in (self._stop_r, self._stop_w):
            os.close(fd)


def shutdown_ray(collector) -> None:
    """The local Ray instance this run started (a cluster joined stays up)."""
    if started_ray(collector):
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
    mark_started_ray(collector, started)
    return collector
