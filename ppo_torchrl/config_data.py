"""A config is data: what the app reads back from disk is never resolved into a call, and what it builds from a
config is checked before anything is called.

Two doors, one rule each:
- **Configs read back** (a checkpoint's saved config, a run dir's `config.yaml`, `.hydra/*.yaml`, a sweep's
  `overrides.yaml`) are plain data: YAML read by OmegaConf's safe loader (no tags, no objects), never resolved, and checked by `plain`,
  which refuses an OmegaConf interpolation (`${...}`) anywhere in them. The trainer saves its config resolved,
  so a saved config never holds one; one that does was edited, and resolving it would reach into this process
  (`${oc.env:...}`, a resolver) with values nobody typed. Nothing of it is resolved.
- **Objects built from a config** (`env.transforms.extra`, the one place the app builds a class named in a
  config): `transform_entry` allows a `_target_` only where it names one of `DATA_TRANSFORMS` by its public
  path (`torchrl.envs.<Name>` or `torchrl.envs.transforms.<Name>`), looked up on TorchRL's transforms module
  (no other module is imported), with arguments that are plain data (no nested `_target_`, no `_partial_`).
  The list holds TorchRL's transforms of an env's tensors whose arguments are data; it leaves out those that
  load weights or tokenizers (R3M, VIP, VC1, Tokenizer), start services (RayTransform) or take a callable. The
  same rule holds for the user's command line and a saved config, so a checkpoint can name only what a user
  could have asked for, and never `torch.load`, `pathlib.Path.unlink` or `builtins.open`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ppo_torchrl.errors import ConfigError

INTERPOLATION = "${"
DATA_TRANSFORMS = (
    "ActionScaling", "BinarizeReward", "CatFrames", "CatTensors", "ClipTransform", "DTypeCastTransform",
    "DoubleToFloat", "ExcludeTransform", "FiniteTensorDictCheck", "FlattenObservation", "FrameSkipTransform",
    "InitTracker", "LineariseRewards", "NoopResetEnv", "ObservationNorm", "PermuteTransform", "RenameTransform",
    "RewardClipping", "RewardScaling", "RewardSum", "SelectTransform", "SignTransform", "SqueezeTransform",
    "StepCounter", "TargetReturn", "TimeMaxPool", "TrajCounter", "UnsqueezeTransform", "VecNorm", "gSDENoise",
)
PUBLIC_PATHS = ("torchrl.envs.transforms.", "torchrl.envs.")  # the longer first
HYDRA_KEYS = ("_target_", "_args_", "_convert_", "_recursive_", "_partial_")


def plain(data: Any, where: str, path: str = "") -> Any:
    """`data` as it is, once checked to be plain data without an interpolation (module doc); ConfigError naming
    the key otherwise."""
    if isinstance(data, str):
        if INTERPOLATION in data:
            raise ConfigError(f"{where}: {path or 'its value'}={data!r} is an interpolation; a saved config is data "
                              "(the trainer saves it resolved), and nothing read back from disk is resolved")
    elif isinstance(data, dict):
        for key, value in data.items():
            if not isinstance(key, (str, int)):
                raise ConfigError(f"{where}: a key of {path or 'the config'} is a {type(key).__name__}, not a name")
            plain(value, where, f"{path}.{key}" if path else str(key))
    elif isinstance(data, (list, tuple)):
        for i, value in enumerate(data):
            plain(value, where, f"{path}[{i}]")
    elif data is not None and not isinstance(data, (bool, int, float)):
        raise ConfigError(f"{where}: {path or 'its value'} is a {type(data).__name__}, not plain data")
    return data


def read_yaml(path: Path | str, within: tuple = (), as_text: bool = False) -> Any:
    """A YAML file of the app's (config.yaml, .hydra/*.yaml) as plain data, checked by `plain`; within: the keys
    of the one part to read (Hydra's hydra.yaml keeps its own interpolations, which nothing here reads). OSError or
    yaml.YAMLError where it cannot be read, KeyError or TypeError where it has no such part, ConfigError where it is
    not plain data. as_text: an interpolation is kept as the text it is, for values only compared, never made into a
    config (a sweep job's overrides)."""
    from omegaconf import OmegaConf

    loaded = OmegaConf.load(path)  # OmegaConf's YAML loader: a SafeLoader (no tags, no objects), floats as YAML 1.2
    data = OmegaConf.to_container(loaded, resolve=False)  # nothing resolved: interpolations stay text
    for key in within:
        data = data[key]
    return data if as_text else plain(data, str(path), ".".join(within))


def read_config(path: Path | str):
    """A run dir's config.yaml as an OmegaConf config, from data that `read_yaml` checked (nothing to resolve)."""
    from omegaconf import OmegaConf

    return OmegaConf.create(read_yaml(path))


def transform_entry(entry, where: str) -> tuple:
    """(the TorchRL transform class an env.transforms.extra entry names, its positional arguments, its keyword
    arguments), checked as the module doc says before anything is built; ConfigError otherwise."""
    from omegaconf import OmegaConf

    data = OmegaConf.to_container(entry, resolve=True) if OmegaConf.is_config(entry) else entry
    example = "{_target_: torchrl.envs.CatFrames, N: 3, dim: -1, in_keys: [observation]}"
    if not isinstance(data, dict) or not data.get("_target_"):
        raise ConfigError(f"{where}={data} needs a _target_ naming a TorchRL transform class, e.g. {example}")
    target = data["_target_"]
    name = next((str(target)[len(p):] for p in PUBLIC_PATHS if str(target).startswith(p)), None)
    if not isinstance(target, str) or name not in DATA_TRANSFORMS:
        raise ConfigError(f"{where}: _target_={target} is not a TorchRL transform this app builds; use one of "
                          f"torchrl.envs.{{{', '.join(DATA_TRANSFORMS)}}} (config_data.py says why no other)")
    if data.get("_partial_"):
        raise ConfigError(f"{where} ({target}): _partial_ is not taken; the entry builds the transform itself")
    arguments = {k: v for k, v in data.items() if k not in HYDRA_KEYS}
    args = data.get("_args_") or []
    for key, value in {**arguments, "_args_": args}.items():
        if _has_target(value):
            raise ConfigError(f"{where} ({target}): {key} holds a _target_; a transform's arguments are plain data")
        plain(value, where, key)
    import torchrl.envs.transforms as transforms

    return getattr(transforms, name), list(args), arguments


def _has_target(value) -> bool:
    if isinstance(value, dict):
        return "_target_" in value or any(_has_target(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_has_target(v) for v in value)
    return False
