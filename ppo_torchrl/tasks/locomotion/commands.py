"""What a legged task asks each row's robot to do, behind one small protocol: `speed(xy_velocity)` (the progress its
reward terms pay for), `observe()` (its segment of the observation, [N, size]), `resample(i, rng)` at a row's reset,
`row_state` / `set_row_state` (a checkpoint). A command kind is one class here.

`HeadingCommand`: walk along the robot's heading (env.locomotion.heading), at up to `target_speed`: the speed paid
for is the trunk's velocity along the heading, capped there; nothing is observed (the climb recipes' task).
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

    def row_state(self, i: int) -> dict:
        return {}

    def set_row_state(self, i: int, state: dict) -> None:
        pass
