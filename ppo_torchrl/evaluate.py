"""Deterministic evaluation on a separate TorchRL env with frozen normalization statistics.

The eval env is `TransformedEnv(GymWrapper)` with an `ObservationNorm` holding the training stats (no
updates) and raw rewards, and the actor runs in DETERMINISTIC exploration mode (the mean, squashed
or clipped to the bounds). It shares no state with the training envs.

    python -m ppo_torchrl.evaluate run=<run dir> [checkpoint=best|last|<file>] [episodes=10] [video=false]
        [heights=0,0.05,0.1,0.15,0.2 [out=<dir>]] [env.terrain.step_height=0.15 ...]

prints mean +- std return and length (MJCF robots: forward velocity along the heading and gait
figures; step envs: the share of episodes that cross), writes <run dir>/eval/eval.json and, with
video=true, an mp4 of the first episode (headless: MUJOCO_GL=egl). `env.<key>=<value>` changes the
run's env config for this evaluation; `heights=` evaluates at each step height and writes
height_sweep.csv and the success-rate curve height_sweep.png.
"""

from __future__ import annotations

import copy
import math
import sys
import time
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl.envs import env_label, episode_seeds, make_torchrl_env
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.locomotion import LocomotionEnv
from ppo_torchrl.models import ActorCritic, deterministic_policy

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


def evaluate_policy(cfg, ac: ActorCritic, obs_stats: Optional[dict], episodes: int, seed: int,
                    deterministic: bool = True, video_path: Optional[Path] = None,
                    progress: Optional[bool] = None) -> dict:
    """Run `episodes` episodes; with video_path, the first one is also written as an mp4.

    progress: True reports each episode on stderr (EpisodeProgress), False never, None only once the
    eval has run for QUIET_S seconds (so short evals during training stay silent).
    """
    return summarize(cfg, run_episodes(cfg, ac, obs_stats, episode_seeds(seed, episodes), deterministic,
                                       video_path, progress))


def merge_episodes(first: dict, second: dict) -> dict:
    """Two `run_episodes` records of one eval (the episodes split between two processes), in order."""
    return {k: first[k] + second[k] if isinstance(first[k], list) else first[k] for k in first}


@torch.no_grad()
def run_episodes(cfg, ac: ActorCritic, obs_stats: Optional[dict], seeds: Sequence[int], deterministic: bool = True,
                 video_path: Optional[Path] = None, progress: Optional[bool] = None) -> dict:
    """One episode per seed (each starts from `env.set_seed(seed)`, so any subset of an eval's seeds
    gives the same episodes it gives there); the per-episode record that `summarize` reads."""
    episodes = len(seeds)
    render = {"render_mode": "rgb_array", "width": VIDEO_SIZE[0], "height": VIDEO_SIZE[1]} if video_path else {}
    env = make_torchrl_env(cfg.env, clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma,
                           obs_stats=obs_stats, train=False, **render)
    # The simulator runs on CPU; a CPU copy of the (small) actor avoids device hops per step.
    if ac.action_low.device.type != "cpu":
        ac = copy.deepcopy(ac)
        ac.actor.cpu()
        ac.action_low, ac.action_high = ac.action_low.cpu(), ac.action_high.cpu()
    actor = deterministic_policy(ac) if deterministic else ac.actor
    mode = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    returns, lengths, frames, distances, gaits, crossed, heights = [], [], [], [], [], [], []
    gym_env = env.base_env._env
    sim = getattr(gym_env.unwrapped, "data", None)  # MuJoCo envs: qpos[0:2] is the base's x, y
    loco = gym_env.unwrapped if isinstance(gym_env.unwrapped, LocomotionEnv) else None
    heading = loco.heading if loco is not None else np.array([1.0, 0.0])  # forward: +x unless the env says
    if loco is not None:
        loco.measure_gait = True
    try:
        with set_exploration_type(mode):
            shown = EpisodeProgress(episodes, progress)
            for i, episode_seed in enumerate(seeds):
                env.set_seed(episode_seed)
                start = env.reset()
                xy_start = sim.qpos[:2].copy() if sim is not None else None
                callback = None
                if video_path is not None and i == 0:  # film the first episode, frame after frame
                    frames.append(gym_env.render())
                    callback = lambda *_: frames.append(gym_env.render())  # noqa: E731
                rollout = env.rollout(max_steps=1_000_000, policy=actor, break_when_any_done=True,
                                      auto_reset=False, tensordict=start, callback=callback)
                returns.append(float(rollout.get(("next", "reward")).sum()))
                lengths.append(int(rollout.shape[-1]))
                if sim is not None:
                    moved = sim.qpos[:2] - xy_start
                    distances.append((float(moved @ heading[:len(moved)]), float(sim.qpos[0])))
                if loco is not None:
                    gaits.append(loco.gait_summary())
                    if loco.has_step:
                        crossed.append(loco.crossed())
                        heights.append(loco.step_height)
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
    return {"returns": returns, "lengths": lengths, "distances": distances, "gaits": gaits, "crossed": crossed,
            "heights": heights, "dt": gym_env.unwrapped.dt if sim is not None else None,
            "success_margin": loco.success_margin if crossed else None}


def summarize(cfg, episodes: dict) -> dict:
    """The eval's figures from `run_episodes`' record."""
    returns, lengths, distances = episodes["returns"], episodes["lengths"], episodes["distances"]
    crossed, gaits = episodes["crossed"], episodes["gaits"]
    result = {
        "return_mean": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "length_mean": float(np.mean(lengths)),
        "length_std": float(np.std(lengths)),
        "returns": returns,
        "lengths": lengths,
    }
    if distances:
        # Forward progress of the base along its heading: mean velocity over each episode, and where it ended.
        dt = episodes["dt"]
        velocities = [d / (n * dt) for (d, _), n in zip(distances, lengths)]
        result.update(forward_velocity_mean=float(np.mean(velocities)), forward_velocity_std=float(np.std(velocities)),
                      x_final_mean=float(np.mean([x1 for _, x1 in distances])))
        if crossed:  # a step env: the env's criterion, the trunk success_margin beyond the step's edge
            result.update(success_rate=float(np.mean(crossed)), success_margin=episodes["success_margin"],
                          step_height_mean=float(np.mean(episodes["heights"])))
        elif cfg.eval.get("success_x") is not None:
            result["success_rate"] = float(np.mean([x1 >= cfg.eval.success_x for _, x1 in distances]))
            result["success_x"] = float(cfg.eval.success_x)
    if gaits:
        result.update(gait_figures(gaits, cfg.env.locomotion.get("joint_speed_limit")))
    return result


# What an eval of a locomotion env adds: gait_figures' keys (also in summary.json and the height sweep)
GAIT_KEYS = ("stride_frequency", "duty_factor", "peak_joint_speed", "over_speed_limit_share", "body_contact_share")


def gait_figures(gaits: list, speed_limit: Optional[float]) -> dict:
    """Per-episode gait figures (locomotion.GaitMeter) over the eval: means, the peak joint speed's max and,
    with a speed limit, the share of all the eval's physics steps in which a joint was over it."""
    figures = {key: float(np.mean([g[key] for g in gaits]))
               for key in ("stride_frequency", "duty_factor", "body_contact_share")}
    figures["peak_joint_speed"] = float(max(g["peak_joint_speed"] for g in gaits))
    if speed_limit is not None:
        figures["joint_speed_limit"] = float(speed_limit)
        over = sum(g["over_speed_limit_time_s"] for g in gaits)
        figures["over_speed_limit_share"] = float(over / max(sum(g["time_s"] for g in gaits), 1e-9))
    return figures


def motion_line(result: dict) -> str:
    """'; forward velocity 0.52 +- 0.04 m/s[, 80% beyond x=2.5 m]' where the env reports motion."""
    if "forward_velocity_mean" not in result:
        return ""
    line = f"; forward velocity {result['forward_velocity_mean']:.2f} +- {result['forward_velocity_std']:.2f} m/s"
    if "success_margin" in result:
        line += (f", {result['success_rate']:.0%} of episodes end {result['success_margin']} m beyond the step "
                 f"({result['step_height_mean'] * 100:.0f} cm on average)")
    elif "success_rate" in result:
        line += f", {result['success_rate']:.0%} of episodes end beyond x={result['success_x']} m"
    if "stride_frequency" in result:
        limit = (f" (limit {result['joint_speed_limit']:g}, passed {result['over_speed_limit_share']:.2%} of the time)"
                 if "joint_speed_limit" in result else "")
        line += (f"; gait: stride frequency {result['stride_frequency']:.1f} Hz, duty factor "
                 f"{result['duty_factor']:.2f}, peak joint speed {result['peak_joint_speed']:.1f} rad/s{limit}, "
                 f"a non-foot body on the ground {result['body_contact_share']:.0%} of the time")
    return line


def write_video(path: Path, frames: list) -> None:
    import imageio.v2 as imageio

    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(path, frames, fps=VIDEO_FPS, macro_block_size=8)


SWEEP_FILES = ("height_sweep.csv", "height_sweep.png")


def apply_overrides(cfg, overrides: list[str]):
    """`env.<key>=<value>` arguments on the run's saved config, typed and checked as training checks them."""
    from omegaconf import OmegaConf

    from ppo_torchrl.locomotion import locomotion_checks, terrain_checks

    for override in overrides:
        try:
            cfg = OmegaConf.merge(cfg, OmegaConf.from_dotlist([override]))
        except Exception as exc:  # omegaconf: an unknown key or a value of the wrong type
            raise ConfigError(f"cannot apply '{override}' to the run's config: {str(exc).splitlines()[0]}") from None
    for ok, message in locomotion_checks(cfg.env.locomotion) + terrain_checks(cfg.env.terrain):
        if not ok:
            raise ConfigError(message)
    return cfg


def parse_heights(text: str) -> list[float]:
    try:
        heights = [float(h) for h in text.split(",") if h.strip()]
    except ValueError:
        raise ConfigError(f"heights={text}: expected step heights in m separated by commas, e.g. 0,0.05,0.1,0.15,0.2") from None
    if not heights or any(not (h >= 0 and math.isfinite(h)) for h in heights):
        raise ConfigError(f"heights={text}: expected step heights >= 0 (m) separated by commas, e.g. 0,0.05,0.1,0.15,0.2")
    return heights


def height_sweep(cfg, ac, obs_stats, heights: list[float], episodes: int, seed: int, out_dir: Path, title: str) -> list:
    """Evaluate at each fixed step height; write height_sweep.csv and the success-rate curve height_sweep.png."""
    import csv

    rows = []
    for height in heights:
        cfg.env.terrain.step_height = height
        result = evaluate_policy(cfg, ac, obs_stats, episodes, seed=seed, progress=True)
        if "success_margin" not in result:
            raise ConfigError("heights= needs a step env (a model with a body named 'step'); to put a flat-ground run "
                              "on the step add env.xml_file=quadruped_step.xml")
        row = {"step_height_m": height, "episodes": episodes, "success_rate": result["success_rate"],
               "forward_velocity_mean": result["forward_velocity_mean"], "return_mean": result["return_mean"],
               **{k: result.get(k) for k in GAIT_KEYS}}
        rows.append(row)
        print(f"step {height * 100:g} cm: {row['success_rate']:.0%} of {episodes} episodes cross; forward velocity "
              f"{row['forward_velocity_mean']:.2f} m/s", flush=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / SWEEP_FILES[0], "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    ax.plot([r["step_height_m"] * 100 for r in rows], [r["success_rate"] * 100 for r in rows], "o-")
    ax.set(xlabel="step height (cm)", ylabel=f"episodes that cross (%, of {episodes})", ylim=(-3, 103))
    ax.set_title(title, fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / SWEEP_FILES[1], dpi=120)
    plt.close(fig)
    return rows


def main(argv: list[str]) -> dict:
    from ppo_torchrl.checkpoint import check_spec, load_policy
    from ppo_torchrl.cli import parse_args
    from ppo_torchrl.envs import env_spec
    from ppo_torchrl.rundir import atomic_write_json, is_run, record, unwritable

    usage = ("python -m ppo_torchrl.evaluate run=<run dir> [checkpoint=best|last|<file>] [episodes=10] [video=false] "
             "[seed=0] [heights=<m,m,...> [out=<dir>]] [env.<key>=<value> ...]")
    help = {
        "run": "the run dir to evaluate (one with config.yaml and checkpoints/)",
        "checkpoint": "best, last, or a checkpoint file",
        "episodes": "number of deterministic episodes (per height with heights=)",
        "video": "also film the first episode: <run dir>/eval/<checkpoint>.mp4 (MUJOCO_GL=egl)",
        "seed": "episode i starts from seed * 1000 + i: the same seed replays the same episodes",
        "heights": "step heights in m, e.g. 0,0.05,0.1,0.15,0.2: evaluate at each; writes height_sweep.csv and the "
                   "success-rate curve height_sweep.png",
        "out": "where the eval writes its files: eval.json, the video, a height sweep's (empty: <run dir>/eval)",
    }
    about = ("Runs the policy deterministically on a fresh env with the run's frozen normalization stats, prints\n"
             "mean +- std return and length (MJCF robots: forward velocity, gait figures; step envs: the share of\n"
             "episodes that cross) and writes <run dir>/eval/eval.json.\n"
             "env.<key>=<value> changes the run's env config for this evaluation, e.g. env.terrain.step_height=0.1\n"
             "(a step height in m) or env.xml_file=quadruped_step.xml (a flat-ground run on the step).")
    overrides = [arg for arg in argv if arg.startswith("env.")]
    args = parse_args([arg for arg in argv if not arg.startswith("env.")],
                      {"run": None, "checkpoint": "best", "episodes": 10, "video": False, "seed": 0, "heights": "",
                       "out": ""}, usage, help, about)
    if args["episodes"] < 1:
        raise ConfigError(f"episodes={args['episodes']} must be >= 1")
    heights = parse_heights(args["heights"]) if args["heights"] else None
    if heights and args["video"]:
        raise ConfigError("video=true films one evaluation; leave it out of a heights= sweep")
    run_dir = Path(args["run"])
    out_dir = Path(args["out"]) if args["out"] else run_dir / "eval"
    why = unwritable(out_dir)  # before any episode runs
    if why:
        raise ConfigError(f"cannot write the eval's files in {out_dir}: {why}; give a writable dir with out=<dir>")
    cfg, ac, state = load_policy(run_dir, args["checkpoint"])
    if overrides:
        cfg = apply_overrides(cfg, overrides)
        check_spec(state, env_spec(cfg.env), cfg.env.id)
    obs_stats = state["normalization"]["obs"]
    label = f"{env_label(cfg.env)} @ {state['frames']} frames ({args['checkpoint']})"
    if heights:
        rows = height_sweep(cfg, ac, obs_stats, heights, args["episodes"], args["seed"], out_dir,
                            f"{run_dir.resolve().name}\n{label}")
        print(f"{label}: height sweep over {args['episodes']} episodes per height: "
              f"{out_dir / SWEEP_FILES[0]}, {out_dir / SWEEP_FILES[1]}")
        if is_run(run_dir):
            record(run_dir)
        return {"heights": rows}
    video = out_dir / f"{args['checkpoint'] if args['checkpoint'] in ('best', 'last') else 'checkpoint'}.mp4"
    result = evaluate_policy(cfg, ac, obs_stats, args["episodes"], seed=args["seed"],
                             video_path=video if args["video"] else None, progress=True)
    result.update(env=env_label(cfg.env), checkpoint=args["checkpoint"], checkpoint_frames=state["frames"],
                  episodes=args["episodes"], video=str(video) if args["video"] else None, overrides=overrides)
    atomic_write_json(out_dir / "eval.json", result)
    if is_run(run_dir):
        record(run_dir)
    print(f"{label}: return {result['return_mean']:.1f} +- "
          f"{result['return_std']:.1f}, length {result['length_mean']:.0f} +- {result['length_std']:.0f} "
          f"over {args['episodes']} episodes" + motion_line(result) + (f"; video: {video}" if args["video"] else ""))
    return result


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
