"""The config as Hydra will compose it, before Hydra runs (the training command checks a whole command
first: __main__.prepare): the conf/ dir, the resolver that names run dirs, composition with a bad
override as one line (and the closest key for one the config lacks), `--cfg job` without the keys the
chosen env, loss and advantage do not read.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ppo_torchrl.conf_files import CONF_DIR
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.overrides import key_hint


def run_name(experiment, env_choice, env_id, xml_file) -> str:
    """What a run dir is named by (conf/config.yaml: hydra.run.dir): the preset, else the env file
    (quadruped_step), else for env=gym the id; a model file given to env=mjcf adds its stem, to env=legged
    (or a scene.xml to env=mjcf) the model's name (legged_trot_go1, go1: not scene)."""
    robot = None
    if xml_file and env_choice == "mjcf" and Path(str(xml_file)).stem != "scene":
        robot = Path(str(xml_file)).stem
    elif xml_file and env_choice in ("mjcf", "legged"):
        from ppo_torchrl.envs.make import resolve_model_file
        from ppo_torchrl.robots.model import robot_label

        try:
            robot = robot_label(resolve_model_file(str(xml_file)))
        except ConfigError:  # no such file: the config check says so, with its reason
            robot = Path(str(xml_file)).stem
    if experiment is not None:
        return f"{experiment}_{robot}" if robot and env_choice == "legged" else str(experiment)
    if env_choice in ("gym", "playground"):  # MuJoCoPlayground/<task>-v1, EnvPool's alias: the task's name
        return str(env_id).rpartition("/")[2]
    return robot or str(env_choice)


def register_resolvers() -> None:
    from omegaconf import OmegaConf

    import ppo_torchrl.config  # noqa: F401  (registers the schemas and their resolvers)

    OmegaConf.register_new_resolver("ppo.run_name", run_name, replace=True)


def compose(overrides: list[str], with_hydra: bool = False):
    """The config as Hydra will compose it (with its hydra node: launcher, sweeper, dirs, if asked);
    a bad override is one line, not Hydra's report."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    register_resolvers()

    if not with_hydra:
        overrides = [a for a in overrides if not a.lstrip("+~").startswith(("hydra.", "hydra/"))]
    try:
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            return hydra_compose(config_name="config", overrides=overrides, return_hydra_config=with_hydra)
    except (HydraException, OmegaConfBaseException) as exc:
        raise ConfigError(one_line(exc) + unknown_key_hint(exc, overrides)) from exc


def unknown_key_hint(exc: BaseException, overrides: list[str]) -> str:
    """`; did you mean collector.total_frames?` for a key the config does not have."""
    import re

    found = re.search(r"override '([^']+)'", str(exc)) or re.search(r"Key '([^']+)' (?:is )?not in", str(exc))
    if not found:
        return ""
    groups = [o for o in overrides if "=" in o and "." not in o.partition("=")[0] and "/" not in o
              and o.partition("=")[0].lstrip("+~") != found.group(1)]  # total_timesteps=1e6 is no group's choice
    if groups == overrides:  # the groups alone failed: nothing to compare the key with
        return ""
    try:
        return key_hint(found.group(1), compose(groups))
    except ConfigError:
        return ""


def hydra_value(cfg, key: str):
    """A value of the composed hydra node (e.g. hydra.run.dir); an interpolation that fails is one line."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        return OmegaConf.select(cfg, key, throw_on_missing=True)
    except OmegaConfBaseException as exc:
        raise ConfigError(f"{key}: {str(exc).splitlines()[0]}; fix the value given to {key}") from None


def show_job(job: list[str], resolve: bool) -> None:
    """`--cfg job`: the composed config as Hydra prints it, less the keys the chosen env, loss and advantage
    do not read (a first comment line names them); then exit 0."""
    from omegaconf import OmegaConf, open_dict, read_write
    from omegaconf.errors import OmegaConfBaseException

    from ppo_torchrl.run.startup import not_applicable

    cfg = compose(job)
    hidden = not_applicable(cfg)
    for key in hidden:
        parent, _, leaf = key.rpartition(".")
        node = OmegaConf.select(cfg, parent)
        with read_write(node), open_dict(node):
            del node[leaf]
    names = ", ".join(f"{key}.*" if key.startswith("env.") else key for key in hidden)
    try:
        text = OmegaConf.to_yaml(cfg, resolve=resolve)
    except OmegaConfBaseException as exc:  # an interpolation that fails with --resolve
        raise ConfigError(one_line(exc)) from exc
    left_out = f"# left out, as this env, loss and advantage do not read them: {names}\n" if hidden else ""
    sys.stdout.write(left_out + text)  # one write: a reader that stops early (| head) gets no broken pipe mid-way
    raise SystemExit(0)


def one_line(exc: BaseException) -> str:
    """Hydra's multi-line messages, folded: what failed, then the first line of why."""
    lines = [l.strip() for l in str(exc).splitlines() if l.strip()]
    head, options = [], []
    for line in lines:
        if line.startswith("Config search path"):
            break  # where Hydra looked: noise to a user
        (options if options or line.startswith("Available options") else head).append(line)
    message = head[0].rstrip(".") if head else type(exc).__name__
    cause = exc.__cause__
    if cause is not None and str(cause).strip():
        message += f": {str(cause).strip().splitlines()[0]}"
        key = getattr(cause, "full_key", None)
        if key and key not in message:
            message += f" (key '{key}')"
    elif len(head) > 1 and "append" not in head[1]:
        message += f": {head[1]}"
    if options:
        message += f". {options[0].rstrip(':')}: {', '.join(options[1:])}"
    return message
