"""Periodic evaluations in a second process, so the training loop does not wait for them.

`eval.background` (auto: runs of >= 150k frames in a process allowed two or more CPUs; true; false).
At each eval point the trainer hands the worker the actor's weights and the frozen observation
statistics of that frame and goes on training; the worker runs the same `evaluate_policy` (the same
TorchRL env, statistics, episode seeds and deterministic actions) on the spare core. Rows of
metrics.csv wait for their eval and are written in order once it is back, so the file reads as if
the eval had run in line: its columns sit on the row of the frame it was taken at. The best
checkpoint is the state of that frame. The final eval runs once the pending ones are back, its episodes
shared between the trainer and the worker (`BackgroundEval.evaluate`).
Only evaluation runs there: the training arithmetic stays on one core.
"""

from __future__ import annotations

import copy
import multiprocessing as mp
import os
import queue
import signal
import sys
from typing import Callable, Dict, List

from ppo_torchrl.envs.make import episode_seeds
from ppo_torchrl.errors import ConfigError, EnvironmentFault
from ppo_torchrl.evaluate import evaluate_policy, merge_episodes, run_episodes, summarize

BACKGROUND_AUTO_MIN_FRAMES = 150_000
MAX_RESTARTS = 3  # a worker that dies more often than this is not a one-off kill: the run stops, saying so
BACKGROUND_CHOICES = ("auto", "true", "false")


def use_background_eval(cfg) -> bool:
    choice = str(cfg.eval.background).lower()
    if cfg.eval.every_frames <= 0 or choice == "false":
        return False
    spare_core = len(os.sched_getaffinity(0)) >= 2 if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1) >= 2
    return choice == "true" or (cfg.collector.total_frames >= BACKGROUND_AUTO_MIN_FRAMES and spare_core)


class BackgroundEval:
    """The worker process, the evals it has not returned yet, and the metrics rows waiting for them."""

    def __init__(self, cfg, write_row: Callable[[dict], None], on_result: Callable[[int, dict, object], dict]):
        from omegaconf import OmegaConf

        self._cfg, self._write_row, self._on_result = cfg, write_row, on_result
        self._cfg_dict = OmegaConf.to_container(cfg, resolve=True)
        self._pending: Dict[int, object] = {}  # frames -> what on_result gets back with the result
        self._sent: Dict[object, dict] = {}  # frames (None: a share of the final eval) -> the job, until back
        self._waiting: List[dict] = []  # rows logged while an earlier eval is out, in order
        self._restarts = 0
        self._start()

    def _start(self) -> None:
        # fork where there is one (Linux, as torch's DataLoader workers): spawn would import the user's
        # __main__ again, which a script without an `if __name__ == "__main__"` guard cannot take.
        context = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
        self._jobs, self._results = context.Queue(), context.Queue()
        self._process = context.Process(target=_serve, name="ppo_torchrl-eval", daemon=True,
                                        args=(self._cfg_dict, self._jobs, self._results, os.getpid()))
        self._process.start()

    def _restart(self) -> None:
        """The worker died (killed, out of memory): one warning line, a new worker, the evals it had sent again."""
        code = self._process.exitcode
        self._restarts += 1
        if self._restarts > MAX_RESTARTS:
            raise EnvironmentFault(f"the background eval process died {self._restarts} times (last exit code {code}); "
                                   "run with eval.background=false to evaluate in the training process")
        print(f"warning: the background eval process died (exit code {code}); started a new one and sent it the "
              f"{len(self._sent)} eval(s) not back yet", file=sys.stderr, flush=True)
        for old in (self._jobs, self._results):  # a worker killed mid-read can leave a queue's lock held: new ones
            old.cancel_join_thread()
            old.close()
        self._start()
        for job in self._sent.values():
            self._jobs.put(job)

    def _put(self, job: dict) -> None:
        self._sent[job["frames"]] = job
        self._jobs.put(job)

    def submit(self, frames: int, job: dict, keep: object = None) -> None:
        """Evaluate `job` (actor weights, obs stats, episodes, seed, deterministic, video path) for `frames`."""
        self._pending[frames] = keep
        self._put({"frames": frames, **job})

    def log(self, row: dict) -> None:
        """Write the row now, or once the evals before it (and its own) are back."""
        self._waiting.append(row)
        self.poll()

    def poll(self, block: bool = False) -> None:
        """Take the evals that are back; with block, wait for all of them."""
        while self._pending:
            back = self._receive(block)
            if back is None:
                break
            frames, result = back
            columns = self._on_result(frames, result, self._pending.pop(frames))
            for row in self._waiting:
                if row["frames"] == frames:
                    row.update(columns)
        while self._waiting and self._waiting[0]["frames"] not in self._pending:
            self._write_row(self._waiting.pop(0))

    def evaluate(self, ac, obs_stats, episodes: int, seed: int, deterministic: bool, video_path=None,
                 video_episodes=(0,), video_length=None) -> dict:
        """An eval now (the final one, after `poll(block=True)`), its episodes shared with the idle worker:
        each episode starts from its own seed, so the figures are those of `evaluate_policy` in line, in
        about half the time. Stochastic evals (the worker's own random stream) and robot envs (whose eval
        env may carry state, e.g. a terrain curriculum, from episode to episode) run wholly in line."""
        half = episodes // 2
        filmed_here = video_path is None or max(video_episodes) < half  # the filmed episodes are this process's
        if episodes < 2 or not deterministic or self._cfg.env.xml_file is not None or self._pending or not filmed_here:
            return evaluate_policy(self._cfg, ac, obs_stats, episodes, seed=seed, deterministic=deterministic,
                                   video_path=video_path, video_episodes=video_episodes, video_length=video_length)
        seeds = episode_seeds(seed, episodes)
        actor = {k: v.detach().to("cpu", copy=True) for k, v in ac.actor.state_dict().items()}
        self._put({"frames": None, "actor": actor, "obs_stats": copy.deepcopy(obs_stats), "seeds": seeds[half:],
                   "seed": seed, "deterministic": True})
        mine = run_episodes(self._cfg, ac, obs_stats, seeds[:half], True, video_path,
                            video_episodes=video_episodes, video_length=video_length, elsewhere=episodes - half)
        return summarize(self._cfg, merge_episodes(mine, self._receive(block=True)[1]))

    def _receive(self, block: bool):
        """(frames, result) of the next eval back; None when none is (block=False). A worker's error is
        raised here: a ConfigError as one line, anything else as a bug."""
        while True:
            try:
                frames, result, error = self._results.get(block=block, timeout=1.0 if block else None)
                break
            except queue.Empty:
                if self._sent and not self._process.is_alive():
                    self._restart()
                if not block:
                    return None
        self._sent.pop(frames, None)
        if error is not None:
            name, message, config_error = error
            raise ConfigError(message) if config_error else RuntimeError(f"background eval: {name}: {message}")
        return frames, result

    def close(self) -> None:
        """Stop the worker; rows still waiting are written without the evals that are not back."""
        self._pending.clear()
        self._sent.clear()
        self.poll()
        try:
            self._jobs.put(None)
            self._process.join(timeout=5)
        finally:
            if self._process.is_alive():
                self._process.terminate()
                self._process.join()
            self._jobs.close()
            self._results.close()


def _serve(cfg_dict: dict, jobs, results, parent_pid: int) -> None:
    """The worker: one actor, rebuilt from the run's config; each job loads weights and evaluates."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group: the trainer decides
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the trainer's handler, forked with it
    import torch
    from omegaconf import OmegaConf

    from ppo_torchrl.envs.make import env_spec, seed_everything
    from ppo_torchrl.rl.models import make_actor_critic

    torch.set_num_threads(1)
    cfg = OmegaConf.create(cfg_dict)
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env), "cpu")
    while True:
        try:
            job = jobs.get(timeout=1.0)
        except queue.Empty:
            if os.getppid() != parent_pid:  # the trainer is gone (killed): so is this worker
                return
            continue
        if job is None:
            return
        try:
            ac.actor.load_state_dict(job["actor"])
            seed_everything(job["seed"])  # a stochastic eval draws from this process's own stream
            if "seeds" in job:  # a share of an eval's episodes: their record, merged by the trainer
                result = run_episodes(cfg, ac, job["obs_stats"], job["seeds"], job["deterministic"], progress=False)
            else:
                result = evaluate_policy(cfg, ac, job["obs_stats"], job["episodes"], seed=job["seed"],
                                         deterministic=job["deterministic"], video_path=job["video_path"],
                                         video_episodes=job["video_episodes"], video_length=job["video_length"],
                                         progress=False)
            results.put((job["frames"], result, None))
        except Exception as exc:  # noqa: BLE001  raised again in the trainer, as one line or as a bug
            results.put((job["frames"], None, (type(exc).__name__, str(exc), isinstance(exc, ConfigError))))
