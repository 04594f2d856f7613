"""tracking=true on a MuJoCo Playground joystick task (env=playground, issue 74 item 3): the joystick issue's fixed
command set (tasks/locomotion/tracking.py: COMMANDS in the robot's units, SETTLE, MEASURE, the same figures and table)
on EnvPool's port of the task.

    python -m ppo_torchrl.evaluate run=<env=playground run> tracking=true [episodes=5] [seed=0] [out=<dir>]

EnvPool draws each episode's command itself (Playground's: uniform within command_a, zero with probability
1 - command_b, each component redrawn with probability 1/2 every few seconds) and takes none from outside. The
command reaches the policy only as the command segment of its observation and enters only the task's reward, not its
physics; so, as a robot's joystick does, the evaluation writes each command of the set into that segment of every
observation the policy sees, and measures the trunk from the task's privileged state: the local linear velocity (the
trunk's velocimeter) and the gyro's yaw rate, as Playground's tracking rewards read them, and the joint angles for
the standing command's motion. Units: sqrt(g l) and sqrt(g / l), l the leg length that robots/model.py reads from the
task's own MJCF (Go1: 0.426 m, as Menagerie's Go1; Spot: 0.657 m). The figures differ from env=legged's in two ways,
said: the velocity is the trunk frame's (env=legged's: the ground velocity in the heading frame; the same on level
ground up to the trunk's tilt), and no gait figures (EnvPool gives no contacts of the feet to read here).

LAYOUTS: where those are in each task's vectors, found from the tasks' observations and checked by
tests/test_playground.py against info["command"], the noise-free state, the gravity vector's motion and the task's own
tracking reward terms (info), computed back from the velocities found. A task without an entry: tracking=true names
the tasks that have one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.tasks.locomotion.tracking import COMMANDS, MEASURE, SETTLE, overall, summarize


@dataclass(frozen=True)
class Layout:
    xml: str  # a scene of the robot (its MJCF and a floor), under EnvPool's asset dir (spec.config.base_path)
    command: int  # start of (vx, vy, yaw rate) in the actor's observation (`state`)
    linvel: int  # start of the local linear velocity (3) in `privileged_state`
    gyro: int  # start of the gyro (3, the trunk frame) in `privileged_state`
    joints: int  # start of the joint angles less the standing pose's (12) in `privileged_state`


_GO1 = Layout("mujoco/playground/assets/mujoco_playground/_src/locomotion/go1/xmls/scene_mjx_feetonly_flat_terrain.xml",
              command=45, linvel=57, gyro=48, joints=63)
# Spot's state: gyro 0-3, gravity 3-6, joint angles 6-18, their error history 18-54, feet 54-66, last action 66-78, the
# command 78-81; its privileged_state: that state (81), then gyro, accelerometer, gravity, local linear velocity, ...
_SPOT = Layout("mujoco/playground/assets/mujoco_playground/_src/locomotion/spot/xmls/scene_mjx_feetonly_flat_terrain.xml",
               command=78, linvel=90, gyro=81, joints=96)
LAYOUTS = {"Go1JoystickFlatTerrain-v1": _GO1, "Go1JoystickRoughTerrain-v1": _GO1, "SpotFlatTerrainJoystick-v1": _SPOT}


def layout_of(env_cfg) -> Layout:
    """The task's Layout; one ConfigError line for a task without one."""
    from ppo_torchrl.envs.playground import task_id

    task = task_id(env_cfg.id)
    if task not in LAYOUTS:
        raise ConfigError(f"tracking=true on env=playground knows where the command and the trunk's velocity are in "
                          f"{', '.join(LAYOUTS)}; not in {task}'s observations")
    return LAYOUTS[task]


@torch.no_grad()
def track(cfg, ac, obs_stats, episodes: int, seed: int, commands=COMMANDS, settle_time: float = SETTLE,
          measure_time: float = MEASURE) -> dict:
    """tracking.track's figures on a Playground task: episode e (seed `seed * 1000 + e`, episode_seeds) of every
    command at once, command c in env c of one pool seeded so (env c: that seed + c)."""
    from ppo_torchrl.envs.make import episode_seeds
    from ppo_torchrl.envs.playground import PlaygroundPool, pool_settings
    from ppo_torchrl.envs.layout import ObservationLayout, Segment
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.rl.array_policy import policy_of

    layout = layout_of(cfg.env)
    settings = pool_settings(cfg.env)
    key, privileged = settings["keys"]
    n = len(commands)
    pool = PlaygroundPool(settings, n)
    robot = read_robot(Path(pool.spec.config.base_path) / layout.xml)
    speed, time = robot.speed_scale, robot.time_scale
    settle = round(settle_time * time / pool.dt)
    steps = settle + round(measure_time * time / pool.dt)
    if steps > pool.spec.config.max_episode_steps:
        raise ConfigError(f"tracking=true holds each command {steps * pool.dt:.1f} s (settling and measuring); the "
                          f"run's episodes end at {pool.spec.config.max_episode_steps} steps: give "
                          f"env.max_episode_steps={steps} or more")
    size = pool.sizes[key]
    act = policy_of(cfg, ac, obs_stats, size, ObservationLayout((Segment.running(key, size),)),
                    len(pool.action_low), n, True)
    target = np.array([[vx * speed, vy * speed, yaw / time] for _, vx, vy, yaw in commands])
    per_episode, traces = [], {}
    c0, rows = layout.command, np.arange(n)
    try:
        for episode_seed in episode_seeds(seed, episodes):
            pool.build(episode_seed)
            alive = np.ones(n, bool)
            lasted = np.full(n, steps)  # steps each env stood (a fall: the step it ended on)
            v, w, q = np.zeros((steps, n, 2)), np.zeros((steps, n)), np.zeros((steps, n, 12))
            for t in range(steps):
                obs = pool.current[key].copy()
                obs[:, c0:c0 + 3] = target  # the joystick's command, in place of the task's own
                out, _, terminated, truncated, _ = pool.step(act(obs), rows)
                p = out[privileged]
                v[t], w[t] = p[:, layout.linvel:layout.linvel + 2], p[:, layout.gyro + 2]
                q[t] = p[:, layout.joints:layout.joints + 12]
                ended = alive & (terminated | truncated)
                lasted[ended] = t
                alive &= ~ended
                if not alive.any():
                    break
            for c, (name, vx, vy, yaw) in enumerate(commands):
                window = slice(settle, lasted[c]) if lasted[c] > settle else slice(0, max(lasted[c], 1))
                ev = np.sqrt(np.mean(np.square(v[window, c] - target[c, :2]).sum(axis=1))) / speed
                ew = np.sqrt(np.mean(np.square(w[window, c] - target[c, 2]))) * time
                joints = q[window, c]
                per_episode.append({"command": name, "seed": episode_seed, "fell": bool(lasted[c] < steps),
                                    "v_xy_error": float(ev), "yaw_rate_error": float(ew),
                                    "joint_motion_rms": float(np.sqrt(np.mean(np.square(joints - joints.mean(axis=0)))))})
                if name not in traces:  # the plot's: the first episode of each command
                    traces[name] = {"t": (np.arange(steps) * pool.dt).tolist(), "v": v[:, c].tolist(),
                                    "w": w[:, c].tolist(), "command": target[c].tolist()}
    finally:
        pool.close_pool()
    return {"commands": summarize(per_episode, commands), "overall": overall(per_episode), "episodes": per_episode,
            "feet": [], "settle_s": settle * pool.dt, "measure_s": (steps - settle) * pool.dt, "traces": traces,
            "leg_length": robot.leg_length, "frame": "the trunk's (privileged_state)",
            "units": {"v_xy_error": "sqrt(g l)", "yaw_rate_error": "sqrt(g / l)", "joint_motion_rms": "rad"}}
