"""The training loop: collect -> advantage -> epochs x minibatches -> log / eval / checkpoint.

Reads top to bottom like CleanRL's ppo_continuous_action.py; each component comes from the
module named like its config group (envs, models, losses, advantage, collector, ...).
"""

from __future__ import annotations

import copy
import math
import random
import shlex
import sys
import time
from collections import deque
from functools import partial
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from ppo_torchrl.run import checkpoint

from ppo_torchrl.run import rundir

from ppo_torchrl.run import startup
from ppo_torchrl.rl.advantage import explained_variance, make_advantage
from ppo_torchrl.run.checkpoint import CheckpointManager, check_spec
from ppo_torchrl.collectors import make_collector
from ppo_torchrl.envs.make import EnvSpec, env_label, seed_everything
from ppo_torchrl.errors import ConfigError, Interrupted, TrainingError
from ppo_torchrl.run.eval_worker import BackgroundEval, use_background_eval
from ppo_torchrl.evaluate import evaluate_policy
from ppo_torchrl.run.lifecycle import Lifecycle
from ppo_torchrl.run.loggers import (COLUMNS, MetricsFile, Progress, amend_last_row, close_logger, make_logger,
                                 truncate_logs)
from ppo_torchrl.rl.losses import LOSS_INPUT_KEYS, LOSS_METRICS, NOT_COMPILABLE, make_loss, make_optimizer
from ppo_torchrl.rl.minibatch import make_minibatch_step
from ppo_torchrl.run.model_record import model_record
from ppo_torchrl.rl.models import make_actor_critic
from ppo_torchrl.run.signals import ON_DISK, Interrupt, StopRequest
from ppo_torchrl.validation import resolve_device, validate_config


def batch_entropy(dist) -> float:
    """Mean policy entropy; a one-sample estimate where there is no closed form (TanhNormal)."""
    try:
        return dist.entropy().mean().item()
    except NotImplementedError:
        return -dist.log_prob(dist.sample()).mean().item()


COMPILE_AUTO_MIN_FRAMES = 150_000


def use_compile(cfg) -> bool:
    choice = str(cfg.compile).lower()
    return choice == "true" or (choice == "auto" and cfg.collector.total_frames >= COMPILE_AUTO_MIN_FRAMES
                                and cfg.loss.name not in NOT_COMPILABLE)


def continued_schedule(state: dict, cfg, num_iterations: int) -> tuple:
    """The lr schedule's anchor after a resume. The same budget: the checkpoint's. A budget extended
    (resume= with more collector.total_frames): from the lr of the last update the run made, down to 0 at
    the new end, with no jump (a restart at optim.lr would undo the annealing). A new optim.lr scales it."""
    saved = state.get("config") or {}
    old_lr = (saved.get("optim") or {}).get("lr", cfg.optim.lr)
    a, lr_a = state.get("lr_schedule") or (0, old_lr)  # checkpoints before the anchor: the schedule from 0
    collector = saved.get("collector") or {}
    old_n = math.ceil(collector.get("total_frames", cfg.collector.total_frames)
                      / collector.get("frames_per_batch", cfg.collector.frames_per_batch))
    i = state["iteration"]
    if old_n != num_iterations and cfg.optim.anneal_lr and 0 < i <= old_n and i - 1 >= a:
        a, lr_a = i - 1, lr_a * (1.0 - (i - 1 - a) / (old_n - a))  # the lr the last update used
    if cfg.optim.lr == old_lr or not old_lr:  # the same lr: the saved anchor as it is (a bit-exact resume)
        return a, lr_a
    return a, lr_a * cfg.optim.lr / old_lr


class Trainer:
    def __init__(self, cfg, run_dir: Path, resume: Optional[dict] = None, spec: Optional[EnvSpec] = None,
                 life: Optional[Lifecycle] = None):
        """resume: the checkpoint a resume continues (Lifecycle.resume read and checked it); spec: the env spec the
        command's check built, with its env; life: the command's Lifecycle (the dir it claimed is committed once
        the run is set up). Without them (a test, a library user) the config is checked here."""
        self.spec = spec if spec is not None else validate_config(cfg, keep_env=True)
        self.life = life if life is not None else Lifecycle()
        self.cfg = cfg
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.model = model_record(cfg.env)  # the robot model it trains on, in every checkpoint (model_record.py)
        ON_DISK.__init__(run_dir=self.run_dir, total_frames=startup.frame_budget(cfg)[1])  # what this run has saved: nothing yet
        torch.set_num_threads(cfg.torch_threads)
        self.device = resolve_device(cfg.device)
        seed_everything(cfg.seed)

        self.ac = make_actor_critic(cfg.policy, self.spec, self.device)
        self.loss_module = make_loss(cfg.loss, self.ac)
        self.advantage = make_advantage(cfg.advantage, self.ac.critic)
        self.params = [p for p in self.loss_module.parameters() if p.requires_grad]
        self.optimizer = make_optimizer(cfg.optim, self.params, self.device)
        # loss -> backward -> clip -> optimizer step: one compiled function with compile on (minibatch.py)
        self.minibatch_step = make_minibatch_step(cfg, self.loss_module, self.optimizer, self.params,
                                                  compile=use_compile(cfg))
        self.collector = make_collector(cfg, self.ac, cfg.seed, self.device, self.spec.take_env())
        try:
            self._set_up(cfg, resume)
        except BaseException:  # worker processes (collector.workers > 1) must not outlive a failed start
            self.collector.close()
            raise

    def _set_up(self, cfg, resume: Optional[dict]) -> None:
        self.logger = make_logger(cfg.logger, self.run_dir, run_name=f"{cfg.env.id}_seed{cfg.seed}_{self.run_dir.name}")
        self.ckpt = CheckpointManager(self.run_dir / rundir.CHECKPOINTS, cfg.checkpoint.keep_last, cfg.checkpoint.save_best)

        self.frames = 0
        self.iteration = 0
        self.lr_anchor = (0, cfg.optim.lr)  # the lr schedule runs linearly from here to 0 (_set_lr)
        # At least total_frames, as SB3's learn(): 1M frames at 2048 per batch is 489 batches.
        self.num_iterations = math.ceil(cfg.collector.total_frames / cfg.collector.frames_per_batch)
        self.recent_returns: deque = deque(maxlen=100)
        self.last_eval: Optional[dict] = None
        self.evals: Optional[BackgroundEval] = None  # eval.background: started by train()
        self.train_time = 0.0  # seconds spent collecting and updating (what SPS divides by)
        self.start_time = time.perf_counter()
        self.earlier_wall_time = 0.0  # seconds the run ran before it was resumed
        self.resumed = resume is not None
        if resume is not None:
            self._restore(resume)
        elif cfg.init_from:
            self._init_from(cfg.init_from, cfg.init_from_optimizer)
        self._first_iteration = self.iteration

    def _restore(self, state: dict) -> None:
        """Continue from a checkpoint: weights, optimizer, stats, envs, counters and RNG streams."""
        self._load_networks(state, f"resume={self.run_dir}")
        self.loss_module.load_state_dict(state.get("loss_module", {}), strict=False)
        self.optimizer.load_state_dict(state["optimizer"])
        self.collector.load_state_dict(state["normalization"])
        self.frames, self.iteration = state["frames"], state["iteration"]
        self.lr_anchor = continued_schedule(state, self.cfg, self.num_iterations)
        ON_DISK.checkpoint, ON_DISK.checkpoint_frames = self.ckpt.dir / checkpoint.LAST, self.frames
        ON_DISK.frames = self.frames
        self.recent_returns.extend(state.get("recent_returns", []))
        self.last_eval = state.get("last_eval")
        self.ckpt.best_return = state.get("best_eval_return")
        self.train_time = state.get("train_time", 0.0)
        self.earlier_wall_time = state.get("wall_time", 0.0)
        rng = state["rng"]
        torch.set_rng_state(rng["torch"])
        np.random.set_state(rng["numpy"])
        random.setstate(rng["python"])

    def _load_networks(self, state: dict, source: str) -> None:
        """Actor and critic weights of a checkpoint; sizes that do not fit are a one-line error."""
        check_spec(state, self.spec, self.cfg.env.id)
        try:
            self.ac.actor.load_state_dict(state["actor"])
            self.ac.critic.load_state_dict(state["critic"])
        except RuntimeError as exc:
            detail = next((l.strip() for l in str(exc).splitlines() if "size mismatch" in l or "Missing" in l
                           or "Unexpected" in l), str(exc).splitlines()[0])
            raise ConfigError(f"{source}: its networks do not fit this run's policy config "
                              f"({detail.rstrip('.')}); use the same policy.* settings as that run") from None

    def _init_from(self, source: str, with_optimizer: bool) -> None:
        """Transfer: weights and normalization stats (and optimizer state) of another run; counters,
        envs and RNG streams start fresh. A run dir gives its best checkpoint."""
        path = self.life.source(Path(source))  # init_from=<the dir this run overwrites>: its old files
        if path.is_dir():
            path = checkpoint.resolve_checkpoint(path, "best")
        if not path.is_file():
            raise ConfigError(f"init_from={source}: no such run dir or checkpoint file")
        state = checkpoint.load(path)
        self._load_networks(state, f"init_from={source}")
        if with_optimizer:
            if "optimizer" not in state:
                raise ConfigError(f"init_from={source}: {path} is a record checkpoint (no optimizer state); "
                                  "leave out init_from_optimizer")
            self.optimizer.load_state_dict(state["optimizer"])
        norm = state["normalization"]
        self.collector.load_state_dict({k: norm.get(k) for k in ("obs", "return", "privileged")})
        source_env = state.get("config", {}).get("env", {})
        print(f"init_from: weights{', optimizer' if with_optimizer else ''} and normalization stats of {path} "
              f"({state['frames']} frames on {env_label(source_env)})", file=sys.stderr)

    # ---------------------------------------------------------------- the loop
    def train(self) -> dict:
        cfg = self.cfg
        if self.resumed:
            truncate_logs(self.run_dir, self.frames)
        columns = COLUMNS + [k for k in self.collector.metric_keys() if k not in COLUMNS]  # the task's own too
        if cfg.loss.stop_kl is not None:  # how many epochs each update ran before the KL stop
            columns.append("train/epochs")
        self.metrics = MetricsFile(self.run_dir / "metrics.csv", columns, append=self.resumed)
        if not self.resumed:  # a resume's overrides reach config.yaml once an iteration has completed
            self.write_config()
        self.life.commit(self.run_dir)  # set up without error: the run starts, what overwrite=true replaced goes
        ON_DISK.started = True
        finishing = self.resumed and self.iteration >= self.num_iterations  # every batch trained, not finished
        print(startup.describe_resume(self.run_dir, self.frames, cfg) + (
              "; every batch is trained: the final eval runs and the run is marked finished" if finishing else "")
              if self.resumed else startup.describe_start(cfg, startup.command_line() or self.life.overrides),
              file=sys.stderr, flush=True)  # (the API's overrides: life.overrides, the CLI's: Hydra's)
        batch_frames = cfg.collector.frames_per_batch
        stop = StopRequest()
        self.progress = Progress(self.num_iterations * batch_frames, self.frames, cfg.logger.print_every_s)
        if use_background_eval(cfg):
            self.evals = BackgroundEval(cfg, self._write_row, self._eval_done)
        try:
            with stop:
                if finishing:
                    self._finish(stop)
                else:
                    self._loop(stop, batch_frames)
        except Interrupt as signal_:  # a second signal: the iteration in flight is abandoned
            self.write_summary(status="interrupted")
            raise Interrupted(f"stopped at once; {ON_DISK.describe()}", signal_.signum) from None
        except Interrupted:
            raise
        except Exception:  # a dead helper process, a full disk, a bug: the summary says the run failed
            try:
                self.write_summary(status="failed")
            except OSError:
                pass
            raise
        finally:
            if self.evals is not None:  # rows still waiting are written, without evals not back
                self.evals.close()
            self.progress.close()
            self.metrics.close()
            self.collector.close()
            if self.logger is not None:
                close_logger(self.logger)
            rundir.record(self.run_dir)
        return self.summary(status="finished")

    def _loop(self, stop: StopRequest, batch_frames: int) -> None:
        cfg = self.cfg
        while self.iteration < self.num_iterations:
            tick = time.perf_counter()
            lr = self._set_lr()
            batch = self.collector.collect()
            update_stats = self.update(batch)
            self.frames += batch_frames
            self.iteration += 1
            self.train_time += time.perf_counter() - tick
            ON_DISK.frames = self.frames
            if self.resumed and self.iteration == self._first_iteration + 1:
                self.write_config()

            last = self.iteration == self.num_iterations
            row = {"iteration": self.iteration, "frames": self.frames, "lr": lr, **update_stats}
            row.update(self._episode_stats())
            if last and self.evals is not None:
                self.evals.poll(block=True)  # the background evals first: their rows, last_eval and best
            if last and cfg.eval.final_episodes > 0 and stop.signum is None:
                self.save_checkpoint()  # the trained frames are on disk before the final eval, which a signal stops
                stop.at_once = True
                row.update(self._evaluate(cfg.eval.final_episodes))
                stop.at_once = False
            elif not last and self._crossed(cfg.eval.every_frames):
                row.update(self._evaluate(cfg.eval.episodes, background=self.evals is not None))
            row["time_s"] = self.wall_time()
            row["sps"] = self.frames / self.train_time
            self._log(row)
            if last or stop.signum is not None or self._crossed(cfg.checkpoint.every_frames):
                path = self.save_checkpoint(eval_return=row.get("eval/return_mean"))
            if stop.signum is not None:
                if self.evals is not None:  # the evals under way (seconds): their rows as an uninterrupted run has them
                    self.evals.poll(block=True)
                self.write_summary(status="interrupted")
                run = shlex.quote(str(self.run_dir))
                then = (f"every frame is trained; the final eval was skipped: python -m ppo_torchrl resume={run} "
                        "runs it and marks the run finished" if last else f"resume with: python -m ppo_torchrl resume={run}")
                raise Interrupted(f"checkpoint at frame {self.frames} saved to {path} ({then})", stop.signum)
            self.write_summary(status="finished" if last else "running")

    def _finish(self, stop: StopRequest) -> None:
        """resume= of a run stopped after its last batch (a signal skipped or cut its final eval, a kill came
        before its last summary): the final eval, if it has not run at these frames, then `finished`. The eval's
        figures join the last row of metrics.csv, as in a run that was not stopped (a row the stop cut is written
        with what the checkpoint holds)."""
        cfg = self.cfg
        ran = self.last_eval is not None and self.last_eval.get("frames") == self.frames
        if cfg.eval.final_episodes > 0 and not ran:
            stop.at_once = True  # a signal stops the eval at once; the run stays as it was, to finish again
            row = self._evaluate(cfg.eval.final_episodes)
            stop.at_once = False
            if amend_last_row(self.run_dir / "metrics.csv", self.frames, row):
                if self.logger is not None:
                    for key, value in row.items():
                        self.logger.log_scalar(key, value, step=self.frames)
            else:  # the signal cut the eval before the last row was written: the row, as far as the checkpoint knows
                last100 = {"train/return_last100": float(np.mean(self.recent_returns))} if self.recent_returns else {}
                self._write_row({"iteration": self.iteration, "frames": self.frames, "time_s": self.wall_time(),
                                 "sps": self.frames / max(self.train_time, 1e-9), **last100, **row})
            self.save_checkpoint(eval_return=row.get("eval/return_mean"))
        self.write_summary(status="finished")

    def _set_lr(self) -> float:
        """optim.anneal_lr: linear from the anchor (iteration a, lr_a; at first 0, optim.lr) to 0 at the
        last iteration."""
        cfg = self.cfg.optim
        a, lr_a = self.lr_anchor
        lr = lr_a * (1.0 - (self.iteration - a) / (self.num_iterations - a)) if cfg.anneal_lr else cfg.lr
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        return lr

    def prepare(self, batch: TensorDict) -> dict:
        """Old log-probs, values and advantages for the batch (in place); returns batch statistics."""
        with torch.no_grad():
            # Old log-probs from the same distribution code the loss uses: the first ratio is exactly 1.
            dist = self.ac.actor.get_dist(batch)
            batch.set("action_log_prob", dist.log_prob(batch.get("action")))
            self.advantage(batch)
        stats = {
            "train/entropy": batch_entropy(dist),
            "policy/loc_mean": batch.get("loc").mean().item(),
            "policy/scale_mean": batch.get("scale").mean().item(),
            "train/explained_variance": explained_variance(batch),
            "train/value_mean": batch.get("state_value").mean().item(),
            "train/advantage_std": batch.get("advantage").std().item(),
        }
        return stats

    def update(self, batch: TensorDict) -> dict:
        """Advantages for the batch, then `epochs` passes of shuffled minibatches."""
        cfg = self.cfg
        stats = self.prepare(batch)
        # Only what the losses read (KLPENPPOLoss reads the old loc/scale; value clipping the old
        # state_value): indexing fewer keys per minibatch is the cheapest part of the hot loop to cut.
        flat = batch.reshape(-1).select(*LOSS_INPUT_KEYS, strict=False)
        n = flat.numel()
        mb_size = cfg.loss.minibatch_size or n
        epochs, step = cfg.loss.epochs, self.minibatch_step
        rows, grad_norms = [], []
        for epoch in range(epochs):
            if epoch and cfg.advantage.recompute:  # advantage.recompute: GAE again with the critic as updated so far
                flat = self._recompute_advantage(batch)
            shuffled = flat[torch.randperm(n, device=self.device)]  # one gather per epoch; minibatches are views
            for minibatch in shuffled.split(mb_size):
                metrics, grad_norm = step(minibatch)  # a non-finite loss or gradient: that step is not taken
                rows.append(metrics)
                grad_norms.append(grad_norm)
            if cfg.loss.stop_kl is not None and \
                    self._epoch_kl(rows[len(rows) * epoch // (epoch + 1):], step) > cfg.loss.stop_kl:
                epochs = epoch + 1  # loss.stop_kl: the rest of this batch's epochs are skipped (CleanRL's target_kl)
                break
        # Checked once per update, not per minibatch (a tensor-to-bool sync each): the run stops all the
        # same, and the message names the first minibatch whose step was skipped.
        metrics, grad_norms = torch.stack(rows), torch.stack(grad_norms)
        finite = torch.isfinite(metrics[:, 0] + grad_norms)
        if not finite.all():
            first = int((~finite).nonzero()[0])
            per_epoch = len(rows) // epochs
            quantity = "loss" if not torch.isfinite(metrics[first, 0]) else "gradient"
            self._non_finite(quantity, first // per_epoch, first % per_epoch)
        if not all(torch.isfinite(p).all() for p in self.params):
            self._non_finite("parameter", epochs - 1, None)
        means = metrics.mean(0).tolist()
        stats["loss/total"] = means[0]
        for key, value in zip(step.metric_keys, means[1:]):
            stats[LOSS_METRICS[key]] = value
        stats["train/grad_norm"] = grad_norms.mean().item()
        if cfg.loss.stop_kl is not None:
            stats["train/epochs"] = epochs
        return stats

    def _recompute_advantage(self, batch: TensorDict) -> TensorDict:
        """advantage.recompute: the batch's advantages and value targets from the critic as it is now; the collected
        values stay (value clipping's old values). The loss's view of the batch, made again."""
        with torch.no_grad():
            collected = batch.get("state_value").clone()
            self.advantage(batch)
            batch.set("state_value", collected)
        return batch.reshape(-1).select(*LOSS_INPUT_KEYS, strict=False)

    @staticmethod
    def _epoch_kl(rows: list, step) -> float:
        """The mean approximate KL over one epoch's minibatch rows (one sync per epoch)."""
        at = 1 + [LOSS_METRICS[k] for k in step.metric_keys].index("train/approx_kl")
        return float(torch.stack(rows)[:, at].mean())

    def _non_finite(self, quantity: str, epoch: int, minibatch: Optional[int]) -> None:
        where = f"epoch {epoch + 1}" + (f", minibatch {minibatch + 1}" if minibatch is not None else "")
        kept = f"the last good checkpoint is {ON_DISK.checkpoint}" if ON_DISK.checkpoint else "no checkpoint had been written yet"
        self.write_summary(status="failed")
        raise TrainingError(f"non-finite {quantity} at iteration {self.iteration + 1} (frames {self.frames}, {where}); "
                            f"training stopped and {kept}")

    # ---------------------------------------------------------------- bookkeeping
    def _crossed(self, every: int) -> bool:
        """True on the iteration whose frames cross a multiple of `every`."""
        if every <= 0:
            return False
        step = self.cfg.collector.frames_per_batch
        return self.frames // every > (self.frames - step) // every

    def _episode_stats(self) -> dict:
        finished = self.collector.pop_episodes()
        for ret, _ in finished:
            self.recent_returns.append(ret)
        stats = {"train/episodes": len(finished)}
        if finished:
            stats["train/episode_return"] = float(np.mean([r for r, _ in finished]))
            stats["train/episode_length"] = float(np.mean([n for _, n in finished]))
        if self.recent_returns:
            stats["train/return_last100"] = float(np.mean(self.recent_returns))
        stats.update(self.collector.env_metrics())
        return stats

    def _evaluate(self, episodes: int, background: bool = False) -> dict:
        """The eval's metrics columns; in the background ({} now), the worker gets a copy of what it needs."""
        video = self.run_dir / "videos" / f"eval_{self.frames:010d}.mp4" if self.cfg.eval.video else None
        job = dict(seed=self.cfg.seed + 10_000, deterministic=self.cfg.eval.deterministic, video_path=video,
                   video_episodes=list(self.cfg.eval.video_episodes), video_length=self.cfg.eval.video_length)
        if background:
            actor = {k: v.detach().to("cpu", copy=True) for k, v in self.ac.actor.state_dict().items()}
            keep = copy.deepcopy(self.state_dict()) if self.cfg.checkpoint.save_best else None  # best.pt if it wins
            self.evals.submit(self.frames, dict(actor=actor, obs_stats=copy.deepcopy(self.collector.obs_stats()),
                                                episodes=episodes, **job), keep)
            return {}
        # in line; with a worker (the final eval), it takes a share of the episodes
        evaluate = self.evals.evaluate if self.evals is not None else partial(evaluate_policy, self.cfg)
        result = evaluate(self.ac, self.collector.obs_stats(), episodes, **job)
        return self._eval_done(self.frames, result, None)

    def _eval_done(self, frames: int, result: dict, state_then: Optional[dict]) -> dict:
        """Record an eval of the policy at `frames`; a background one also offers that frame's state as best.pt."""
        self.last_eval = {"frames": frames, **result}
        if state_then is not None:
            state_then["last_eval"] = self.last_eval
            self.ckpt.offer_best(state_then, result["return_mean"])
        row = {"eval/return_mean": result["return_mean"], "eval/return_std": result["return_std"],
               "eval/length_mean": result["length_mean"], **result.get("columns", {})}  # the task's own columns
        return {k: v for k, v in row.items() if v is not None}

    def _log(self, row: dict) -> None:
        if self.evals is not None:  # written once the evals it waits for are back
            self.evals.log(row)
        else:
            self._write_row(row)

    def _write_row(self, row: dict) -> None:
        self.metrics.write(row)
        if self.logger is not None:
            for key, value in row.items():
                if key not in ("iteration", "frames") and value is not None and not (isinstance(value, float) and math.isnan(value)):
                    self.logger.log_scalar(key, value, step=self.frames)
        self.progress.update(row, self.cfg.collector.frames_per_batch, force=row["iteration"] == self.num_iterations)

    def state_dict(self) -> dict:
        return {
            "actor": self.ac.actor.state_dict(),
            "critic": self.ac.critic.state_dict(),
            # the loss's own state (e.g. the KL penalty's beta); the weights are saved once, above
            "loss_module": {k: v for k, v in self.loss_module.state_dict().items()
                            if not k.startswith(("actor_network", "critic_network"))},
            "optimizer": self.optimizer.state_dict(),
            "normalization": self.collector.state_dict(),
            "frames": self.frames,
            "iteration": self.iteration,
            "lr_schedule": list(self.lr_anchor),
            "spec": {"obs_dim": self.spec.obs_dim, "action_dim": self.spec.action_dim},
            "model": self.model,
            "rng": {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()},
            "config": OmegaConf.to_container(self.cfg, resolve=True),
            "last_eval": self.last_eval,
            "best_eval_return": self.ckpt.best_return,
            "recent_returns": list(self.recent_returns),
            "train_time": self.train_time,
            "wall_time": self.wall_time(),
        }

    def wall_time(self) -> float:
        """Seconds since the run started, the time before a resume included."""
        return self.earlier_wall_time + time.perf_counter() - self.start_time

    def save_checkpoint(self, eval_return: Optional[float] = None) -> Path:
        path = self.ckpt.save(self.state_dict(), eval_return)
        ON_DISK.checkpoint, ON_DISK.checkpoint_frames = path, self.frames
        rundir.record(self.run_dir)
        return path

    def write_config(self) -> None:
        rundir.atomic_write_bytes(self.run_dir / "config.yaml",
                                      lambda f: f.write(OmegaConf.to_yaml(self.cfg, resolve=True).encode()))

    def summary(self, status: str) -> dict:
        last_eval = self.last_eval or {}
        return {
            "env": env_label(self.cfg.env),
            "seed": self.cfg.seed,
            "loss": self.cfg.loss.name,
            "policy": self.cfg.policy.head,
            "status": status,
            "frames": self.frames,
            "iterations": self.iteration,
            "wall_s": round(self.wall_time(), 3),
            "train_s": round(self.train_time, 3),
            "sps": round(self.frames / self.train_time, 1) if self.train_time else None,
            "eval_return_mean": last_eval.get("return_mean"),
            "eval_return_std": last_eval.get("return_std"),
            "eval_frames": last_eval.get("frames"),
            **{k: last_eval[k] for k in last_eval.get("task_keys", ()) if k in last_eval},  # the task's figures
            "train_return_last100": float(np.mean(self.recent_returns)) if self.recent_returns else None,
            "best_eval_return": self.ckpt.best_return,
            "run_dir": str(self.run_dir),
        }

    def write_summary(self, status: str) -> None:
        path = self.run_dir / "summary.json"
        new = not path.exists()
        if new:  # listed before it is written (write-ahead): a kill in between leaves a file the manifest calls the app's
            rundir.intend(self.run_dir, [path])
        rundir.atomic_write_json(path, self.summary(status))
        if new:
            rundir.record(self.run_dir)


def train(cfg, run_dir: Path, resume: Optional[dict] = None, next_steps: bool = True, spec: Optional[EnvSpec] = None,
          life: Optional[Lifecycle] = None) -> dict:
    """Train a run to its end; its last lines say what it reached, where its files are and (next_steps) the
    commands to paste next."""
    from ppo_torchrl.run.loggers import quiet_mujoco

    quiet_mujoco()
    trainer = Trainer(cfg, run_dir, resume, spec, life)
    summary = trainer.train()
    print(startup.describe_end(summary, next_steps), file=sys.stderr, flush=True)
    return summary
