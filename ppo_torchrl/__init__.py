"""ppo_torchrl: PPO for MuJoCo robots, built from TorchRL components and wired by Hydra."""

import os

# Headless rendering: EGL works on machines without a display (set MUJOCO_GL to override).
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"
