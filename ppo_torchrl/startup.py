"""The line a run prints when it starts: its real frame budget and what the config files changed.

`collector.total_frames` is rounded up to whole batches, and env files and presets (conf/env,
conf/experiment) change hyperparameters with only a comment to say so; this line says both.
"""

from __future__ import annotations

import math
from pathlib import Path

from omegaconf import OmegaConf

from ppo_torchrl.config import Config
from ppo_torchrl.envs import env_label

CONF_DIR = Path(__file__).resolve().parent.parent / "conf"
NOT_SHOWN = ("env.", "seed", "resume")  # the env is named anyway; the seed and resume dir are the user's


def frame_budget(cfg) -> tuple[int, int]:
    """(batches, frames): the loop runs whole batches, at least collector.total_frames frames."""
    batches = math.ceil(cfg.collector.total_frames / cfg.collector.frames_per_batch)
    return batches, batches * cfg.collector.frames_per_batch


def command_line() -> list[str]:
    """This run's command-line overrides, when Hydra runs it (none for a Trainer built in code)."""
    from hydra.core.hydra_config import HydraConfig

    return list(HydraConfig.get().overrides.task) if HydraConfig.initialized() else []


def describe_start(cfg, cli_overrides: list[str]) -> str:
    """`start: Hopper-v4, 489 batches x 2048 = 1,001,472 frames (collector.total_frames=1000000 rounded
    up); set by the env file/preset: policy.width=128, ...`: keys given on the command line are left out."""
    batches, frames = frame_budget(cfg)
    line = (f"start: {env_label(cfg.env)}, {batches} batch{'es' if batches != 1 else ''} x "
            f"{cfg.collector.frames_per_batch} = {frames:,} frames")
    if frames != cfg.collector.total_frames:
        line += f" (collector.total_frames={cfg.collector.total_frames} rounded up)"
    defaults = flatten(OmegaConf.to_container(OmegaConf.structured(Config)))
    users = user_values(cli_overrides)
    changed = [f"{key}={show(value)}" for key, value in flatten(OmegaConf.to_container(cfg, resolve=True)).items()
               if key in defaults and value != defaults[key] and not key.startswith(NOT_SHOWN)
               and not (key in users and users[key] in (value, None))]
    if not changed:
        return line + "; the env file/preset changes no defaults"
    return line + f"; set by the env file/preset: {', '.join(changed)}"


def user_values(cli_overrides: list[str]) -> dict:
    """Keys the command line set: `key=value` ones (value None: whatever it is), and those a group
    choice's file sets (`loss=a2c`: loss.epochs=1, ...), with that file's value."""
    users = {}
    for override in cli_overrides:
        key, _, option = override.lstrip("+~").partition("=")
        group_file = CONF_DIR / key / f"{option}.yaml"
        if "." not in key and "/" not in key and group_file.is_file():
            text = group_file.read_text()
            if "@package _global_" not in text:  # env files and presets are what the line describes
                node = OmegaConf.create(text)
                node.pop("defaults", None)
                users.update(flatten(OmegaConf.to_container(node), f"{key}."))
        else:
            users[key] = None
    return users


def flatten(node, prefix: str = "") -> dict:
    if not isinstance(node, dict):
        return {prefix.rstrip("."): node}
    return {k: v for key, value in node.items() for k, v in flatten(value, f"{prefix}{key}.").items()}


def show(value) -> str:
    """A value as it would be typed on the command line."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, list):
        return "[" + ",".join(show(v) for v in value) + "]"
    return str(value)


def describe_resume(run_dir, frames: int, cfg) -> str:
    return f"resumed {run_dir} at frame {frames:,} of {frame_budget(cfg)[1]:,}"
