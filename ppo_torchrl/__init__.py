"""ppo_torchrl: PPO for MuJoCo robots, built from TorchRL components and wired by Hydra."""

__version__ = "0.1.0"
