"""An env config's values, checked one way for training (validation.validate_config) and for evaluate's
env.<key>=<value> on a run's saved config (evaluate.apply_overrides): every number finite, the robot's perturbation
scales where they mean something, env=legged given its model, and a refusal that names the key the user types."""

from __future__ import annotations

from omegaconf import OmegaConf

from ppo_torchrl.errors import ConfigError

# The robot's perturbation scales (env.legged.* / env.locomotion.*: a robustness sweep's grip halved, trunk 10% heavier):
# > 0 and at most these. A friction 10x a model's own is beyond any ground a robot meets; with a trunk 10x heavier Go1
# falls in every episode, its drives at their limit all the time (a result still). At 1e9 or inf the physics gave
# NaN, written as eval.json (issue 76); 0 or below means no grip or no trunk.
SCALE_LIMITS = {"friction_scale": 10.0, "trunk_mass_scale": 10.0}


def check_env(env) -> None:
    """An env config's values, checked one way for training (validate_config) and for evaluate's env.<key>=<value>
    on a run's saved config (evaluate.apply_overrides): every number finite (infinity only in a range), env=legged
    given its model (its checks need the robot: without one they named curriculum keys the user never typed), the
    perturbation scales in (0, SCALE_LIMITS], then the env's own checks (envs.env_checks), a refusal naming the key
    the user types (env.legged.<key> for a value env=legged derives from it). One ConfigError line."""
    from ppo_torchrl.envs.make import env_checks

    finite(OmegaConf.to_container(env, resolve=True), "env.")
    legged = env.get("legged")
    if legged is not None and not env.get("xml_file"):
        from ppo_torchrl.shipped import robots

        example = next((r for r in robots() if "go1" in r), robots()[0])
        raise ConfigError("env=legged reads its robot from a model file: give env.xml_file=<its scene.xml>, e.g. "
                          f"env.xml_file={example} (the shipped robots: {', '.join(robots())})")
    for node in ("legged", "locomotion"):
        values = env.get(node)
        for key, top in SCALE_LIMITS.items():
            value = values.get(key) if values is not None else None
            if value is not None and not 0 < value <= top:
                raise ConfigError(f"env.{node}.{key}={value} must be > 0 and at most {top:g} (x the model's own; "
                                  "the robustness sweeps use 0.5 for the grip and 1.1 for the trunk)")
    for ok, message in env_checks(env):
        if not ok:
            raise ConfigError(as_typed(env, message))


def as_typed(env, message: str) -> str:
    """A check's message on a value env=legged derives (env.locomotion.<key>, env.terrain.<key>), led by the
    env.legged key the user types (robots/recipe.py DERIVED); any other message as it is."""
    import re

    found = re.match(r"env\.(locomotion|terrain)\.(\w+)=", message)
    if env.get("legged") is None or found is None:
        return message
    from ppo_torchrl.robots.recipe import DERIVED

    source = DERIVED.get(found.group(1), {}).get(found.group(2))
    if source is None or source not in env.legged:
        return message
    return f"env.legged.{source}={env.legged[source]} is out of range ({message}, which env=legged derives from it)"


def finite(node, path: str) -> None:
    """check_finite's walk over plain data: `path` is the dotted prefix of `node` ('env.' for an env config)."""
    import math

    if isinstance(node, dict):
        for key, value in node.items():
            finite(value, f"{path}{key}.")
    elif isinstance(node, list):
        for value in node:
            finite(value, path)
    elif isinstance(node, float) and not math.isfinite(node):
        key = path.rstrip(".")
        if math.isnan(node) or not ("range" in key or key.startswith("env.make_kwargs")):
            raise ConfigError(f"{key}={node} must be a finite number")
