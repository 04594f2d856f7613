"""Drive a joystick policy with a scripted command sequence and film it (issue 73 item 5): the command and the measured
velocity drawn in each frame, at real-time speed.

    python -m ppo_torchrl.evaluate run=<joystick run> drive="forward:0.3,0,0:4;turn:0,0,0.25:4;left:0,0.25,0:4;stop:0,0,0:3"

Each segment is name:vx,vy,yaw:seconds, in the robot's units (speeds in sqrt(g l), the yaw rate in sqrt(g / l));
the episode starts from the evaluation's first seed and runs the segments in turn (the nominal world). Writes
drive.mp4 (and returns what each segment measured: the mean velocity over its second half).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from ppo_torchrl.errors import ConfigError

DEFAULT = "forward:0.3,0,0:4;turn:0,0,0.25:4;left:0,0.25,0:4;stop:0,0,0:3"


def parse(text: str) -> list:
    """'name:vx,vy,yaw:seconds;...' -> [(name, [vx, vy, yaw], seconds)]; ConfigError when malformed."""
    example = f"e.g. drive=\"{DEFAULT}\""
    segments = []
    try:
        for part in text.split(";"):
            name, values, seconds = part.split(":")
            command = [float(v) for v in values.split(",")]
            if len(command) != 3 or not (float(seconds) > 0 and math.isfinite(float(seconds))) \
                    or not all(math.isfinite(v) for v in command):
                raise ValueError
            segments.append((name.strip() or "segment", command, float(seconds)))
    except ValueError:
        raise ConfigError(f"drive={text}: expected name:vx,vy,yaw:seconds segments separated by ';', {example}") from None
    return segments


def caption(frame: np.ndarray, lines: list) -> np.ndarray:
    """The frame with `lines` of text drawn in its top-left corner (Pillow, matplotlib's own dependency)."""
    from PIL import Image, ImageDraw

    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    draw.rectangle([4, 4, 4 + 7 * max(len(line) for line in lines), 8 + 14 * len(lines)], fill=(0, 0, 0))
    for k, line in enumerate(lines):
        draw.text((8, 6 + 14 * k), line, fill=(255, 255, 255))
    return np.asarray(image)


@torch.no_grad()
def drive(make_batch, cfg, ac, obs_stats, segments: list, path: Path, seed: int, owner=None) -> list:
    import imageio.v2 as imageio

    from ppo_torchrl.envs.filming import VIDEO_MAX_FPS, VIDEO_SIZE
    from ppo_torchrl.run.rundir import intend
    from ppo_torchrl.tasks.locomotion.evaluation import eval_policy

    batch = make_batch(cfg.env, 1, evaluation=True, render_mode="rgb_array", width=VIDEO_SIZE[0], height=VIDEO_SIZE[1])
    try:
        world, task = batch.world, batch.task
        if task.command.size != 3:
            raise ConfigError("drive= steers a joystick run (env.legged.command.kind=velocity)")
        speed, time = world.units
        rate = 1.0 / time
        every = max(1, math.ceil((1.0 / world.dt) / VIDEO_MAX_FPS - 1e-9))
        short = [name for name, _, s in segments if round(s / world.dt) < 1]
        if short:  # a segment of no control step would measure nothing
            raise ConfigError(f"drive=: segment {short[0]} is shorter than a control step ({world.dt:.3f} s)")
        total = sum(round(s / world.dt) for _, _, s in segments)
        if total > batch.max_steps:
            raise ConfigError(f"drive=: {total * world.dt:.1f} s of commands, longer than the run's episodes "
                              f"({batch.max_steps * world.dt:.1f} s): give env.max_episode_steps={total} or more")
        batch.reset_row(0, seed)
        batch.reset_row(0)
        act = eval_policy(cfg, ac, obs_stats, batch, 1, True)
        path.parent.mkdir(parents=True, exist_ok=True)
        if owner is not None:
            intend(owner, [path])  # imageio writes the mp4 in place: listed first (rundir.py)
        writer = imageio.get_writer(path, fps=(1.0 / world.dt) / every, macro_block_size=8)
        out, step = [], 0
        try:
            for name, command, seconds in segments:
                task.command.hold(0, [command[0] * speed, command[1] * speed, command[2] * rate])
                measured = []
                for _ in range(round(seconds / world.dt)):
                    _, _, terminated, _, _ = batch.step(act(batch.last_obs))
                    motion = task.motion(batch.reading)
                    now = [motion["velocity"][0, 0] / speed, motion["velocity"][0, 1] / speed,
                           motion["yaw_rate"][0] / rate]
                    measured.append(now)
                    if step % every == every // 2:
                        writer.append_data(caption(batch.render(), [
                            f"{name}: command vx {command[0]:+.2f} vy {command[1]:+.2f} yaw {command[2]:+.2f}",
                            f"measured vx {now[0]:+.2f} vy {now[1]:+.2f} yaw {now[2]:+.2f}",
                            "(sqrt(g l), sqrt(g / l))"]))
                    step += 1
                    if terminated[0]:
                        break
                half = np.mean(measured[len(measured) // 2:], axis=0)
                out.append({"segment": name, "command": command, "measured": [float(x) for x in half],
                            "fell": bool(terminated[0])})
                if terminated[0]:
                    break
        finally:
            writer.close()
        return out
    finally:
        batch.close()
