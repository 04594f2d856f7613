"""Collectors: each `collect()` returns one batch of `frames_per_batch` frames.

Every backend implements `Collector` below and returns a TensorDict of batch size [num_envs, steps]
with TorchRL's keys: `observation`, `action`, and under `next`: `observation`, `reward`, `done`,
`terminated`, `truncated`. Observations and rewards are the normalized ones the learner sees; raw
episode returns and lengths come from `pop_episodes()`. A third backend is one new module here and
one entry in BACKENDS.

- `torchrl` (torchrl_collector.py): TorchRL's `Collector` over `TransformedEnv(GymWrapper)`, the
  reference pipeline; any TorchRL transform can be added to it (`env.transforms.extra`).
- `fast` (fast.py): the same math in a lean numpy loop, the default when no extra transform is asked.
- `multiprocess` (multiprocess.py): TorchRL's `MultiSyncCollector` (`collector.workers` > 1) or
  `RayCollector` (`collector.distributed=ray`) over the torchrl backend's env; chosen by those keys.
"""

from __future__ import annotations

from typing import Dict, List, Optional, Protocol, Tuple

import torch
from tensordict import TensorDict

from ppo_torchrl.collectors.fast import FastCollector
from ppo_torchrl.collectors.multiprocess import MultiProcessCollector
from ppo_torchrl.collectors.torchrl_collector import TorchRLCollector
from ppo_torchrl.errors import ConfigError


class Collector(Protocol):
    """What the trainer, checkpoints, evaluation and export need of a backend."""

    def collect(self) -> TensorDict: ...

    def pop_episodes(self) -> List[Tuple[float, int]]:
        """(raw return, length) of the episodes finished since the last call."""

    def env_metrics(self) -> Dict[str, float]:
        """Scalars the envs keep, logged each iteration: a step env's curriculum level and recent success
        rate (`LocomotionEnv.terrain_metrics`); {} where the envs say nothing or live in other processes."""

    def obs_stats(self) -> Optional[dict]:
        """Observation statistics {"mean", "var", "count"} (None without normalization)."""

    def state_dict(self) -> dict: ...

    def load_state_dict(self, state: dict) -> None: ...

    def close(self) -> None: ...


BACKENDS: Dict[str, type] = {"fast": FastCollector, "torchrl": TorchRLCollector,
                              "multiprocess": MultiProcessCollector}
CHOICES = ("auto", "fast", "torchrl")  # collector.backend; multiprocess follows from workers / distributed


def resolve_backend(cfg) -> str:
    """`auto`: fast unless TorchRL transforms are asked for; fast with them is a one-line error.
    Several workers (or Ray) run TorchRL's collectors over the torchrl backend's env."""
    backend, extra = cfg.collector.backend, bool(cfg.env.transforms.extra)
    if cfg.collector.workers > 1 or cfg.collector.distributed:
        if backend == "fast":
            raise ConfigError("collector.workers > 1 and collector.distributed run TorchRL's collectors over the "
                              "torchrl backend's env: use collector.backend=auto (or torchrl), not fast")
        return "multiprocess"
    if backend == "auto":
        return "torchrl" if extra else "fast"
    if backend == "fast" and extra:
        raise ConfigError("env.transforms.extra needs collector.backend=torchrl (or auto): the fast backend "
                          "runs no TorchRL transform")
    return backend


def make_collector(cfg, ac, seed: int, device: torch.device) -> Collector:
    return BACKENDS[resolve_backend(cfg)](cfg, ac, seed, device)
