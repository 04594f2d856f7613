"""What a legged task asks each row's robot to do, behind one small protocol: `speed(xy_velocity)` (the progress its
reward terms pay for), `observe()` (its segment of the observation, [N, size]), `resample(i, rng)` at a row's reset,
`tick(rngs)` after each control step, `row_state` / `set_row_state` (a checkpoint). A command kind is one class here.

`HeadingCommand`: walk along the robot's heading (env.locomotion.heading), at up to `target_speed`: the speed paid
for is the trunk's velocity along the heading, capped there; nothing is observed (the climb recipes' task).
`VelocityCommand`: a joystick (vx, vy, yaw rate), the first command kind after the rebuild.
"""

from __future__ import annotations

from typing import Optional

import numpy as np


class HeadingCommand:
    size = 0  # observation elements

    def __init__(self, n: int, world, target_speed: Optional[float]):
        self.n, self.heading, self.heading_is_x = n, world.heading, world.heading_is_x
        self.target_speed = target_speed

    def progress(self, xy_velocity: np.ndarray) -> np.ndarray:
        """[N] the velocity along the heading (the eval's forward velocity; uncapped)."""
        return xy_velocity[:, 0].copy() if self.heading_is_x else xy_velocity @ self.heading

    def speed(self, progress: np.ndarray) -> np.ndarray:
        """[N] what the forward term pays for: the progress, capped at target_speed."""
        return progress if self.target_speed is None else np.minimum(progress, self.target_speed)

    def observe(self) -> np.ndarray:
        return np.zeros((self.n, 0))

    def resample(self, i: int, rng) -> None:
        pass

    def tick(self, rngs: list) -> None:
        pass

    def row_state(self, i: int) -> dict:
        return {}

    def set_row_state(self, i: int, state: dict) -> None:
        pass


class VelocityCommand:
    """A joystick (config.py, CommandConfig): per row a commanded (vx, vy) in the trunk's heading frame and a yaw
    rate, drawn from the ranges at each reset and again every `resample` (drawn too), a `stand_share` of the draws all
    zero; observed in the robot's units (speeds over sqrt(g l), the yaw rate over sqrt(g / l)). `hold(i, value)` sets
    a row's command until it is set again (an evaluation's fixed commands)."""

    size = 3

    def __init__(self, n: int, world, command: dict, dt: float, speed_scale: float, time_scale: float):
        self.n, self.heading, self.heading_is_x, self.dt = n, world.heading, world.heading_is_x, dt
        self.ranges = np.array([command["vx"], command["vy"], command["yaw"]], np.float64)  # [3, 2], SI
        self.stand_share = float(command["stand_share"])
        self.resample_s = tuple(float(t) for t in command["resample"])
        self.scale = np.array([speed_scale, speed_scale, 1.0 / time_scale])  # SI per robot unit
        self.value = np.zeros((n, 3))
        self.countdown = np.zeros(n, np.int64)  # control steps until the next draw
        self.held = np.zeros(n, bool)
        self.target_speed = None

    def progress(self, xy_velocity: np.ndarray) -> np.ndarray:
        return xy_velocity[:, 0].copy() if self.heading_is_x else xy_velocity @ self.heading

    def speed(self, progress: np.ndarray) -> np.ndarray:
        return progress

    def observe(self) -> np.ndarray:
        return self.value / self.scale

    def draw(self, i: int, rng) -> None:
        if self.stand_share > 0 and rng.uniform() < self.stand_share:
            self.value[i] = 0.0
        else:
            self.value[i] = rng.uniform(self.ranges[:, 0], self.ranges[:, 1])
        self.countdown[i] = max(1, round(rng.uniform(*self.resample_s) / self.dt))

    def resample(self, i: int, rng) -> None:
        self.held[i] = False
        self.draw(i, rng)

    def hold(self, i: int, value) -> None:
        self.value[i], self.held[i] = np.asarray(value, np.float64), True

    def tick(self, rngs: list) -> None:
        """A control step passed: rows whose time is up draw again (held rows keep theirs)."""
        self.countdown -= 1
        for i in np.flatnonzero((self.countdown <= 0) & ~self.held):
            self.draw(int(i), rngs[i])

    def row_state(self, i: int) -> dict:
        return {"value": self.value[i].copy(), "countdown": int(self.countdown[i]), "held": bool(self.held[i])}

    def set_row_state(self, i: int, state: dict) -> None:
        if state:
            self.value[i], self.countdown[i], self.held[i] = state["value"], state["countdown"], state["held"]


def make_command(n: int, world, legged: dict, dt: float):
    """The command kind of env.locomotion.command (heading, the default, or velocity)."""
    from ppo_torchrl.errors import ConfigError

    command = legged.get("command") or {}
    kind = command.get("kind", "heading")
    if kind == "heading":
        return HeadingCommand(n, world, legged.get("target_speed"))
    if kind == "velocity":
        return VelocityCommand(n, world, command, dt, *world.units)
    raise ConfigError(f"env.legged.command.kind={kind} is not known; use heading or velocity")
