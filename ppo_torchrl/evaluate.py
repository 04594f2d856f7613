"""Deterministic evaluation on a separate TorchRL env with frozen normalization statistics.

The eval env is `TransformedEnv(GymWrapper)` with an `ObservationNorm` holding the training stats (no
updates) and raw rewards, and the actor runs in DETERMINISTIC exploration mode (the mean, squashed
or clipped to the bounds). It shares no state with the training envs.

    python -m ppo_torchrl.evaluate run=<run dir> [checkpoint=best|last|<file>] [episodes=10] [video=false]

prints mean +- std return and length, writes <run dir>/eval/eval.json and, with video=true, an mp4
of the first episode (headless: MUJOCO_GL=egl).
"""

from __future__ import annotations

import copy
import math
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl.envs import env_label, episode_seeds, make_torchrl_env
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.models import ActorCritic

VIDEO_FPS = 30
VIDEO_SIZE = (480, 360)
QUIET_S = 5.0  # progress=None (training's evals): no line unless the eval is still running after this
EVERY_S = 10.0  # off a terminal, a plain progress line at most this often


class EpisodeProgress:
    """`eval: 3/10 episodes, 12 s elapsed, ETA 28 s` on stderr after an episode: on a terminal an
    updating line, erased when the eval ends; otherwise a plain line at most every EVERY_S seconds."""

    def __init__(self, total: int, progress: Optional[bool], tty: Optional[bool] = None):
        self.total, self.start, self.last, self.shown = total, time.perf_counter(), -math.inf, False
        self.quiet_s = math.inf if progress is False else 0.0 if progress else QUIET_S
        self.tty = sys.stderr.isatty() if tty is None else tty

    def update(self, done: int) -> None:
        now = time.perf_counter()
        elapsed = now - self.start
        if self.tty and done == self.total:
            if self.shown:  # the result line comes next, in its place
                print("\r\x1b[K", end="", file=sys.stderr, flush=True)
            return
        if elapsed < self.quiet_s or (not self.tty and now - self.last < EVERY_S):
            return
        eta = elapsed / done * (self.total - done)
        line = f"eval: {done}/{self.total} episodes, {elapsed:.0f} s elapsed, ETA {eta:.0f} s"
        print("\r" + line if self.tty else line, end="" if self.tty else "\n", file=sys.stderr, flush=True)
        self.last, self.shown = now, True


@torch.no_grad()
def evaluate_policy(cfg, ac: ActorCritic, obs_stats: Optional[dict], episodes: int, seed: int,
                    deterministic: bool = True, video_path: Optional[Path] = None,
                    progress: Optional[bool] = None) -> dict:
    """Run `episodes` episodes; with video_path, the first one is also written as an mp4.

    progress: True reports each episode on stderr (EpisodeProgress), False never, None only once the
    eval has run for QUIET_S seconds (so short evals during training stay silent).
    """
    render = {"render_mode": "rgb_array", "width": VIDEO_SIZE[0], "height": VIDEO_SIZE[1]} if video_path else {}
    env = make_torchrl_env(cfg.env, clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma,
                           obs_stats=obs_stats, train=False, **render)
    # The simulator runs on CPU; a CPU copy of the (small) actor avoids device hops per step.
    actor = ac.actor if ac.action_low.device.type == "cpu" else copy.deepcopy(ac.actor).cpu()
    mode = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    returns, lengths, frames, distances = [], [], [], []
    gym_env = env.base_env._env
    sim = getattr(gym_env.unwrapped, "data", None)  # MuJoCo envs: qpos[0] is the base's x
    try:
        with set_exploration_type(mode):
            shown = EpisodeProgress(episodes, progress)
            for i, episode_seed in enumerate(episode_seeds(seed, episodes)):
                env.set_seed(episode_seed)
                start = env.reset()
                x_start = float(sim.qpos[0]) if sim is not None else None
                callback = None
                if video_path is not None and i == 0:  # film the first episode, frame after frame
                    frames.append(gym_env.render())
                    callback = lambda *_: frames.append(gym_env.render())  # noqa: E731
                rollout = env.rollout(max_steps=1_000_000, policy=actor, break_when_any_done=True,
                                      auto_reset=False, tensordict=start, callback=callback)
                returns.append(float(rollout.get(("next", "reward")).sum()))
                lengths.append(int(rollout.shape[-1]))
                if sim is not None:
                    distances.append((x_start, float(sim.qpos[0])))
                shown.update(i + 1)
    except Exception as exc:
        if video_path is not None and not frames:
            raise ConfigError(f"rendering is unavailable here ({type(exc).__name__}: {str(exc).splitlines()[0]}); "
                              "set MUJOCO_GL=egl (or osmesa) or run with video=false") from exc
        raise
    finally:
        env.close()
    if video_path is not None:
        write_video(video_path, frames)
    result = {
        "return_mean": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "length_mean": float(np.mean(lengths)),
        "length_std": float(np.std(lengths)),
        "returns": returns,
        "lengths": lengths,
    }
    if distances:
        # Forward progress of the base: mean velocity over each episode, and where it ended.
        dt = gym_env.unwrapped.dt
        velocities = [(x1 - x0) / (n * dt) for (x0, x1), n in zip(distances, lengths)]
        result.update(forward_velocity_mean=float(np.mean(velocities)), forward_velocity_std=float(np.std(velocities)),
                      x_final_mean=float(np.mean([x1 for _, x1 in distances])))
        if cfg.eval.get("success_x") is not None:
            result["success_rate"] = float(np.mean([x1 >= cfg.eval.success_x for _, x1 in distances]))
            result["success_x"] = float(cfg.eval.success_x)
    return result


def motion_line(result: dict) -> str:
    """'; forward velocity 0.52 +- 0.04 m/s[, 80% beyond x=2.5 m]' where the env reports motion."""
    if "forward_velocity_mean" not in result:
        return ""
    line = f"; forward velocity {result['forward_velocity_mean']:.2f} +- {result['forward_velocity_std']:.2f} m/s"
    if "success_rate" in result:
        line += f", {result['success_rate']:.0%} of episodes end beyond x={result['success_x']} m"
    return line


def write_video(path: Path, frames: list) -> None:
    import imageio.v2 as imageio

    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(path, frames, fps=VIDEO_FPS, macro_block_size=8)


def main(argv: list[str]) -> dict:
    from ppo_torchrl.checkpoint import atomic_write_json, load_policy
    from ppo_torchrl.cli import parse_args

    usage = "python -m ppo_torchrl.evaluate run=<run dir> [checkpoint=best|last|<file>] [episodes=10] [video=false] [seed=0]"
    help = {
        "run": "the run dir to evaluate (one with config.yaml and checkpoints/)",
        "checkpoint": "best, last, or a checkpoint file",
        "episodes": "number of deterministic episodes",
        "video": "also film the first episode: <run dir>/eval/<checkpoint>.mp4 (MUJOCO_GL=egl)",
        "seed": "episode i starts from seed * 1000 + i: the same seed replays the same episodes",
    }
    about = ("Runs the policy deterministically on a fresh env with the run's frozen normalization stats, prints\n"
             "mean +- std return and length and writes <run dir>/eval/eval.json.")
    args = parse_args(argv, {"run": None, "checkpoint": "best", "episodes": 10, "video": False, "seed": 0}, usage,
                      help, about)
    if args["episodes"] < 1:
        raise ConfigError(f"episodes={args['episodes']} must be >= 1")
    run_dir = Path(args["run"])
    cfg, ac, state = load_policy(run_dir, args["checkpoint"])
    video = run_dir / "eval" / f"{args['checkpoint'] if args['checkpoint'] in ('best', 'last') else 'checkpoint'}.mp4"
    result = evaluate_policy(cfg, ac, state["normalization"]["obs"], args["episodes"], seed=args["seed"],
                             video_path=video if args["video"] else None, progress=True)
    result.update(env=env_label(cfg.env), checkpoint=args["checkpoint"], checkpoint_frames=state["frames"],
                  episodes=args["episodes"], video=str(video) if args["video"] else None)
    atomic_write_json(run_dir / "eval" / "eval.json", result)
    print(f"{env_label(cfg.env)} @ {state['frames']} frames ({args['checkpoint']}): return {result['return_mean']:.1f} +- "
          f"{result['return_std']:.1f}, length {result['length_mean']:.0f} +- {result['length_std']:.0f} "
          f"over {args['episodes']} episodes" + motion_line(result) + (f"; video: {video}" if args["video"] else ""))
    return result


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
