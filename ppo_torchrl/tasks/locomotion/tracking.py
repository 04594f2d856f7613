"""How well a joystick policy tracks its commands (issue 73 item 4): a fixed set of commands, each held for a whole
episode, measured after a settling time.

    python -m ppo_torchrl.evaluate run=<joystick run> tracking=true [episodes=5] [seed=0] [extremes=true] [out=<dir>]

For each command of COMMANDS (in the robot's units: speeds in sqrt(g l), the yaw rate in sqrt(g / l)) `episodes`
episodes (episode seeds seed * 1000 + i) start from their reset, the command held; after SETTLE (x sqrt(l / g)) the
MEASURE window's steps are measured: the tracking error of the ground velocity in the trunk's heading frame,
|v_xy - command_xy| (RMS over the window, in sqrt(g l)), and of the yaw rate (in sqrt(g / l)); whether the episode
ended early (a fall); the per-foot gait figures on the forward commands; on the standing command the joints' motion
(the RMS of each joint angle about its own mean over the window, rad). Per command and over all of them; one
plot of commanded against measured velocity over time (`tracking.png`). extremes=true: the same set once per corner of
the run's randomization (RandomizeConfig: grip, trunk mass and strength at their ends), each world fixed.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from ppo_torchrl.errors import ConfigError

# (name, vx, vy, yaw): the evaluation set, in the robot's units
COMMANDS = (("stand", 0.0, 0.0, 0.0),
            ("forward slow", 0.15, 0.0, 0.0), ("forward", 0.3, 0.0, 0.0), ("forward fast", 0.5, 0.0, 0.0),
            ("backward slow", -0.15, 0.0, 0.0), ("backward", -0.3, 0.0, 0.0), ("backward fast", -0.5, 0.0, 0.0),
            ("left", 0.0, 0.25, 0.0), ("right", 0.0, -0.25, 0.0),
            ("turn left", 0.0, 0.0, 0.25), ("turn right", 0.0, 0.0, -0.25),
            ("forward turning left", 0.3, 0.0, 0.25), ("forward turning right", 0.3, 0.0, -0.25))
SETTLE, MEASURE = 10.0, 30.0  # x sqrt(l / g): Go1 ~2 s and ~6 s
MAX_ROWS = 32


def extremes(randomize: dict) -> list:
    """The corners of the run's randomization (its grip, trunk mass and strength ranges): [(name, draw)]."""
    out = []
    for grip in ("low", "high"):
        for mass in ("light", "heavy"):
            for strength in ("weak", "strong"):
                pick = lambda key, end: randomize[key][0 if end in ("low", "light", "weak") else 1]  # noqa: E731
                out.append((f"grip {grip}, {mass}, {strength}",
                            {"friction": pick("friction", grip), "trunk_mass": pick("trunk_mass", mass),
                             "com": [0.0, 0.0, 0.0], "strength": pick("strength", strength), "delayed": False}))
    return out


@torch.no_grad()
def track(make_batch, cfg, ac, obs_stats: Optional[dict], episodes: int, seed: int, world_draw: Optional[dict] = None,
          commands=COMMANDS, settle_time: float = SETTLE, measure_time: float = MEASURE) -> dict:
    """The tracking figures of one world (the nominal one, or `world_draw` fixed in every row); times in sqrt(l / g)."""
    from ppo_torchrl.envs.make import episode_seeds
    from ppo_torchrl.robots.gait import GaitMeter
    from ppo_torchrl.tasks.locomotion.evaluation import GaitBatch, eval_policy

    from ppo_torchrl.envs.make import gym_make_kwargs

    if (gym_make_kwargs(cfg.env)["legged"].get("command") or {}).get("kind") != "velocity":
        raise ConfigError("tracking=true measures a joystick run (env.legged.command.kind=velocity); this run walks "
                          "along its heading")
    jobs = [(c, s) for c in range(len(commands)) for s in episode_seeds(seed, episodes)]
    per_episode, traces = [], {}
    for start in range(0, len(jobs), MAX_ROWS):
        chunk = jobs[start:start + MAX_ROWS]
        rows = len(chunk)
        batch = make_batch(cfg.env, rows, evaluation=True)
        try:
            world, task = batch.world, batch.task
            speed, time = world.units
            rate = 1.0 / time
            settle = round(settle_time / rate / world.dt)
            steps = settle + round(measure_time / rate / world.dt)
            if steps > batch.max_steps:
                raise ConfigError(f"tracking=true holds each command {steps * world.dt:.1f} s (settling and measuring); the "
                                  f"run's episodes end at {batch.max_steps} steps ({batch.max_steps * world.dt:.1f} s): give "
                                  f"env.max_episode_steps={steps} or more")
            batch.gait = GaitBatch(rows, world, cfg.env.locomotion.get("joint_speed_limit"))
            for i, (c, episode_seed) in enumerate(chunk):
                if world_draw is not None:
                    task.randomize.fix(i, world_draw)
                batch.reset_row(i, episode_seed)
                batch.reset_row(i)  # as evaluate starts an episode (evaluation.py)
                _, vx, vy, yaw = commands[c]
                task.command.hold(i, [vx * speed, vy * speed, yaw * rate])
            act = eval_policy(cfg, ac, obs_stats, batch, rows, True)
            alive = np.ones(rows, bool)
            v, w, q = np.zeros((steps, rows, 2)), np.zeros((steps, rows)), np.zeros((steps, rows, len(world.act_dofs)))
            for t in range(steps):
                if t == settle:
                    for i in range(rows):  # the gait of the measured window only
                        batch.gait.reset(i)
                _, _, terminated, truncated, _ = batch.step(act(batch.last_obs))
                motion = task.motion(batch.reading)
                v[t], w[t], q[t] = motion["velocity"], motion["yaw_rate"], motion["joint_angle"]
                alive &= ~terminated
                if not alive.any():
                    break
            for i, (c, episode_seed) in enumerate(chunk):
                name, vx, vy, yaw = commands[c]
                window = slice(settle, steps)
                fell = not alive[i]
                ev = np.sqrt(np.mean(np.square(v[window, i] - [vx * speed, vy * speed]).sum(axis=1))) / speed
                ew = np.sqrt(np.mean(np.square(w[window, i] - yaw * rate))) / rate
                joints = q[window, i]
                still = float(np.sqrt(np.mean(np.square(joints - joints.mean(axis=0)))))
                gait = batch.gait.meters[i].summary()
                per_episode.append({"command": name, "seed": episode_seed, "fell": fell, "v_xy_error": float(ev),
                                    "yaw_rate_error": float(ew), "joint_motion_rms": still,
                                    "foot_contact_share": gait["foot_contact_share"],
                                    "touchdown_frequency": gait["touchdown_frequency"],
                                    "longest_air_moving_s": gait["longest_air_moving_s"],
                                    "draw": dict(task.randomize.draws[i])})
                if name not in traces:  # the plot's: one episode per command
                    traces[name] = {"t": (np.arange(steps) * world.dt).tolist(), "v": v[:, i].tolist(),
                                    "w": w[:, i].tolist(), "command": [vx * speed, vy * speed, yaw * rate]}
        finally:
            batch.close()
    feet = list(world.foot_names)
    return {"commands": summarize(per_episode, commands), "overall": overall(per_episode), "episodes": per_episode,
            "feet": feet, "settle_s": settle * world.dt, "measure_s": (steps - settle) * world.dt, "traces": traces,
            "units": {"v_xy_error": "sqrt(g l)", "yaw_rate_error": "sqrt(g / l)", "joint_motion_rms": "rad"}}


def summarize(per_episode: list, commands=COMMANDS) -> list:
    rows = []
    for name, vx, vy, yaw in commands:
        mine = [e for e in per_episode if e["command"] == name]
        standing = [e for e in mine if not e["fell"]] or mine
        row = {"command": name, "vx": vx, "vy": vy, "yaw": yaw, "episodes": len(mine),
               "falls": float(np.mean([e["fell"] for e in mine])),
               "v_xy_error": float(np.mean([e["v_xy_error"] for e in standing])),
               "yaw_rate_error": float(np.mean([e["yaw_rate_error"] for e in standing]))}
        if name == "stand":
            row["joint_motion_rms"] = float(np.mean([e["joint_motion_rms"] for e in standing]))
        if vx > 0 and vy == 0 and yaw == 0 and standing and "foot_contact_share" in standing[0]:  # a task with feet read
            row["foot_contact_share"] = np.mean([e["foot_contact_share"] for e in standing], axis=0).tolist()
            row["touchdown_frequency"] = np.mean([e["touchdown_frequency"] for e in standing], axis=0).tolist()
            row["foot_up_over_0.5s"] = float(np.mean([max(e["longest_air_moving_s"]) > 0.5 for e in standing]))
        rows.append(row)
    return rows


def overall(per_episode: list) -> dict:
    standing = [e for e in per_episode if not e["fell"]] or per_episode
    return {"episodes": len(per_episode), "falls": float(np.mean([e["fell"] for e in per_episode])),
            "v_xy_error": float(np.mean([e["v_xy_error"] for e in standing])),
            "yaw_rate_error": float(np.mean([e["yaw_rate_error"] for e in standing]))}


def table(result: dict) -> str:
    lines = ["| command | episodes | falls | v_xy error (sqrt(g l)) | yaw rate error (sqrt(g / l)) | more |",
             "|---|---|---|---|---|---|"]
    for r in result["commands"]:
        more = []
        if "joint_motion_rms" in r:
            more.append(f"joints move {r['joint_motion_rms']:.3f} rad rms")
        if "foot_contact_share" in r:
            more.append("feet down " + " ".join(f"{x:.2f}" for x in r["foot_contact_share"]) +
                        f", {np.mean(r['touchdown_frequency']):.2f} touchdowns/s")
        lines.append(f"| {r['command']} | {r['episodes']} | {r['falls']:.0%} | {r['v_xy_error']:.3f} | "
                     f"{r['yaw_rate_error']:.3f} | {'; '.join(more)} |")
    o = result["overall"]
    lines.append(f"| **all** | {o['episodes']} | {o['falls']:.0%} | {o['v_xy_error']:.3f} | {o['yaw_rate_error']:.3f} | |")
    return "\n".join(lines) + "\n"


def plot(result: dict, path: Path, title: str, owner=None) -> None:
    """Commanded against measured velocity over time, one panel per command (vx, vy and the yaw rate)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ppo_torchrl.report import write_png

    traces = result["traces"]
    cols = 4
    rowsn = math.ceil(len(traces) / cols)
    fig, axes = plt.subplots(rowsn, cols, figsize=(3.2 * cols, 2.3 * rowsn), squeeze=False)
    for ax, (name, tr) in zip(axes.flat, traces.items()):
        t, v, w = np.array(tr["t"]), np.array(tr["v"]), np.array(tr["w"])
        for k, (label, series, cmd) in enumerate((("vx", v[:, 0], tr["command"][0]), ("vy", v[:, 1], tr["command"][1]),
                                                  ("yaw", w, tr["command"][2]))):
            color = f"C{k}"
            ax.plot(t, series, color=color, lw=0.8, label=label)
            ax.axhline(cmd, color=color, ls="--", lw=0.8)
        ax.axvline(result["settle_s"], color="0.6", lw=0.6)
        ax.set_title(name, fontsize=8)
        ax.tick_params(labelsize=6)
    for ax in list(axes.flat)[len(traces):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6)
    fig.suptitle(title + "  (dashed: commanded; m/s and rad/s; grey line: the end of settling)", fontsize=8)
    fig.tight_layout()
    write_png(fig, path, 110, owner)
    plt.close(fig)
