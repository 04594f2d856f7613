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
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl.envs import batched, env_checks, env_label, episode_seeds, make_torchrl_env
from ppo_torchrl.filming import VIDEO_SIZE, EpisodeProgress, Filming, video_line
from ppo_torchrl.env_state import env_state_of
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.locks import read, releasing
from ppo_torchrl.robots.env import LocomotionEnv
from ppo_torchrl.robots.gait import FOOT_PAIRS
from ppo_torchrl.models import ActorCritic, deterministic_policy

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

        return task_episodes(cfg, ac, obs_stats, seeds, deterministic, video_path, progress, video_episodes,
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
    returns, lengths, distances, gaits, crossed, heights = [], [], [], [], [], []
    terminated, ends = [], []  # per episode: ended by the env (not its time limit), and why (locomotion envs)
    gym_env = env_state_of(env).gym_envs[0]
    film = (Filming(video_path, gym_env, [e for e in video_episodes if 0 <= e < episodes], video_length)
            if video_path is not None else None)
    video = None
    sim = getattr(gym_env.unwrapped, "data", None)  # MuJoCo envs: qpos[0:2] is the base's x, y
    loco = gym_env.unwrapped if isinstance(gym_env.unwrapped, LocomotionEnv) else None
    heading = loco.heading if loco is not None else np.array([1.0, 0.0])  # forward: +x unless the env says
    if loco is not None:
        loco.measure_gait = True
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
                ends.append(loco.termination if loco is not None else None)
                if sim is not None:
                    moved = sim.qpos[:2] - xy_start
                    distances.append((float(moved @ heading[:len(moved)]), float(sim.qpos[0])))
                if loco is not None:
                    gaits.append(loco.gait_summary())
                    if loco.has_step:
                        crossed.append(loco.crossed())
                        heights.append(loco.step_height)
                if film is not None:
                    shown.update(i + 1, film.spent_s, film.left_s(i + 1, lengths))
                else:
                    shown.update(i + 1)
    finally:
        env.close()
        if film is not None:
            video = film.close()
    return {"returns": returns, "lengths": lengths, "distances": distances, "gaits": gaits, "crossed": crossed,
            "heights": heights, "dt": gym_env.unwrapped.dt if sim is not None else None,
            "success_margin": loco.success_margin if crossed else None, "video": video, "terminated": terminated,
            "ends": ends, "seeds": list(seeds), "feet": tuple(loco.foot_names) if loco is not None else None}


def summarize(cfg, episodes: dict) -> dict:
    """The eval's figures from `run_episodes`' record."""
    returns, lengths, distances = episodes["returns"], episodes["lengths"], episodes["distances"]
    crossed, gaits, terminated = episodes["crossed"], episodes["gaits"], episodes["terminated"]
    result = {
        "return_mean": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "length_mean": float(np.mean(lengths)),
        "length_std": float(np.std(lengths)),
        "returns": returns,
        "lengths": lengths,
    }
    beyond = None  # per episode: beyond the success line when the episode ended
    if distances:
        # Forward progress of the base along its heading: mean velocity over each episode, and where it ended.
        dt = episodes["dt"]
        velocities = [d / (n * dt) for (d, _), n in zip(distances, lengths)]
        result.update(forward_velocity_mean=float(np.mean(velocities)), forward_velocity_std=float(np.std(velocities)),
                      x_final_mean=float(np.mean([x1 for _, x1 in distances])))
        if crossed:  # a step env: the env's line, the trunk success_margin beyond the step's edge
            beyond = crossed
            result.update(success_margin=episodes["success_margin"],
                          step_height_mean=float(np.mean(episodes["heights"])))
        elif cfg.eval.get("success_x") is not None:
            beyond = [x1 >= cfg.eval.success_x for _, x1 in distances]
            result["success_x"] = float(cfg.eval.success_x)
    # why episodes ended early: the env's reason (locomotion envs), else 'terminated' (the env said only that)
    ends = [(why or "terminated") if stop else None for stop, why in zip(terminated, episodes["ends"])]
    if beyond is not None:
        # success: beyond the line when the episode ends, and the episode did not end by a fall or a forbidden
        # contact (terminated); crossed_at_end_rate counts the line alone, terminated episodes too
        result.update(success_rate=float(np.mean([b and not t for b, t in zip(beyond, terminated)])),
                      crossed_at_end_rate=float(np.mean(beyond)))
    result["terminated_share"] = float(np.mean(terminated))
    result["termination_shares"] = {why: ends.count(why) / len(ends) for why in sorted(set(ends) - {None})}
    if gaits:
        result["feet"] = list(episodes["feet"])
        result.update(gait_figures(gaits, cfg.env.locomotion.get("joint_speed_limit")))
    result["outcomes"] = [  # one per episode, in order
        {"seed": seed, "length": n, "return": r, "terminated": stop, "termination": why,
         **({"crossed": bool(b), "success": bool(b and not stop)} if beyond is not None else {}),
         **({key: gaits[i][key] for key in (*EPISODE_FOOT_KEYS, *EPISODE_TORQUE_KEYS)} if gaits else {})}
        for i, (seed, n, r, stop, why) in enumerate(zip(episodes["seeds"], lengths, returns, terminated, ends))
        for b in [beyond[i] if beyond is not None else None]]
    return result


# What an eval of a locomotion env adds: gait_figures' keys and the feet's names (also in summary.json and the
# height sweep). Per foot, in the model's foot order (`feet`): foot_contact_share, the share of time on the ground,
# touchdown_frequency (Hz) and longest_air_s, the longest time it was off the ground in any episode (a foot
# held up for seconds shows here); longest_air_moving_s counts only the time the robot moved (not a standstill).
# <kind>_pairs_together: of the time a foot of a pair is down, the share both are, the two pairs of a kind pooled
# (locomotion.FOOT_PAIRS): diagonal LF+RH, RF+LH (a trot: near 1), same_side LF+LH, RF+RH (a pace), same_end
# LF+RF, LH+RH (a bound); only for four feet, one at each corner.
PAIR_KEYS = tuple(f"{kind}_pairs_together" for kind in FOOT_PAIRS)
# Per foot in each episode's outcome (eval.json) and row (height_sweep_episodes.csv): a worst case over the eval
# (longest_air_moving_s) shows whether one episode or every one holds a foot up.
EPISODE_FOOT_KEYS = ("foot_contact_share", "touchdown_frequency", "longest_air_moving_s")
# Per episode too, a robot read from its model (env=legged): the largest |joint torque| / the model's own limit and
# the share of time a joint was at its limit (robots/gait.py); over the eval, the max and the pooled share.
EPISODE_TORQUE_KEYS = ("peak_torque_share", "torque_at_limit_share")
GAIT_KEYS = ("stride_frequency", "duty_factor", "peak_joint_speed", "over_speed_limit_share", "body_contact_share",
             "feet", "foot_contact_share", "touchdown_frequency", "longest_air_s", "longest_air_moving_s", *PAIR_KEYS,
             *EPISODE_TORQUE_KEYS)


def gait_figures(gaits: list, speed_limit: Optional[float]) -> dict:
    """Per-episode gait figures (locomotion.GaitMeter) over the eval: means (each foot's too), the peak joint
    speed's max, the pairs' time down together over all the eval's time and, with a speed limit, the share of all
    the eval's physics steps in which a joint was over it."""
    figures = {key: float(np.mean([g[key] for g in gaits]))
               for key in ("stride_frequency", "duty_factor", "body_contact_share")}
    for key in ("foot_contact_share", "touchdown_frequency"):
        figures[key] = np.mean([g[key] for g in gaits], axis=0).tolist() if gaits[0][key] else []
    for key in ("longest_air_s", "longest_air_moving_s"):
        figures[key] = np.max([g[key] for g in gaits], axis=0).tolist() if gaits[0][key] else []
    for kind in gaits[0]["pair_together_time_s"]:
        down = sum(g["pair_down_time_s"][kind] for g in gaits)
        together = sum(g["pair_together_time_s"][kind] for g in gaits)
        figures[f"{kind}_pairs_together"] = float(together / down) if down > 0 else None
    figures["peak_joint_speed"] = float(max(g["peak_joint_speed"] for g in gaits))
    figures["peak_torque_share"] = figures["torque_at_limit_share"] = None  # None: the model's limits not known
    if gaits[0]["peak_torque_share"] is not None:
        figures["peak_torque_share"] = float(max(g["peak_torque_share"] for g in gaits))
        at_limit = sum(g["torque_at_limit_share"] * g["time_s"] for g in gaits)
        figures["torque_at_limit_share"] = float(at_limit / max(sum(g["time_s"] for g in gaits), 1e-9))
    if speed_limit is not None:
        figures["joint_speed_limit"] = float(speed_limit)
        over = sum(g["over_speed_limit_time_s"] for g in gaits)
        figures["over_speed_limit_share"] = float(over / max(sum(g["time_s"] for g in gaits), 1e-9))
    return figures


def ended_line(result: dict) -> str:
    """'8% end terminated (5% contact: trunk, 3% fall)'; an env that gives no reason: '8% end terminated'."""
    reasons = ", ".join(f"{share:.0%} {why}" for why, share in result["termination_shares"].items()
                        if why != "terminated")
    return f"{result['terminated_share']:.0%} end terminated" + (f" ({reasons})" if reasons else "")


def motion_line(result: dict) -> str:
    """The eval's figures after return and length, one topic a line (each starting '\n  '): where the robot went
    (forward velocity where the env moves, the step's crossings, terminations), its gait, each foot, the pairs."""
    lines = []
    moving = "forward_velocity_mean" in result and (result["forward_velocity_mean"] or result["forward_velocity_std"]
                                                    or "success_rate" in result)
    honest = (f"and are not terminated ({result['crossed_at_end_rate']:.0%} are beyond it at the end; "
              f"{ended_line(result)})") if "success_rate" in result else ""
    went = [f"forward velocity {result['forward_velocity_mean']:.2f} +- {result['forward_velocity_std']:.2f} m/s"] \
        if moving else []
    if "success_margin" in result:
        went.append(f"{result['success_rate']:.0%} of episodes cross the line {result['success_margin']:.3g} m beyond the "
                    f"step ({result['step_height_mean'] * 100:.0f} cm on average) {honest}")
    elif "success_rate" in result:
        went.append(f"{result['success_rate']:.0%} of episodes end beyond x={result['success_x']} m {honest}")
    elif result.get("terminated_share"):
        went.append(ended_line(result))
    if went:
        lines.append(", ".join(went))
    if "stride_frequency" in result:
        limit = (f" (limit {result['joint_speed_limit']:g}, passed {result['over_speed_limit_share']:.2%} of the time)"
                 if "joint_speed_limit" in result else "")
        lines.append(f"gait: stride frequency {result['stride_frequency']:.1f} Hz, duty factor "
                     f"{result['duty_factor']:.2f}, peak joint speed {result['peak_joint_speed']:.1f} rad/s{limit}, "
                     f"a non-foot body on the ground {result['body_contact_share']:.0%} of the time"
                     + (f", joint torque up to {result['peak_torque_share']:.0%} of the model's limit (at it "
                        f"{result['torque_at_limit_share']:.1%} of the time)" if result.get("peak_torque_share") is not None else ""))
        if result["feet"]:
            feet = zip(result["feet"], result["foot_contact_share"], result["touchdown_frequency"],
                       result["longest_air_s"], result["longest_air_moving_s"])
            lines.append("per foot (share of time on the ground, touchdowns/s, longest time in the air in s (of it "
                         "while moving)): " + ", ".join(f"{name} {share:.2f} {rate:.1f} {air:.2f} ({moving_s:.2f})"
                                                        for name, share, rate, air, moving_s in feet))
        pairs = [(key[:-len("_pairs_together")].replace("_", " "), result[key]) for key in PAIR_KEYS
                 if result.get(key) is not None]
        if pairs:
            lines.append("feet of a pair down together, of the time one is: " +
                         ", ".join(f"{kind} {share:.2f}" for kind, share in pairs))
    return "".join(f"\n  {line}" for line in lines)


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


SWEEP_FILES = ("height_sweep.csv", "height_sweep.png", "height_sweep_episodes.csv", "height_sweep.json")


def apply_overrides(cfg, overrides: list[str]):
    """`env.<key>=<value>` arguments on the run's saved config, typed and checked as training checks them."""
    from omegaconf import OmegaConf

    for override in overrides:
        try:
            cfg = OmegaConf.merge(cfg, OmegaConf.from_dotlist([override]))
        except Exception as exc:  # omegaconf: an unknown key or a value of the wrong type
            raise ConfigError(f"cannot apply '{override}' to the run's config: {str(exc).splitlines()[0]}") from None
    for ok, message in env_checks(cfg.env):
        if not ok:
            raise ConfigError(message)
    return cfg


MAX_EPISODES = 10**6
MAX_STEP_M, MAX_STEP_LEGS = 2.0, 4.0  # a step no robot here can meet, let alone climb: a typo (heights=1e9)


def parse_heights(text: str) -> list[tuple]:
    """heights=0,0.05,0.1 (m) or, for env=legged, in leg lengths: 0,0.2l,0.25l,0.3l. [(value, in leg lengths)]."""
    example = "e.g. 0,0.05,0.1,0.15,0.2 (m) or, for env=legged, 0,0.2l,0.25l,0.3l (leg lengths)"
    try:
        heights = [(float(h.strip()[:-1]), True) if h.strip().endswith("l") else (float(h), False)
                   for h in text.split(",") if h.strip()]
    except ValueError:
        raise ConfigError(f"heights={text}: expected step heights separated by commas, {example}") from None
    if not heights or any(not (h >= 0 and math.isfinite(h)) for h, _ in heights):
        raise ConfigError(f"heights={text}: expected step heights >= 0 separated by commas, {example}")
    tall = next((h for h, legs in heights if h > (MAX_STEP_LEGS if legs else MAX_STEP_M)), None)
    if tall is not None:
        raise ConfigError(f"heights={text}: a step of {tall:g} is taller than any robot here can meet (at most "
                          f"{MAX_STEP_M:g} m, or {MAX_STEP_LEGS:g}l in leg lengths); {example}")
    return heights


def heights_in_metres(heights: list[tuple], env_cfg) -> list[float]:
    """parse_heights' values in m: a height in leg lengths times the robot's (read from its model)."""
    if not any(legs for _, legs in heights):
        return [h for h, _ in heights]
    if env_cfg.get("legged") is None:
        raise ConfigError("heights in leg lengths (0.25l) need a run of env=legged, whose robot has one; give m here")
    from ppo_torchrl.envs import resolve_model_file
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import in_metres

    leg = read_robot(resolve_model_file(env_cfg.xml_file), env_cfg.legged.keyframe).leg_length
    return [in_metres(h, leg) if legs else h for h, legs in heights]


def sweep_row(height: float, episodes: int, result: dict) -> dict:
    """One height's row of height_sweep.csv: success (beyond the line and not terminated), the line alone,
    the share of episodes terminated and by each reason, the gait figures (each foot's a column per foot)."""
    row = {"step_height_m": height, "episodes": episodes, "success_rate": result["success_rate"],
           "forward_velocity_mean": result["forward_velocity_mean"], "return_mean": result["return_mean"],
           "crossed_at_end_rate": result["crossed_at_end_rate"], "terminated_share": result["terminated_share"],
           **{f"terminated: {why}": share for why, share in result["termination_shares"].items()}}
    for key in GAIT_KEYS:
        value = result.get(key)
        if key == "feet":
            continue
        if isinstance(value, list):
            row.update({f"{key} {foot}": v for foot, v in zip(result["feet"], value)})
        else:
            row[key] = value
    return row


def height_sweep(cfg, ac, obs_stats, heights: list[float], episodes: int, seed: int, out_dir: Path, title: str,
                 owner: Optional[Path] = None) -> list:
    """Evaluate at each fixed step height; write height_sweep.csv (a row per height), the success-rate curve
    height_sweep.png, height_sweep_episodes.csv (a row per episode: crossed, terminated and why, length and
    EPISODE_FOOT_KEYS per foot) and height_sweep.json (each height's eval result, eval.json's figures).
    owner: the run dir whose manifest lists them (rundir.atomic_write_bytes)."""
    import csv
    import io

    from ppo_torchrl.rundir import atomic_write_bytes, atomic_write_json

    rows, results, per_episode = [], [], []
    for height in heights:
        cfg.env.terrain.step_height = height
        result = evaluate_policy(cfg, ac, obs_stats, episodes, seed=seed, progress=True)
        if "success_margin" not in result:
            raise ConfigError("heights= needs a step env (a model with a body named 'step'); to put a flat-ground run "
                              "on the step add env.xml_file=quadruped_step.xml")
        rows.append(sweep_row(height, episodes, result))
        results.append({"step_height_m": height, **result})
        for outcome in result["outcomes"]:
            per_episode.append({"step_height_m": height,
                                **{k: v for k, v in outcome.items() if k not in EPISODE_FOOT_KEYS},
                                **{f"{key} {foot}": v for key in EPISODE_FOOT_KEYS
                                   for foot, v in zip(result["feet"], outcome.get(key, []))}})
        feet = ", ".join(f"{foot} {share:.2f}" for foot, share in zip(result["feet"], result["foot_contact_share"]))
        print(f"step {height * 100:g} cm: {result['success_rate']:.0%} of {episodes} episodes cross and are not "
              f"terminated ({result['crossed_at_end_rate']:.0%} beyond the line at the end; {ended_line(result)}); "
              f"forward velocity {result['forward_velocity_mean']:.2f} m/s; share of time on the ground: {feet}",
              flush=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, table in ((SWEEP_FILES[0], rows), (SWEEP_FILES[2], per_episode)):
        columns = list(dict.fromkeys(k for row in table for k in row))  # a reason met at one height only: 0 elsewhere
        text = io.StringIO(newline="")
        writer = csv.DictWriter(text, fieldnames=columns, restval=0.0 if name == SWEEP_FILES[0] else "")
        writer.writeheader()
        writer.writerows(table)
        atomic_write_bytes(out_dir / name, lambda f: f.write(text.getvalue().encode()), owner)
    atomic_write_json(out_dir / SWEEP_FILES[3], {"title": title, "episodes": episodes, "seed": seed,
                                                 "heights": results}, owner)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ppo_torchrl.report import write_png

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    x = [r["step_height_m"] * 100 for r in rows]
    ax.plot(x, [r["success_rate"] * 100 for r in rows], "o-", label="cross and not terminated (success)")
    ax.plot(x, [r["crossed_at_end_rate"] * 100 for r in rows], "s--", color="0.6", label="beyond the line at the end")
    ax.set(xlabel="step height (cm)", ylabel=f"episodes (%, of {episodes})", ylim=(-3, 103))
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(title, fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    write_png(fig, out_dir / SWEEP_FILES[1], 120, owner)
    plt.close(fig)
    print(f"per episode: {out_dir / SWEEP_FILES[2]}; every figure: {out_dir / SWEEP_FILES[3]}")
    return rows


@releasing  # the shared locks it takes (locks.read) go when it ends
def main(argv: list[str]) -> dict:
    from ppo_torchrl.checkpoint import check_same_env, check_spec, load_policy, resolve_checkpoint
    from ppo_torchrl.checkpoint import label as checkpoint_label
    from ppo_torchrl.cli import parse_args, resolve_run
    from ppo_torchrl.envs import env_spec
    from ppo_torchrl.model_record import check_model
    from ppo_torchrl.ownership import holder
    from ppo_torchrl.rundir import atomic_write_json, check_replaceable, intend, output_dir_for, record, unwritable
    from ppo_torchrl.usage import EVALUATE

    usage, spec, help, about = EVALUATE  # usage.py: --help answers before torch is imported
    overrides = [arg for arg in argv if arg.startswith("env.")]
    args = parse_args([arg for arg in argv if not arg.startswith("env.")], spec, usage, help, about)
    if args["episodes"] < 1:
        raise ConfigError(f"episodes={args['episodes']} must be >= 1")
    if args["episodes"] > MAX_EPISODES:
        raise ConfigError(f"episodes={args['episodes']} must be at most {MAX_EPISODES:,} (a million episodes of a "
                          "thousand steps run for days)")
    if not 0 <= args["seed"] * 1000 + args["episodes"] < 2**32:  # episode i's seed is seed * 1000 + i (32-bit)
        raise ConfigError(f"seed={args['seed']} must be in 0..{(2**32 - args['episodes']) // 1000}: episode i starts "
                          "from seed * 1000 + i")
    heights = parse_heights(args["heights"]) if args["heights"] else None
    if any(arg.startswith(("video_episodes=", "video_length=")) for arg in argv):
        args["video"] = True
    video_episodes, video_length = parse_video_choices(args["video_episodes"], args["video_length"], args["episodes"])
    if heights and args["video"]:
        raise ConfigError("video=true films one evaluation, not a heights= sweep: film each height with a command of "
                          "its own, env.terrain.step_height=<m> video=true (e.g. env.terrain.step_height=0.1 video=true)")
    run_dir = resolve_run(args["run"])  # run=latest[/<env>]: the newest run dir under outputs/
    read(run_dir)  # a shared lock: no overwrite or run starts there while this reads it (locks.py)
    checkpoint = resolve_checkpoint(run_dir, args["checkpoint"])  # best without a best.pt: last.pt, said so
    which = checkpoint_label(checkpoint)
    out_dir = Path(args["out"]) if args["out"] else output_dir_for(run_dir, run_dir / "eval")  # zoo: outputs/zoo/<name>
    why = unwritable(out_dir)  # before any episode runs
    if why:
        raise ConfigError(f"cannot write the eval's files in {out_dir}: {why}; give a writable dir with out=<dir>")
    video = out_dir / f"{which}.mp4"
    writes = [out_dir / name for name in SWEEP_FILES] if heights else [out_dir / "eval.json"] + [video] * args["video"]
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
    if heights:
        heights = heights_in_metres(heights, cfg.env)
        rows = height_sweep(cfg, ac, obs_stats, heights, args["episodes"], args["seed"], out_dir,
                            f"{run_dir.resolve().name}\n{label}", owner=run_dir)
        print(f"{label}: height sweep over {args['episodes']} episodes per height: "
              f"{out_dir / SWEEP_FILES[0]}, {out_dir / SWEEP_FILES[1]}")
        record(run_dir, writes)  # in the run dir that holds them, however out= spells it
        return {"heights": rows}
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
          f"over {args['episodes']} episodes" + motion_line(result) + ("\n  " + video_line(result["video"])
                                                                       if result["video"] else ""))
    return result


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
