"""Deterministic evaluation on a separate TorchRL env with frozen normalization statistics.

The eval env is the training pipeline's `TransformedEnv(GymWrapper)` with the normalization frozen at the
training stats (no updates) and raw rewards, and the actor runs in DETERMINISTIC exploration mode (the mean, squashed
or clipped to the bounds). It shares no state with the training envs.

    python -m ppo_torchrl.evaluate run=<run dir> [checkpoint=best|last|<file>] [episodes=10] [video=false]
        [heights=0,0.05,0.1,0.15,0.2 [out=<dir>]] [env.terrain.step_height=0.15 ...]

prints mean +- std return and length (MJCF robots: forward velocity along the heading and gait
figures, each foot's too; step envs: the share of episodes that cross and are not terminated, beside
the share beyond the line at the end), writes <run dir>/eval/eval.json (with a record per episode) and, with
video=true, an mp4 of the first episode (or those of video_episodes=, up to video_length= seconds)
from a camera that follows the robot, at real-time speed (headless: MUJOCO_GL=egl). `env.<key>=<value>` changes the
run's env config for this evaluation; `heights=` evaluates at each step height and writes
height_sweep.csv, the success-rate curve height_sweep.png, height_sweep_episodes.csv and height_sweep.json.
"""

from __future__ import annotations

import copy
import functools
import math
import sys
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl.envs.make import batched, env_checks, env_label, episode_seeds, make_batch, make_torchrl_env
from ppo_torchrl.envs.filming import VIDEO_SIZE, EpisodeProgress, Filming, video_line
from ppo_torchrl.envs.state import env_state_of
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.locks import read, releasing
from ppo_torchrl.tasks import figures_kind, figures_module
from ppo_torchrl.rl.models import ActorCritic, deterministic_policy

def evaluate_policy(cfg, ac: ActorCritic, obs_stats: Optional[dict], episodes: int, seed: int,
                    deterministic: bool = True, video_path: Optional[Path] = None,
                    progress: Optional[bool] = None, video_episodes: Sequence[int] = (0,),
                    video_length: Optional[float] = None) -> dict:
    """Run `episodes` episodes; with video_path, episodes `video_episodes` (the first by default) are
    also written as one mp4 (Filming), at most `video_length` seconds; result["video"] says what it holds.

    progress: True reports each episode on stderr (EpisodeProgress), False never, None only once the
    eval has run for QUIET_S seconds (so short evals during training stay silent).
    """
    record = run_episodes(cfg, ac, obs_stats, episode_seeds(seed, episodes), deterministic, video_path, progress,
                          video_episodes, video_length)
    result = summarize(cfg, record)
    if record.get("video"):
        result["video"] = record["video"]
    return result


def merge_episodes(first: dict, second: dict) -> dict:
    """Two `run_episodes` records of one eval (the episodes split between two processes), in order."""
    return {k: first[k] + second[k] if isinstance(first[k], list) else first[k] for k in first}


@torch.no_grad()
def run_episodes(cfg, ac: ActorCritic, obs_stats: Optional[dict], seeds: Sequence[int], deterministic: bool = True,
                 video_path: Optional[Path] = None, progress: Optional[bool] = None,
                 video_episodes: Sequence[int] = (0,), video_length: Optional[float] = None,
                 elsewhere: int = 0) -> dict:
    """One episode per seed (each starts from `env.set_seed(seed)`, so any subset of an eval's seeds
    gives the same episodes it gives there); the per-episode record that `summarize` reads. With
    video_path, episodes video_episodes (indices into seeds) are filmed: Filming."""
    if batched(cfg.env):  # a legged task: its episodes side by side in one batch (tasks/locomotion/evaluation.py)
        from ppo_torchrl.tasks.locomotion.evaluation import task_episodes

        return task_episodes(make_batch, cfg, ac, obs_stats, seeds, deterministic, video_path, progress, video_episodes,
                             video_length, elsewhere)
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
    returns, lengths, distances = [], [], []
    terminated = []  # per episode: ended by the env (not its time limit)
    metrics = []  # per episode, where the env keeps them (episode_metrics(): a Playground task's reward terms)
    gym_env = env_state_of(env).gym_envs[0]
    film = (Filming(video_path, gym_env, [e for e in video_episodes if 0 <= e < episodes], video_length)
            if video_path is not None else None)
    video = None
    sim = getattr(gym_env.unwrapped, "data", None)  # MuJoCo envs: qpos[0:2] is the base's x, y (forward: +x)
    try:
        with set_exploration_type(mode):
            shown = EpisodeProgress(episodes, progress, elsewhere=elsewhere)
            for i, episode_seed in enumerate(seeds):
                env.set_seed(episode_seed)
                start = env.reset()
                xy_start = sim.qpos[:2].copy() if sim is not None else None
                callback = film.start(i) if film is not None else None
                if callback is not None:
                    film.on_frame = functools.partial(shown.filming, i, film, lengths)
                rollout = env.rollout(max_steps=1_000_000, policy=actor, break_when_any_done=True,
                                      auto_reset=False, tensordict=start, callback=callback)
                returns.append(float(rollout.get(("next", "reward")).sum()))
                lengths.append(int(rollout.shape[-1]))
                terminated.append(bool(rollout.get(("next", "terminated"))[-1].any()))
                if hasattr(gym_env.unwrapped, "episode_metrics"):
                    metrics.append(gym_env.unwrapped.episode_metrics())
                if sim is not None:
                    moved = sim.qpos[:2] - xy_start
                    distances.append((float(moved[0]), float(sim.qpos[0])))
                if film is not None:
                    shown.update(i + 1, film.spent_s, film.left_s(i + 1, lengths))
                else:
                    shown.update(i + 1)
    finally:
        env.close()
        if film is not None:
            video = film.close()
    return {"returns": returns, "lengths": lengths, "distances": distances, "gaits": [], "crossed": [],
            "heights": [], "dt": gym_env.unwrapped.dt if sim is not None else None, "success_margin": None,
            "video": video, "terminated": terminated, "ends": [None] * len(seeds), "seeds": list(seeds), "feet": None,
            "metrics": metrics,  # a MuJoCo base's forward velocity; a Playground task's reward terms
            "figures": figures_kind(cfg.env, sim is not None)}


def summarize(cfg, episodes: dict) -> dict:
    """The eval's figures from `run_episodes`' record: returns, lengths, how episodes ended, one outcome per episode;
    then those of the record's kind (episodes["figures"]: a locomotion task's, tasks/locomotion/figures.py)."""
    returns, lengths, terminated = episodes["returns"], episodes["lengths"], episodes["terminated"]
    result = {
        "return_mean": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "length_mean": float(np.mean(lengths)),
        "length_std": float(np.std(lengths)),
        "returns": returns,
        "lengths": lengths,
    }
    # why episodes ended early: the env's reason (a task's), else 'terminated' (the env said only that)
    ends = [(why or "terminated") if stop else None for stop, why in zip(terminated, episodes["ends"])]
    result["terminated_share"] = float(np.mean(terminated))
    result["termination_shares"] = {why: ends.count(why) / len(ends) for why in sorted(set(ends) - {None})}
    result["outcomes"] = [{"seed": seed, "length": n, "return": r, "terminated": stop, "termination": why}
                          for seed, n, r, stop, why in zip(episodes["seeds"], lengths, returns, terminated, ends)]
    kind = figures_module(episodes.get("figures"))
    if kind is not None:
        result["figures"] = episodes["figures"]
        kind.figures(cfg, episodes, result)
    return result


def result_lines(result: dict) -> str:
    """What the eval's kind prints after return and length (each line starting '\n  '); '' for none."""
    kind = figures_module(result.get("figures"))
    return kind.motion_line(result) if kind is not None else ""


def parse_video_choices(episodes_text: str, length_text: str, episodes: int) -> tuple:
    """video_episodes= and video_length= as ([episode numbers], seconds or None)."""
    try:
        which = sorted({int(e) for e in episodes_text.split(",") if e.strip()})
    except ValueError:
        which = []
    if not which or which[0] < 0 or which[-1] >= episodes:
        raise ConfigError(f"video_episodes={episodes_text}: expected episode numbers in 0..{episodes - 1} (episodes="
                          f"{episodes}) separated by commas, e.g. 0 or 0,3")
    if not length_text:
        return which, None
    try:
        length = float(length_text)
    except ValueError:
        length = math.nan
    if not (length > 0 and math.isfinite(length)):
        raise ConfigError(f"video_length={length_text}: expected the video's length in seconds > 0, e.g. 10 "
                          "(simulated seconds: videos play in real time)")
    return which, length


def apply_overrides(cfg, overrides: list[str]):
    """`env.<key>=<value>` arguments on the run's saved config, typed and checked as training checks them."""
    from omegaconf import OmegaConf

    for override in overrides:
        try:
            cfg = OmegaConf.merge(cfg, OmegaConf.from_dotlist([override]))
        except Exception as exc:  # omegaconf: an unknown key or a value of the wrong type
            from ppo_torchrl.overrides import key_hint  # a misspelt key: the closest one

            raise ConfigError(f"cannot apply '{override}' to the run's config: {str(exc).splitlines()[0]}"
                              f"{key_hint(override.partition('=')[0], cfg)}") from None
    from ppo_torchrl.envs.values import check_env

    check_env(cfg.env)  # as training checks it: finite, in range, named as typed (env_values.py)
    return cfg


TRACKING_FILES = ("tracking.json", "tracking.md", "tracking.png")


def tracking_eval(cfg, ac, obs_stats, args: dict, out_dir: Path, run_dir: Path, label: str) -> dict:
    """tracking=true (tasks/joystick.py): the fixed command set, in the nominal world and, with extremes=true, at
    each corner of the run's randomization; tracking.json, tracking.md, tracking.png."""
    from ppo_torchrl.run.rundir import atomic_write_bytes, atomic_write_json, record
    from ppo_torchrl.tasks import joystick

    results = {}
    for name, draw in joystick.worlds(cfg.env, args["extremes"]):
        results[name] = joystick.track(cfg, ac, obs_stats, args["episodes"], args["seed"], draw)
        o = results[name]["overall"]
        print(f"{label}, {name}: v_xy error {o['v_xy_error']:.3f} sqrt(g l), yaw rate error {o['yaw_rate_error']:.3f} "
              f"sqrt(g / l), falls {o['falls']:.0%} of {o['episodes']} episodes", flush=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    text = "".join(f"## {name}\n\n{joystick.table(r)}\n" for name, r in results.items())
    atomic_write_json(out_dir / TRACKING_FILES[0], {"title": label, "seed": args["seed"], "worlds": results},
                      owner=run_dir)
    atomic_write_bytes(out_dir / TRACKING_FILES[1], lambda f: f.write(f"# {label}\n\n{text}".encode()), run_dir)
    joystick.plot(results["nominal"], out_dir / TRACKING_FILES[2], label, run_dir)
    record(run_dir, [out_dir / n for n in TRACKING_FILES])
    print(joystick.table(results["nominal"]) + f"tracking: {out_dir / TRACKING_FILES[0]}, {out_dir / TRACKING_FILES[2]}")
    return {"tracking": {name: r["overall"] for name, r in results.items()}}


def drive_eval(cfg, ac, obs_stats, driving, seed: int, out_dir: Path, run_dir: Path, label: str) -> dict:
    """drive= (tasks/joystick.py): one episode filmed through the command script, drive.mp4, and each
    segment's command against the velocity measured over it."""
    from ppo_torchrl.run.rundir import record
    from ppo_torchrl.tasks.joystick import drive

    segments = drive(make_batch, cfg, ac, obs_stats, driving, out_dir / "drive.mp4", episode_seeds(seed, 1)[0],
                     owner=run_dir)
    record(run_dir, [out_dir / "drive.mp4"])
    for segment in segments:
        print(f"{segment['segment']}: command {segment['command']}, measured "
              f"{[round(x, 3) for x in segment['measured']]}" + (" (fell)" if segment["fell"] else ""))
    print(f"{label}: {out_dir / 'drive.mp4'}")
    return {"drive": segments}


def heights_eval(cfg, ac, obs_stats, heights, args: dict, out_dir: Path, run_dir: Path, label: str, writes) -> dict:
    """heights= (tasks/locomotion/sweep.py): the step task's episodes at each step height; its sweep files."""
    from ppo_torchrl.run.rundir import record
    from ppo_torchrl.tasks.locomotion import sweep

    heights = sweep.heights_in_metres(heights, cfg.env, args["heights"])  # a unit note on stderr where due
    rows = sweep.height_sweep(cfg, ac, obs_stats, heights, args["episodes"], args["seed"], out_dir,
                              f"{run_dir.resolve().name}\n{label}", owner=run_dir, evaluate=evaluate_policy)
    print(f"{label}: height sweep over {args['episodes']} episodes per height: "
          f"{out_dir / sweep.SWEEP_FILES[0]}, {out_dir / sweep.SWEEP_FILES[1]}")
    record(run_dir, writes)  # in the run dir that holds them, however out= spells it
    return {"heights": rows}


@releasing  # the shared locks it takes (locks.read) go when it ends
def main(argv: list[str]) -> dict:
    from ppo_torchrl.run.checkpoint import check_same_env, check_spec, load_policy, resolve_checkpoint
    from ppo_torchrl.run.checkpoint import label as checkpoint_label
    from ppo_torchrl.cli import check_episodes, parse_args, resolve_run
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.run.model_record import check_model
    from ppo_torchrl.run.ownership import holder
    from ppo_torchrl.run.rundir import atomic_write_json, check_replaceable, intend, output_dir_for, record, unwritable
    from ppo_torchrl.usage import EVALUATE

    usage, spec, help, about = EVALUATE  # usage.py: --help answers before torch is imported
    overrides = [arg for arg in argv if arg.startswith("env.")]
    args = parse_args([arg for arg in argv if not arg.startswith("env.")], spec, usage, help, about)
    check_episodes(args["episodes"], args["seed"])  # the one check evaluate_run() runs too (cli.py)
    from ppo_torchrl.tasks.locomotion import sweep  # heights=: the step task's own sweep

    heights = sweep.parse_heights(args["heights"]) if args["heights"] else None
    if any(arg.startswith(("video_episodes=", "video_length=")) for arg in argv):
        args["video"] = True
    video_episodes, video_length = parse_video_choices(args["video_episodes"], args["video_length"], args["episodes"])
    driving = None
    if args["drive"]:
        from ppo_torchrl.tasks.joystick import parse_drive

        driving = parse_drive(args["drive"])
        if args["tracking"] or heights or args["video"]:
            raise ConfigError("drive= films its own episode: leave out tracking=, heights= and video=")
    if args["extremes"] and not args["tracking"]:
        raise ConfigError("extremes=true goes with tracking=true (a joystick run's tracking at its randomization's ends)")
    if args["tracking"] and (heights or args["video"]):
        raise ConfigError("tracking=true is an evaluation of its own: leave out heights= and video=")
    if heights and args["video"]:
        raise ConfigError("video=true films one evaluation, not a heights= sweep: film each height with a command of "
                          "its own, env.terrain.step_height=<m> video=true (e.g. env.terrain.step_height=0.1 video=true)")
    run_dir = resolve_run(args["run"])  # run=latest[/<env>]: the newest run dir under outputs/
    read(run_dir)  # a shared lock: no overwrite or run starts there while this reads it (locks.py)
    checkpoint = resolve_checkpoint(run_dir, args["checkpoint"])  # best without a best.pt: last.pt, said so
    which = checkpoint_label(checkpoint)
    out_dir = Path(args["out"]) if args["out"] else output_dir_for(run_dir, run_dir / "eval")  # zoo: outputs/zoo/<name>
    if not args["out"] and out_dir != run_dir / "eval":  # a shipped run (zoo/, results/) stays as it was shipped
        print(f"note: {run_dir} is a shipped run; the eval's files go to {out_dir} (out=<dir> for another)",
              file=sys.stderr, flush=True)
    why = unwritable(out_dir)  # before any episode runs
    if why:
        raise ConfigError(f"cannot write the eval's files in {out_dir}: {why}; give a writable dir with out=<dir>")
    video = out_dir / f"{which}.mp4"
    writes = [out_dir / "drive.mp4"] if driving else [out_dir / name for name in TRACKING_FILES] if args["tracking"] else \
        [out_dir / name for name in sweep.SWEEP_FILES] if heights else [out_dir / "eval.json"] + [video] * args["video"]
    check_replaceable(run_dir, writes)  # a file there that the app did not write is left alone: one line
    read(holder(out_dir))  # out= in another run dir: that one is read (and written) too
    cfg, ac, state = load_policy(run_dir, str(checkpoint))
    filed_in = holder(writes[0]) or (None if args["out"] else run_dir)  # the run whose dir gets the results
    if filed_in is not None:
        check_same_env(filed_in, cfg, args["checkpoint"])
    if not any(o.startswith("env.xml_file=") for o in overrides):  # another model on purpose: not compared
        check_model(state, cfg.env, f"run={run_dir}")  # the robot model it trained on, unchanged
    if overrides:
        cfg = apply_overrides(cfg, overrides)
        check_spec(state, env_spec(cfg.env), cfg.env.id)
    obs_stats = state["normalization"]["obs"]
    label = f"{env_label(cfg.env)} @ {state['frames']} frames ({which})"
    if args["tracking"] or args["drive"]:  # before any env is built
        from ppo_torchrl.tasks import joystick

        joystick.check(cfg.env, args["tracking"], bool(args["drive"]), args["extremes"], run_dir)
    if args["tracking"]:
        return tracking_eval(cfg, ac, obs_stats, args, out_dir, run_dir, label)
    if args["drive"]:
        return drive_eval(cfg, ac, obs_stats, driving, args["seed"], out_dir, run_dir, label)
    if heights:
        return heights_eval(cfg, ac, obs_stats, heights, args, out_dir, run_dir, label, writes)
    if args["video"]:
        intend(run_dir, [video])  # imageio writes the mp4 in place: listed first, a cut one is the app's
    result = evaluate_policy(cfg, ac, obs_stats, args["episodes"], seed=args["seed"],
                             video_path=video if args["video"] else None, progress=True,
                             video_episodes=video_episodes, video_length=video_length)
    result.update(env=env_label(cfg.env), checkpoint=which, checkpoint_frames=state["frames"],
                  episodes=args["episodes"], video=result.get("video"), overrides=overrides)
    atomic_write_json(out_dir / "eval.json", result, owner=run_dir)
    record(run_dir, writes)
    print(f"{label}: return {result['return_mean']:.1f} +- "
          f"{result['return_std']:.1f}, length {result['length_mean']:.0f} +- {result['length_std']:.0f} "
          f"over {args['episodes']} episodes" + result_lines(result) + ("\n  " + video_line(result["video"])
                                                                       if result["video"] else ""))
    return result


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
