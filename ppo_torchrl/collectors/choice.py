"""Which TorchRL collector class a config runs, and why (the start line says it).

A new collector class is registered here (`BACKENDS`); collection.py runs whatever is registered (its
docstring states the contract)."""

from __future__ import annotations

from typing import Tuple

from ppo_torchrl.errors import ConfigError

# collector.backend -> (module, class, the policy it steps: "actor" (it reads the actor's net, distribution and
# bounds) or "sampling" (models.sampling_policy: the lean draw), the name the start line gives it)
BACKENDS = {"fast": ("ppo_torchrl.collectors.fast", "FastCollector", "actor", "FastCollector"),
            "torchrl": ("ppo_torchrl.collectors.torchrl_path", "TorchRLCollector", "sampling", "torchrl.Collector"),
            "envpool": ("ppo_torchrl.collectors.envpool_backend", "EnvpoolCollector", "actor", "EnvpoolCollector"),
            "playground": ("ppo_torchrl.collectors.playground", "PlaygroundCollector", "actor", "PlaygroundCollector")}
CHOICES = ("auto", *BACKENDS)  # collector.backend
# TorchRL's Collector against FastCollector, whole-process frames/s on Hopper-v4 by collector.num_envs
# (benchmarks/speed.py --backends fast,torchrl --envs 1,8,16: results/speed/torchrl_path_2026-11-27.txt):
# its per-step transforms cost less per frame as one batched env steps more envs
TORCHRL_PATH_SHARE = {1: 0.42, 8: 0.72, 16: 0.93}


def resolve_backend(cfg) -> str:
    """`auto`: fast unless TorchRL transforms are asked for; fast with them is a one-line error. env=playground:
    the playground collector (EnvPool's pool stepped whole: collectors/playground.py), the one it runs on."""
    backend, extra = cfg.collector.backend, bool(cfg.env.transforms.extra)
    if cfg.env.get("playground") is not None or backend == "playground":
        from ppo_torchrl.collectors.playground import check_playground

        check_playground(cfg)
        return "playground"
    if backend == "auto":
        return "torchrl" if extra else "fast"
    if backend == "envpool":  # an option: C++ env steps (collectors/envpool_backend.py)
        from ppo_torchrl.collectors.envpool_backend import check_envpool

        check_envpool(cfg)
    if backend == "fast" and extra:
        raise ConfigError("env.transforms.extra needs collector.backend=torchrl (or auto): the fast collector "
                          "runs no TorchRL transform per step")
    return backend


def describe_backend(cfg) -> Tuple[str, str]:
    """(which collector runs, why): the start line says it."""
    c = cfg.collector
    path = resolve_backend(cfg)
    name = BACKENDS[path][3]
    if path == "fast":
        why = "no env.transforms.extra" if c.backend == "auto" else "collector.backend=fast"
    elif path == "envpool":
        why = "collector.backend=envpool: the envs stepped in C++ by EnvPool"
    elif path == "playground":
        why = "env=playground: one EnvPool of collector.num_envs envs stepped in C++"
    else:
        why = "env.transforms.extra runs per step" if c.backend == "auto" else "collector.backend=torchrl"
        measured = max([n for n in TORCHRL_PATH_SHARE if n <= c.num_envs] or [1])
        why += (f"; at collector.num_envs={c.num_envs} ~{TORCHRL_PATH_SHARE[measured]:.0%} of the fast collector's "
                f"frames/s (measured at {measured} env{'s' if measured > 1 else ''} on Hopper, docs/speed.md): more "
                "envs per process amortize its per-step transforms")
    if c.distributed == "ray":
        name = f"RayCollector({name} x {c.workers})"
    elif c.workers > 1:
        name = f"MultiSyncCollector({name} x {c.workers})"
    return name, why


def collector_class(backend: str) -> Tuple[type, str]:
    """The collector class of a (resolved) backend and the policy it steps ("actor" or "sampling")."""
    import importlib

    module, name, policy, _ = BACKENDS[backend]
    return getattr(importlib.import_module(module), name), policy
