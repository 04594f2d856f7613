"""Checkpoints: atomic writes, the last K kept, the best by eval return kept apart.

A checkpoint holds everything a resume or an evaluation needs: actor, critic, optimizer,
normalization statistics, frame and iteration counters, RNG states and the resolved config.
Writes go to a temporary file that is renamed over the target, so a process killed mid-write
leaves the previous checkpoint intact. Reads build data only (safe_pickle): a file that asks for anything else
(a crafted pickle's `os.system`) is refused in one line before any of it runs.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path
from typing import Optional

import torch

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.rundir import CHECKPOINTS, LAST, atomic_write_bytes, moved_aside
from ppo_torchrl.run.safe_pickle import load_torch, refused_name

BEST = "best.pt"


def save(path: Path, state: dict) -> None:
    # Serialized in memory first: torch's zip writer reports a full disk as "unexpected pos ...", a plain
    # write reports it as ENOSPC, which the error path turns into one line.
    buffer = io.BytesIO()
    torch.save(state, buffer)
    atomic_write_bytes(path, lambda f: f.write(buffer.getbuffer()))


def load(path: Path | str) -> dict:
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"checkpoint '{path}' does not exist")
    from ppo_torchrl.envs.state import check_packed  # torchrl's import, only when a checkpoint is read

    try:
        state = load_torch(path)  # tensors, numbers, strings, numpy arrays, plain containers: nothing runs
        check_packed(state)  # the env state inside (env_state.pack's pickled bytes): data only as well
    except Exception as exc:  # a crafted, truncated or foreign file: say so in one line
        asked = refused_name(exc)
        if asked is not None:
            raise ConfigError(f"checkpoint '{path}' is not safe to load: it asks for {asked}, and a ppo_torchrl "
                              "checkpoint holds only tensors, numbers, strings, numpy arrays and plain containers; "
                              "nothing of it was run") from None
        raise ConfigError(f"checkpoint '{path}' is corrupt or not a ppo_torchrl checkpoint ({type(exc).__name__})") from exc
    if not isinstance(state, dict) or "actor" not in state or "frames" not in state:
        raise ConfigError(f"checkpoint '{path}' is not a ppo_torchrl checkpoint (no actor weights or frame count)")
    for key in ("frames", "iteration"):  # a count below 0 (an edited or damaged file) would resume at frame -4,096
        count = state.get(key, 0)
        if isinstance(count, bool) or not hasattr(count, "__index__") or count < 0:
            raise ConfigError(f"checkpoint '{path}' is damaged: its {key} count is {count!r}, not a count >= 0; use "
                              "another checkpoint of the run (checkpoints/frames_<N>.pt, best.pt)")
    return state


class CheckpointManager:
    """<run dir>/checkpoints/{last.pt, best.pt, frames_<N>.pt}; keeps the newest `keep_last`."""

    def __init__(self, directory: Path, keep_last: int, save_best: bool):
        self.dir = Path(directory)
        self.keep_last = keep_last
        self.save_best = save_best
        self.best_return: Optional[float] = None

    def save(self, state: dict, eval_return: Optional[float] = None) -> Path:
        save(self.dir / LAST, state)
        if self.keep_last > 0:
            frames = state["frames"]
            save(self.dir / f"frames_{frames:010d}.pt", state)
            # By frame count: keep the newest keep_last up to now; any beyond now is not this run's past.
            saved = sorted((int(p.stem.split("_")[1]), p) for p in self.dir.glob("frames_*.pt")
                           if p.stem.split("_")[1].isdigit())
            kept = [f for f, _ in saved if f <= frames][-self.keep_last:]
            for old_frames, old in saved:
                if old_frames not in kept:
                    old.unlink()
        self.offer_best(state, eval_return)
        return self.dir / LAST

    def offer_best(self, state: dict, eval_return: Optional[float]) -> None:
        """best.pt, when `eval_return` beats every earlier eval of this run."""
        if self.save_best and eval_return is not None and (self.best_return is None or eval_return > self.best_return):
            self.best_return = eval_return
            state["best_eval_return"] = eval_return
            save(self.dir / BEST, state)


def check_spec(state: dict, spec, env_id: str) -> None:
    """A checkpoint fits an env when its observation and action sizes are the env's."""
    saved = state.get("spec", {})
    if (saved.get("obs_dim"), saved.get("action_dim")) != (spec.obs_dim, spec.action_dim):
        raise ConfigError(
            f"the checkpoint was made for observations of size {saved.get('obs_dim')} and actions of size "
            f"{saved.get('action_dim')}, but {env_id} has {spec.obs_dim} and {spec.action_dim}"
        )


def resolve_checkpoint(run_dir: Path, which: str) -> Path:
    """`best`, `last` or a file path (absolute, or relative to the run's checkpoints dir). `best` of a run
    without one (no eval saved it: zoo/quadruped_climb ships last.pt alone) is `last`, said on stderr;
    a checkpoint that is not there is one line naming the ones that are."""
    run_dir = Path(run_dir)
    found = run_dir / CHECKPOINTS
    if not found.is_dir():  # the sibling an overwrite moved the run to is looked for only then
        aside = moved_aside(run_dir)
        moved = f"; overwrite=true moved the run that was there to {aside}: run={aside}" if aside else ""
        if not run_dir.exists():
            raise ConfigError(f"run={run_dir}: no such dir{moved}")
        raise ConfigError(f"run={run_dir} is not a ppo_torchrl run dir (no checkpoints/){moved}")
    if which in ("best", "last"):
        path = found / f"{which}.pt"
        if which == "best" and not path.exists() and (found / LAST).is_file():
            print(f"note: {run_dir} has no best.pt (no eval saved one): using last.pt", file=sys.stderr, flush=True)
            path = found / LAST
    else:
        path = Path(which)
        path = path if path.is_absolute() or path.exists() else found / which
    if not path.is_file():
        have = sorted(f.name for f in found.glob("*.pt"))
        named = {BEST: "checkpoint=best", LAST: "checkpoint=last"}
        raise ConfigError(f"checkpoint={which}: {path} does not exist; {found} holds "
                          + (", ".join(f"{n} ({named.get(n, f'checkpoint={n}')})" for n in have) if have else
                             "no checkpoint"))
    return path


def label(path: Path) -> str:
    """What a resolved checkpoint is called in results and file names: best, last, or its file's stem."""
    return {BEST: "best", LAST: "last"}.get(Path(path).name, Path(path).stem)


def note_older_best(best: Path, state: dict) -> None:
    """best.pt is the policy of the highest in-training eval return, which on a task whose return is not its goal can
    be an early one (a joystick run's robot standing still at 1M frames of 20M): one stderr line when the run's
    last.pt holds more frames, naming checkpoint=last, so nobody films or exports an early policy unawares."""
    last = best.with_name(LAST)
    try:
        final = load(last).get("frames", 0) if last.is_file() else 0
    except ConfigError:  # a damaged last.pt: best.pt is still what was asked for, and said as it is
        return
    if final > state["frames"]:
        score = state.get("best_eval_return")
        print(f"note: best.pt is the policy at {state['frames']:,} of the run's {final:,} frames (its highest "
              f"in-training eval return{f', {score:.1f}' if score is not None else ''}); checkpoint=last is the final "
              "one", file=sys.stderr, flush=True)


def load_policy(run_dir: Path, which: str = "best"):
    """(config, actor-critic with the checkpoint's weights, checkpoint state) of a finished run."""
    from ppo_torchrl.config import run_config
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.rl.models import make_actor_critic

    path = resolve_checkpoint(run_dir, which)
    state = load(path)
    if path.name == BEST:
        note_older_best(path, state)
    cfg = run_config(run_dir, state, announce=True)  # the checkpoint's config, not a damaged config.yaml's
    spec = env_spec(cfg.env)
    check_spec(state, spec, cfg.env.id)
    ac = make_actor_critic(cfg.policy, spec)
    ac.actor.load_state_dict(state["actor"])
    ac.critic.load_state_dict(state["critic"])
    return cfg, ac, state


def check_same_env(run_dir: Path, cfg, checkpoint: str) -> None:
    """A checkpoint of another env is not filed in this run's dir: one ConfigError line (out=<dir> writes it
    elsewhere). The run's env is its config.yaml's; a run without a readable one is not checked."""
    from ppo_torchrl.config_data import read_config
    from ppo_torchrl.envs.make import env_label

    try:
        own = read_config(Path(run_dir) / "config.yaml").env
        own_label = env_label(own)
    except Exception:  # noqa: BLE001 - no config.yaml, or a damaged one: nothing to compare with
        return
    if own_label != env_label(cfg.env):
        raise ConfigError(f"checkpoint={checkpoint} is a {env_label(cfg.env)} policy and run={run_dir} a {own_label} "
                          f"run: its results would be filed as this run's; evaluate it with run=<its own run dir>, "
                          "or give out=<dir>")
