"""Which TorchRL collector class a config runs, and why (the start line says it)."""

from __future__ import annotations

from typing import Tuple

from ppo_torchrl.errors import ConfigError

CHOICES = ("auto", "fast", "torchrl")  # collector.backend


def resolve_backend(cfg) -> str:
    """`auto`: fast unless TorchRL transforms are asked for; fast with them is a one-line error."""
    backend, extra = cfg.collector.backend, bool(cfg.env.transforms.extra)
    if backend == "auto":
        return "torchrl" if extra else "fast"
    if backend == "fast" and extra:
        raise ConfigError("env.transforms.extra needs collector.backend=torchrl (or auto): the fast collector "
                          "runs no TorchRL transform per step")
    return backend


def describe_backend(cfg) -> Tuple[str, str]:
    """(which collector runs, why): the start line says it."""
    c = cfg.collector
    path = resolve_backend(cfg)
    name = "FastCollector" if path == "fast" else "torchrl.Collector"
    if path == "fast":
        why = "no env.transforms.extra" if c.backend == "auto" else "collector.backend=fast"
    else:
        why = "env.transforms.extra runs per step" if c.backend == "auto" else "collector.backend=torchrl"
    if c.distributed == "ray":
        name = f"RayCollector({name} x {c.workers})"
    elif c.workers > 1:
        name = f"MultiSyncCollector({name} x {c.workers})"
    return name, why
