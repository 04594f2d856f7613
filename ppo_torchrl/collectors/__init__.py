"""Collectors: TorchRL collectors, at three scales, and the app's view of them.

Three TorchRL collector classes step the one env of `envs.make_torchrl_env` (TransformedEnv(GymWrapper)):
- `FastCollector` (fast.py): a `torchrl.collectors.Collector` whose rollout steps the Gymnasium envs in
  numpy with the env's own normalization; the default;
- TorchRL's own `Collector`, which runs the transforms per step and so takes any TorchRL transform
  (`env.transforms.extra`);
- `EnvpoolCollector` (envpool_backend.py, `collector.backend=envpool`): FastCollector's loop over EnvPool's
  C++ envs, an option.
Each runs in one process, in `collector.workers` processes (TorchRL's `MultiSyncCollector`) or on Ray
(`collector.distributed=ray`: `RayCollector`), each taking it as `collector_class` (collection.py).
`Collection` is what the trainer sees: batches [envs, steps], finished episodes, statistics, state.
"""

from __future__ import annotations

import torch

from ppo_torchrl.collectors.choice import CHOICES, describe_backend, resolve_backend
from ppo_torchrl.collectors.collection import Collection

__all__ = ["CHOICES", "Collection", "describe_backend", "make_collector", "resolve_backend"]


def make_collector(cfg, ac, seed: int, device: torch.device, first_env=None) -> Collection:
    """first_env: a Gymnasium env of cfg.env already built (the command's check built it), the collection's env 0."""
    return Collection(cfg, ac, seed, device, first_env)
