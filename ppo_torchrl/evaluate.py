"""Deterministic evaluation on a separate TorchRL env with frozen normalization statistics.

The eval env is `TransformedEnv(GymEnv)` with an `ObservationNorm` holding the training stats (no
updates) and raw rewards, and the actor runs in DETERMINISTIC exploration mode (the mean, squashed
or clipped to the bounds). It shares no state with the training envs.

    python -m ppo_torchrl.evaluate run=<run dir> [checkpoint=best|last|<file>] [episodes=10] [video=false]

prints mean +- std return and length, writes <run dir>/eval/eval.json and, with video=true, an mp4
of the first episode (headless: MUJOCO_GL=egl).
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl.envs import episode_seeds, make_torchrl_env
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.models import ActorCritic

VIDEO_FPS = 30
VIDEO_SIZE = (480, 360)


@torch.no_grad()
def evaluate_policy(cfg, ac: ActorCritic, obs_stats: Optional[dict], episodes: int, seed: int,
                    deterministic: bool = True, video_path: Optional[Path] = None) -> dict:
    """Run `episodes` episodes; with video_path, the first one is also written as an mp4."""
    render = {"render_mode": "rgb_array", "width": VIDEO_SIZE[0], "height": VIDEO_SIZE[1]} if video_path else {}
    env = make_torchrl_env(cfg.env, clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma,
                           obs_stats=obs_stats, train=False, **render)
    # The simulator runs on CPU; a CPU copy of the (small) actor avoids device hops per step.
    actor = ac.actor if ac.action_low.device.type == "cpu" else copy.deepcopy(ac.actor).cpu()
    mode = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    returns, lengths, frames = [], [], []
    try:
        with set_exploration_type(mode):
            for i, episode_seed in enumerate(episode_seeds(seed, episodes)):
                env.set_seed(episode_seed)
                start = env.reset()
                callback = None
                if video_path is not None and i == 0:  # film the first episode, frame after frame
                    gym_env = env.base_env._env
                    frames.append(gym_env.render())
                    callback = lambda *_: frames.append(gym_env.render())  # noqa: E731
                rollout = env.rollout(max_steps=1_000_000, policy=actor, break_when_any_done=True,
                                      auto_reset=False, tensordict=start, callback=callback)
                returns.append(float(rollout.get(("next", "reward")).sum()))
                lengths.append(int(rollout.shape[-1]))
    except Exception as exc:
        if video_path is not None and not frames:
            raise ConfigError(f"rendering is unavailable here ({type(exc).__name__}: {str(exc).splitlines()[0]}); "
                              "set MUJOCO_GL=egl (or osmesa) or run with video=false") from exc
        raise
    finally:
        env.close()
    if video_path is not None:
        write_video(video_path, frames)
    return {
        "return_mean": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "length_mean": float(np.mean(lengths)),
        "length_std": float(np.std(lengths)),
        "returns": returns,
        "lengths": lengths,
    }


def write_video(path: Path, frames: list) -> None:
    import imageio.v2 as imageio

    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(path, frames, fps=VIDEO_FPS, macro_block_size=8)


def main(argv: list[str]) -> dict:
    from ppo_torchrl.checkpoint import atomic_write_json, load_policy
    from ppo_torchrl.cli import parse_args

    usage = "python -m ppo_torchrl.evaluate run=<run dir> [checkpoint=best|last|<file>] [episodes=10] [video=false] [seed=0]"
    args = parse_args(argv, {"run": None, "checkpoint": "best", "episodes": 10, "video": False, "seed": 0}, usage)
    if args["episodes"] < 1:
        raise ConfigError(f"episodes={args['episodes']} must be >= 1")
    run_dir = Path(args["run"])
    cfg, ac, state = load_policy(run_dir, args["checkpoint"])
    video = run_dir / "eval" / f"{args['checkpoint'] if args['checkpoint'] in ('best', 'last') else 'checkpoint'}.mp4"
    result = evaluate_policy(cfg, ac, state["normalization"]["obs"], args["episodes"], seed=args["seed"],
                             video_path=video if args["video"] else None)
    result.update(env=cfg.env.id, checkpoint=args["checkpoint"], checkpoint_frames=state["frames"],
                  episodes=args["episodes"], video=str(video) if args["video"] else None)
    atomic_write_json(run_dir / "eval" / "eval.json", result)
    print(f"{cfg.env.id} @ {state['frames']} frames ({args['checkpoint']}): return {result['return_mean']:.1f} +- "
          f"{result['return_std']:.1f}, length {result['length_mean']:.0f} +- {result['length_std']:.0f} "
          f"over {args['episodes']} episodes" + (f"; video: {video}" if args["video"] else ""))
    return result


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
