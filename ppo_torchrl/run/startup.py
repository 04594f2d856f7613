"""The line a run prints when it starts: its real frame budget and what the config files changed.

`collector.total_frames` is rounded up to whole batches, and env files and presets (conf/env,
conf/experiment) change hyperparameters with only a comment to say so; this line says both.
"""

from __future__ import annotations

import math
from pathlib import Path

from omegaconf import OmegaConf

from ppo_torchrl.collectors.choice import describe_backend
from ppo_torchrl.conf_files import CONF_DIR
from ppo_torchrl.config import Config
from ppo_torchrl.envs.make import MJCF_ID, env_label
from ppo_torchrl.run.loggers import job_tag

NOT_SHOWN = ("env.", "seed", "resume")  # the env is named anyway; the seed and resume dir are the user's
# loss.<key>: the losses that read it (losses.py); every loss reads the others
POLICY_GRADIENT = ("clip_ppo", "kl_ppo", "ppo", "a2c")  # reinforce has no entropy bonus nor critic coefficient
LOSS_KEYS = {"clip_epsilon": ("clip_ppo",), "kl_target": ("kl_ppo",), "kl_beta": ("kl_ppo",),
             "entropy_coef": POLICY_GRADIENT, "entropy_samples": POLICY_GRADIENT, "critic_coef": POLICY_GRADIENT}


def not_applicable(cfg) -> list[str]:
    """Keys (or whole nodes) of the config that the chosen env, loss and advantage do not read: env.locomotion
    and env.terrain on an env without a model file (only MJCF robots read them), loss keys of other losses,
    advantage.lmbda without GAE. Every config still has them (checkpoints hold the whole config)."""
    mjcf = cfg.env.get("xml_file") or OmegaConf.select(cfg, "env.id", throw_on_missing=False) == MJCF_ID
    hidden = [] if mjcf else ["env.locomotion", "env.terrain"]
    hidden += [f"loss.{key}" for key, losses in LOSS_KEYS.items() if cfg.loss.name not in losses]
    return hidden + (["advantage.lmbda"] if cfg.advantage.name != "gae" else [])


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
    up); collector: FastCollector (no env.transforms.extra); set by the env file/preset: policy.width=128, ...`:
    keys given on the command line are left out."""
    batches, frames = frame_budget(cfg)
    line = (f"start: {env_label(cfg.env)}, {batches} batch{'es' if batches != 1 else ''} x "
            f"{cfg.collector.frames_per_batch} = {frames:,} frames")
    if frames != cfg.collector.total_frames:
        line += f" (collector.total_frames={cfg.collector.total_frames} rounded up)"
    collector, why = describe_backend(cfg)
    line += f"; collector: {collector} ({why})"
    if str(cfg.device) == "auto":  # what auto picked, said once
        line += f"; {auto_device()}"
    defaults = flatten(OmegaConf.to_container(OmegaConf.structured(Config)))
    users = user_values(cli_overrides)
    unread = tuple(not_applicable(cfg))
    changed = [f"{key}={show(value)}" for key, value in flatten(OmegaConf.to_container(cfg, resolve=True)).items()
               if key in defaults and value != defaults[key] and not key.startswith(NOT_SHOWN)
               and not (key in users and users[key] in (value, None)) and key not in unread]
    line += "; the env file/preset changes no defaults" if not changed else f"; set by the env file/preset: {', '.join(changed)}"
    return job_tag() + line + robot_line(cfg.env)


def auto_device() -> str:
    """`device=auto: cpu (no CUDA device)` or `device=auto: cuda (<its name>)`: what device=auto picked."""
    import torch

    from ppo_torchrl.validation import resolve_device

    device = resolve_device("auto")
    why = torch.cuda.get_device_name(device) if device.type == "cuda" else "no CUDA device"
    return f"device=auto: {device.type} ({why})"


def robot_line(env_cfg) -> str:
    """env=legged: a second line, what was read from the robot's model and what the recipe asks of it."""
    if env_cfg.get("legged") is None or not env_cfg.get("xml_file"):
        return ""
    from ppo_torchrl.envs.make import resolve_model_file
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import describe

    return "\n" + describe(read_robot(resolve_model_file(env_cfg.xml_file), env_cfg.legged.keyframe), env_cfg.legged)


def user_values(cli_overrides: list[str]) -> dict:
    """Keys the command line set: `key=value` ones (value None: whatever it is), and those a group
    choice's file sets (`loss=a2c`: loss.epochs=1, ...), with that file's value."""
    users = {}
    for override in cli_overrides:
        key, _, option = override.lstrip("+~").partition("=")
        group_file = Path(CONF_DIR) / key / f"{option}.yaml"
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
    limit = ""
    if cfg.env.get("playground") is not None:
        from ppo_torchrl.collectors.playground import RESUME_LIMIT

        limit = f" ({RESUME_LIMIT})"
    elif cfg.collector.backend == "envpool":
        from ppo_torchrl.collectors.envpool_backend import RESUME_LIMIT

        limit = f" ({RESUME_LIMIT})"
    return f"resumed {run_dir} at frame {frames:,} of {frame_budget(cfg)[1]:,}{limit}"


def duration(seconds: float) -> str:
    """14 s, 3 min 20 s, 2 h 05 min."""
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"


def describe_end(summary: dict, next_steps: bool = True) -> str:
    """What a finished run prints last: one line (frames, wall time, final and best eval, where the files
    are), then the commands to paste next (watch it, plot it, train it on); a sweep's job prints the line only."""
    import shlex

    from ppo_torchrl.cli import python_command, shown_path

    run_dir, ev = shown_path(summary["run_dir"]), summary.get("eval_return_mean")
    if ev is not None:
        result = f"final eval {ev:.1f} +- {summary.get('eval_return_std') or 0.0:.1f}"
        if summary.get("best_eval_return") is not None:
            result += f", best {summary['best_eval_return']:.1f}"
    elif summary.get("train_return_last100") is not None:
        result = f"no eval; train return (last 100 episodes) {summary['train_return_last100']:.1f}"
    else:
        result = "no eval, no finished episode"
    line = (f"{job_tag()}done: {summary['env']}, {summary['frames']:,} frames in {duration(summary['wall_s'])}; "
            f"{result}; files in {run_dir}")
    if not next_steps:
        return line
    python, more = python_command(), 2 * summary["frames"]
    return "\n".join([
        line, f"next: watch the best checkpoint, plot the run, train it on to {more:,} frames:",
        f"  {python} -m ppo_torchrl.evaluate {shlex.quote(f'run={run_dir}')} video=true",
        f"  {python} -m ppo_torchrl.report {shlex.quote(run_dir)}",
        f"  {python} -m ppo_torchrl {shlex.quote(f'resume={run_dir}')} collector.total_frames={more}"])
