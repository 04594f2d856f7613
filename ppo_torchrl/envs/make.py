"""Environments: checking an id, the raw Gymnasium env, and the TorchRL `TransformedEnv`.

- `make_gym_env` gives the real Gymnasium MuJoCo env; `make_batch` the batched env of a robot read from its model
  file (env=legged, env=mjcf, the in-house quadruped presets: tasks/locomotion/batch.py);
- `make_torchrl_env` gives `TransformedEnv(GymWrapper(...))` with the transforms: the one env of every
  path (TorchRL's Collector steps it, the fast collector steps its Gymnasium envs with its transforms'
  statistics, evaluation runs it with frozen statistics).
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Sequence

import gymnasium as gym
import numpy as np
import torch
from omegaconf import OmegaConf
from torchrl.envs import Compose, GymWrapper, Transform, TransformedEnv

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.envs.normalization import (
    ObservationNormalization,
    RewardNormalization,
    make_observation_normalizer,
    make_reward_normalizer,
)
from ppo_torchrl.envs.rows import BatchRows, GymRows
from ppo_torchrl.envs.state import EnvState
from ppo_torchrl.envs.layout import OBS_FRAMES, OBS_LAYOUTS, privileged_layout_of
from ppo_torchrl.envs.mjcf import FLOOR_DRAWN_M, MjcfInfo, check_mjcf, floor_to_the_horizon  # noqa: F401 (their home)
from ppo_torchrl.envs.positions import resumable

# Gymnasium's v4 MuJoCo envs warn on every make that v5 exists; the warning is not actionable here.
warnings.filterwarnings("ignore", message=".*is out of date.*")
warnings.filterwarnings("ignore", category=DeprecationWarning, module="gymnasium")

ASSETS_DIR = Path(__file__).resolve().parent.parent / "assets"
MJCF_ID = "mjcf"  # env.id of a robot given by its model file (env=mjcf env.xml_file=...)
MJCF_ENV_ID = "Ant-v5"  # Gymnasium's locomotion class that runs it: it takes any model through xml_file
# env.terrain keys that do something (the rest only tune these)
TERRAIN_KNOBS = ("step_height", "step_height_range", "curriculum", "step_distance", "eval_step_height",
                 "observe_contacts", "height_samples")
TRACKING_CAMERA = "track"  # videos use a model camera of this name when there is one (it can follow the robot)


@dataclass
class EnvSpec:
    """The shapes and bounds the models and checkpoints depend on; `env`: the Gymnasium env they were read from,
    kept open for the training env to step (env_spec(keep_env=True)), handed over once by `take_env`."""

    obs_dim: int
    action_dim: int
    action_low: np.ndarray
    action_high: np.ndarray
    env: Any = field(default=None, compare=False, repr=False)
    privileged_dim: Optional[int] = None  # the env's privileged observation (layout.privileged_layout_of), if any

    def take_env(self):
        env, self.env = self.env, None
        return env

    def close(self) -> None:
        env = self.take_env()
        if env is not None:
            env.close()


def check_env_id(env_id: str) -> None:
    """Fail with one line unless `env_id` is a registered continuous-control Gymnasium env (or mjcf)."""
    if env_id not in gym.registry and env_id != MJCF_ID:
        from ppo_torchrl.envs.playground import playground_hint

        from ppo_torchrl.conf_files import env_files

        known = ", ".join(n for n in env_files() if n != "gym")
        raise ConfigError(
            f"unknown environment id '{env_id}': not registered in Gymnasium{playground_hint(env_id)}. "
            f"Env files: {known}. Any other registered id: env=gym env.id=<id>"
        )


def env_label(env_cfg) -> str:
    """How runs name their env: the id; with a model file, legged:<the model's name> for env=legged
    (legged:go1), else mjcf:<the file's name> (mjcf:quadruped.xml), a Menagerie scene.xml by the model's name."""
    xml_file = env_cfg.get("xml_file")
    if not xml_file:
        return str(env_cfg.get("id"))
    name = Path(str(xml_file)).name
    if env_cfg.get("legged") is not None or Path(name).stem == "scene":
        from ppo_torchrl.robots.model import robot_label

        try:
            name = robot_label(resolve_model_file(str(xml_file)))
        except ConfigError:
            pass
    return f"{'legged' if env_cfg.get('legged') is not None else env_cfg.get('id')}:{name}"


def resolve_model_file(xml_file: str) -> Path:
    """A path as given (absolute or from the working dir), else a model shipped in assets/ (`menagerie/unitree_go1/
    scene.xml`), else the shipped Menagerie model of the path's last folder and file name."""
    path = Path(xml_file).expanduser()
    if path.is_file():
        return path.resolve()
    if (ASSETS_DIR / xml_file).is_file():
        return ASSETS_DIR / xml_file
    moved = ASSETS_DIR / "menagerie" / path.parent.name / path.name
    if path.parent.name and moved.is_file():  # a run recorded before the Menagerie robots came into the package,
        return moved  # e.g. .../shared/robots/unitree_go1/scene.xml: the same file (results/README.md)
    from ppo_torchrl.shipped import models_hint  # the six Menagerie robots first (issue 76)

    raise ConfigError(f"env.xml_file={xml_file}: no such file (a path, or {models_hint()})")


def _scaled_for_checks(env_cfg):
    """The env config whose locomotion and terrain values are checked: env=legged's scaled to its robot
    (read from env.xml_file: a model that cannot be read is one line here), any other as it is."""
    if env_cfg.get("legged") is None or not env_cfg.get("xml_file"):
        return env_cfg
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import scaled_env

    return scaled_env(env_cfg, read_robot(resolve_model_file(env_cfg.xml_file), env_cfg.legged.keyframe))


def env_checks(env_cfg) -> list:
    """env.legged's checks, then the locomotion and terrain checks on the values its recipe gives the robot
    (env=legged; any other env's as they are): training and evaluate's env.<key>=<value> check one way (a
    legged run's saved config leaves the derived keys, such as the curriculum's height range, to the recipe)."""
    from ppo_torchrl.robots.recipe import legged_checks
    from ppo_torchrl.tasks.locomotion.checks import locomotion_checks
    from ppo_torchrl.tasks.locomotion.terrain import terrain_checks

    legged = legged_checks(env_cfg.get("legged"))
    if not all(ok for ok, _ in legged):  # the recipe cannot scale bad targets
        return legged
    scaled = _scaled_for_checks(env_cfg)
    return legged + locomotion_checks(scaled.locomotion) + terrain_checks(scaled.get("terrain"))


# env.locomotion's keys that are Gymnasium Ant-v5's own arguments (mjcf_kwargs passes them at the top level)
ANT_KEYS = ("forward_reward_weight", "healthy_reward", "healthy_z_range", "terminate_when_unhealthy",
            "ctrl_cost_weight", "contact_cost_weight", "frame_skip", "reset_noise_scale", "main_body",
            "contact_forces_in_observation")


def mjcf_kwargs(env_cfg) -> dict:
    """gymnasium.make kwargs that turn Ant-v5 into the locomotion env of env.xml_file."""
    if env_cfg.id not in (MJCF_ID, MJCF_ENV_ID):
        raise ConfigError(f"env.xml_file needs env=mjcf (or env.id={MJCF_ENV_ID}), not env.id={env_cfg.id}")
    path = resolve_model_file(env_cfg.xml_file)
    info = check_mjcf(path)
    robot = None
    if env_cfg.get("legged") is not None:  # env=legged: the robot read from its model, the recipe scaled to it
        from ppo_torchrl.robots.model import read_robot
        from ppo_torchrl.robots.recipe import scaled_env

        env_cfg = scaled_env(env_cfg, read_robot(path, env_cfg.legged.keyframe))
        robot = {"keyframe": env_cfg.legged.keyframe, "action_scale": env_cfg.legged.action_scale,
                 "saturation_cap": env_cfg.legged.get("saturation_cap", True),
                 "obs_layout": env_cfg.legged.get("obs_layout", OBS_LAYOUTS[0]),
                 "obs_frame": env_cfg.legged.get("obs_frame", OBS_FRAMES[0])}
    loco = env_cfg.locomotion
    low, high = loco.healthy_z_range
    if not low < high:
        raise ConfigError(f"env.locomotion.healthy_z_range={list(loco.healthy_z_range)} must be [low, high] with low < high")
    main_body = int(loco.main_body) if str(loco.main_body).isdigit() else str(loco.main_body)
    if not (0 < main_body < len(info.bodies) if isinstance(main_body, int) else main_body in info.bodies):
        named = ", ".join(b for b in info.bodies[1:6] if b)
        raise ConfigError(f"env.locomotion.main_body={loco.main_body} is not a body of {path.name} "
                          f"(a body name, e.g. {named}, or an id in 1..{len(info.bodies) - 1})")
    kwargs = {"camera_name": TRACKING_CAMERA} if TRACKING_CAMERA in info.cameras else {}
    return {
        **kwargs,
        # every env.locomotion key but Ant-v5's own (below): heading, actuator limits, each reward term's weight (a
        # new term's key reaches the task with no list to extend: tasks/locomotion/rewards.py)
        "legged": {key: _plain(loco.get(key)) for key in loco if key not in ANT_KEYS},
        "terrain": _plain(env_cfg.get("terrain")) or {},
        "xml_file": str(path),
        "forward_reward_weight": loco.forward_reward_weight,
        "healthy_reward": loco.healthy_reward,
        "healthy_z_range": (low, high),
        "terminate_when_unhealthy": loco.terminate_when_unhealthy,
        "ctrl_cost_weight": loco.ctrl_cost_weight,
        "contact_cost_weight": loco.contact_cost_weight,
        "frame_skip": loco.frame_skip,
        "reset_noise_scale": loco.reset_noise_scale,
        "main_body": main_body,
        "include_cfrc_ext_in_observation": loco.contact_forces_in_observation,
        **({"robot": robot} if robot is not None else {}),
    }


def _plain(value):
    """An OmegaConf node or a config dataclass as plain Python (dicts, lists), anything else as is."""
    import dataclasses

    from omegaconf import OmegaConf

    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    return OmegaConf.to_container(value, resolve=True) if OmegaConf.is_config(value) else value


def gym_make_kwargs(env_cfg, render_mode: Optional[str] = None, evaluation: bool = False, **render_kwargs) -> dict:
    """What `gymnasium.make(env.id, ...)` gets: the MJCF model and knobs, time limit, make_kwargs.
    evaluation: an eval env (terrain: env.terrain.eval_step_height, no curriculum)."""
    check_env_id(env_cfg.id)
    if env_cfg.id == MJCF_ID and not env_cfg.get("xml_file"):
        which = "env=legged" if env_cfg.get("legged") is not None else "env=mjcf"
        raise ConfigError(f"{which} needs the robot's model file: env.xml_file=<path to an MJCF file with a free joint>, "
                          "e.g. a MuJoCo Menagerie robot's scene.xml")
    kwargs = mjcf_kwargs(env_cfg) if env_cfg.get("xml_file") else {}
    if kwargs:
        kwargs["evaluation"] = evaluation
    else:
        from ppo_torchrl.config import LocomotionConfig, TerrainConfig

        terrain, default = env_cfg.get("terrain") or {}, TerrainConfig()
        changed = [f"terrain.{k}" for k in terrain if k in TERRAIN_KNOBS and _plain(terrain[k]) != getattr(default, k)]
        loco, loco_default = env_cfg.get("locomotion") or {}, LocomotionConfig()
        changed += [f"locomotion.{k}" for k in loco if _plain(loco[k]) != _plain(getattr(loco_default, k, None))]
        changed += ["legged"] if env_cfg.get("legged") is not None else []
        if changed:  # a key this env does not read is refused, never ignored
            raise ConfigError(f"env.{changed[0]} works on MJCF robots (env=mjcf, env=legged, env=quadruped_step), "
                              f"not env.id={env_cfg.id}")
    kwargs.update(env_cfg.make_kwargs or {})
    if env_cfg.max_episode_steps is not None:
        kwargs["max_episode_steps"] = env_cfg.max_episode_steps
    if render_mode is not None:
        if not env_cfg.get("xml_file") and not {"camera_id", "camera_name", "default_camera_config"} & kwargs.keys():
            kwargs.update(tracking_camera(env_cfg.id))
        kwargs.update(render_mode=render_mode, **render_kwargs)
    return kwargs


def tracking_camera(env_id: str) -> dict:
    """The gym.make kwargs of a video that follows the robot. Gymnasium's MuJoCo models carry a `track` camera
    on the torso in trackcom mode (Hopper, Walker2d, HalfCheetah, Ant, Humanoid), but Gymnasium 1.x renders from
    a free camera that stays where the episode began unless the camera is named. A MuJoCo env without one falls
    back to that free camera; other envs take no camera. (MJCF robots: tasks/locomotion/filming.py adds `track` when
    missing.)"""
    from gymnasium.envs.registration import load_env_creator

    try:
        from gymnasium.envs.mujoco.mujoco_env import MujocoEnv
    except ImportError:  # no mujoco: no MuJoCo env to film
        return {}
    entry = gym.spec(env_id).entry_point
    creator = load_env_creator(entry) if isinstance(entry, str) else entry
    return {"camera_name": TRACKING_CAMERA} if isinstance(creator, type) and issubclass(creator, MujocoEnv) else {}


def make_gym_env(env_cfg, render_mode: Optional[str] = None, evaluation: bool = False, **render_kwargs) -> gym.Env:
    if env_cfg.get("playground") is not None:  # env=playground: a MuJoCo Playground task stepped by EnvPool
        from ppo_torchrl.envs.playground import make_playground_env

        return make_playground_env(env_cfg, render_mode, **render_kwargs)
    if batched(env_cfg):  # a robot of a model file is a batch of rows (tasks/locomotion/batch.py), never one env
        raise ValueError(f"env {env_label(env_cfg)} is a batched env: envs.make_batch(env_cfg, num_envs) builds it")
    kwargs = gym_make_kwargs(env_cfg, render_mode, evaluation, **render_kwargs)
    env_id = env_cfg.id
    # The passive checker re-validates every step; the id is checked once above instead.
    try:
        env = gym.make(env_id, disable_env_checker=True, **kwargs)
    except ConfigError:
        raise
    except (gym.error.Error, ImportError, TypeError, ValueError) as exc:  # a missing extra, a bad make_kwargs
        first = next((l.strip() for l in str(exc).splitlines() if l.strip()), "")
        raise ConfigError(f"cannot make env '{env_cfg.id}': {type(exc).__name__}: {first}") from None
    if render_mode is not None:
        floor_to_the_horizon(env.unwrapped)
    if not isinstance(env.action_space, gym.spaces.Box):
        raise ConfigError(
            f"env '{env_cfg.id}' has a {type(env.action_space).__name__} action space; "
            "ppo_torchrl trains continuous-control (Box) envs only"
        )
    if len(env.observation_space.shape) != 1:
        raise ConfigError(f"env '{env_cfg.id}' has observations of shape {env.observation_space.shape}; a flat vector is required")
    if env.observation_space.dtype != np.float64:  # the env boundary: every path (training, eval, export)
        with np.errstate(over="ignore"):  # gymnasium's Box compares the float32 bounds in float64: no overflow here
            env = gym.wrappers.DtypeObservation(env, np.float64)  # sees float64 observations, as MuJoCo's envs give
    return env


def extra_transforms(env_cfg) -> list:
    """env.transforms.extra, built: each entry names one of TorchRL's data transforms, checked before anything is
    called (config_data.transform_entry: no other class, no nested _target_, arguments plain data)."""
    from ppo_torchrl.config_data import transform_entry

    built = []
    for i, entry in enumerate(env_cfg.transforms.extra or []):
        where = f"env.transforms.extra[{i}]"
        cls, args, kwargs = transform_entry(entry, where)
        try:
            transform = cls(*args, **kwargs)
        except (TypeError, ValueError, KeyError, RuntimeError) as exc:
            detail = " ".join(str(exc).split())[:300]
            raise ConfigError(f"{where} ({cls.__name__}) cannot be built: {detail}") from None
        if not isinstance(transform, Transform):  # the list holds Transform classes: a guard, not a branch
            raise ConfigError(f"{where} ({cls.__name__}) is a {type(transform).__name__}, not a TorchRL Transform")
        built.append(transform)
    return built


def env_spec(env_cfg, keep_env: bool = False) -> EnvSpec:
    """The env's sizes and action bounds, read from the env built from `env_cfg`. keep_env: that env stays open in
    the spec (`EnvSpec.env`) for the training env of the same config to step (make_torchrl_env's first_env), so
    that a run builds its env once before step 1; else it is closed. (A batched env is read from one row of its own,
    which is not kept: a batch is built for its number of rows.)"""
    if batched(env_cfg):
        keep_env = False
    env = make_batch(env_cfg) if batched(env_cfg) else make_gym_env(env_cfg)
    observation_space = getattr(env, "single_observation_space", env.observation_space)
    action_space = getattr(env, "single_action_space", env.action_space)
    if env_cfg.transforms.extra:  # the observation the networks see is the transformed one
        torchrl_env = make_torchrl_env(env_cfg, clip_actions=False, gamma=0.99)
        try:
            obs_shape = torchrl_env.observation_spec["observation"].shape
            torchrl_env.rollout(2)  # a transform that fails on real data fails here, not after hours
        except Exception as exc:  # noqa: BLE001 - a user's transform can fail in any way
            raise ConfigError(f"env.transforms.extra does not run on {env_cfg.id}: {type(exc).__name__}: "
                              f"{str(exc).strip().splitlines()[0] if str(exc).strip() else ''}") from None
        finally:
            torchrl_env.close()
        if len(obs_shape) != 1:
            raise ConfigError(f"env.transforms.extra makes observations of shape {tuple(obs_shape)}; the networks "
                              "need a flat vector (use dim=-1)")
    spec = EnvSpec(
        obs_dim=int(obs_shape[0]) if env_cfg.transforms.extra else int(observation_space.shape[0]),
        action_dim=int(action_space.shape[0]),
        action_low=action_space.low.astype(np.float32),
        action_high=action_space.high.astype(np.float32),
        privileged_dim=getattr(privileged_layout_of(env), "size", None),
    )
    if keep_env:
        spec.env = env
    else:
        env.close()
    return spec


def batched(env_cfg) -> bool:
    """A robot of a model file (env=legged, env=mjcf and the in-house quadruped presets) is stepped as one batched env
    (tasks/locomotion/batch.py); every other env one Gymnasium env per row."""
    return bool(env_cfg.get("xml_file"))


def make_batch(env_cfg, num_envs: int = 1, evaluation: bool = False, render_mode: Optional[str] = None,
               threads: Optional[int] = None, privileged: bool = False, **render_kwargs):
    """The batched legged env of `env_cfg`: `num_envs` robots (LeggedBatchEnv); privileged: it keeps what its
    privileged observation reads (policy.critic_obs=privileged)."""
    from ppo_torchrl.tasks.locomotion.batch import LeggedBatchEnv

    kwargs = gym_make_kwargs(env_cfg, evaluation=evaluation)
    kwargs.pop("evaluation", None)
    return LeggedBatchEnv(kwargs, num_envs=num_envs, evaluation=evaluation, threads=threads,
                          render_mode=render_mode, privileged=privileged, **render_kwargs)


def make_rows(env_cfg, num_envs: int, train: bool = True, render_mode: Optional[str] = None, first_env=None,
              threads: Optional[int] = None, privileged: bool = False, **render_kwargs):
    """The rows of a training or evaluation env (env_rows.py): a batch for env=legged, views of one EnvPool for
    env=playground, else Gymnasium envs."""
    if batched(env_cfg):
        if first_env is not None:
            first_env.close()
        return BatchRows(make_batch(env_cfg, num_envs, not train, render_mode, threads, privileged, **render_kwargs))
    if env_cfg.get("playground") is not None:  # the num_envs envs: views of one EnvPool (envs_playground.py)
        from ppo_torchrl.envs.playground import PlaygroundRows

        return PlaygroundRows([resumable(first_env if i == 0 and first_env is not None else
                                         make_gym_env(env_cfg, render_mode, not train, **render_kwargs))
                               for i in range(num_envs)])
    return GymRows([resumable(first_env if i == 0 and first_env is not None else
                              make_gym_env(env_cfg, render_mode, not train, **render_kwargs)) for i in range(num_envs)])


def seed_rows(rows, seed: int) -> None:
    """Each row i is reset with seed + i once built, so that everything that follows is reproducible."""
    if isinstance(rows, BatchRows):
        rows.batch.reset(seed=seed)
        return
    for i, env in enumerate(rows.envs):
        env.reset(seed=seed + i)
        env.action_space.seed(seed + i)


def make_torchrl_env(
    env_cfg,
    *,
    clip_actions: bool,
    gamma: float,
    obs_stats: Optional[dict] = None,
    train: bool = True,
    render_mode: Optional[str] = None,
    device: str = "cpu",
    num_envs: int = 1,
    seed: Optional[int] = None,
    first_env=None,
    threads: Optional[int] = None,
    privileged: bool = False,
    **render_kwargs,
) -> TransformedEnv:
    """`TransformedEnv(GymWrapper(gymnasium env))` with the configured transforms: the card's pipeline,
    which TorchRL's Collector steps and the fast collector steps in numpy. Its first transform, `EnvState`
    (env_state.py), owns the env-side state: the Gymnasium envs, both normalizers, the episode counters,
    the env metrics and the positions.

    train=True: running statistics (or fixed ones fitted on random rollouts) and reward normalization,
    as a collector needs them; `obs_stats` (init_from) start them.
    train=False: observation statistics frozen from `obs_stats`, rewards left raw: the evaluation env,
    whose returns are the ones a user compares.
    seed: each env i is reset with seed + i once built, so that everything that follows is reproducible.
    first_env: a Gymnasium env of `env_cfg` already built (env_spec's, kept by the command's check): env 0.
    threads: a batched env's physics threads (collector.physics_threads; None or 0: one per core).
    privileged: the env's privileged observation gets statistics of its own too (policy.critic_obs=privileged): the
    rows declare its layout (`privileged_layout()`, env_rows.py).
    """
    t = env_cfg.transforms
    rows = make_rows(env_cfg, num_envs, train, render_mode, first_env, threads, privileged, **render_kwargs)
    if seed is not None:
        seed_rows(rows, seed)
    # The same envs the fast collector steps, wrapped (GymEnv(id, frame_skip=...) would take frame_skip as its own
    # action repeat instead of passing it to the MuJoCo env); several Gymnasium envs or a batch: one batched env.
    base = GymWrapper(rows.gym_env(), device=device)
    obs_dim = int(rows.last_obs().shape[1]) if isinstance(rows, BatchRows) else \
        int(rows.envs[0].observation_space.shape[0])
    if not train and t.obs_norm != "none" and obs_stats is None:
        raise ValueError("a frozen observation normalization needs obs_stats")
    # each segment of the observation scaled as the env declares it (layout.py; one running segment by default)
    fit_env = functools.partial(make_batch if batched(env_cfg) else make_gym_env, env_cfg)  # obs_norm=fixed: one row
    obs_norm = make_observation_normalizer(t, obs_dim, obs_stats, frozen=not train, seed=0 if seed is None else seed,
                                           fit_env=fit_env if train else None,
                                           layout=rows.layout())
    reward_norm = make_reward_normalizer(t, num_envs, gamma) if train else None
    privileged_layout = rows.privileged_layout() if privileged else None
    if privileged and privileged_layout is None:
        raise ConfigError(f"policy.critic_obs=privileged: env.id={env_cfg.id} has no privileged observation")
    privileged_norm = None if privileged_layout is None else make_observation_normalizer(
        t, privileged_layout.size, layout=privileged_layout)  # running statistics of their own (the critic's)
    state = EnvState(rows, obs_norm, reward_norm, privileged_norm)
    transforms = [state]
    if clip_actions:  # Normal head: the env gets the clipped action, the batch keeps the sample
        spec = base.action_spec
        transforms.append(ClipActionToBounds(spec.space.low, spec.space.high))
    transforms.append(ObservationNormalization(state))  # float64 in, float32 out
    transforms += extra_transforms(env_cfg)
    if train:
        transforms.append(RewardNormalization(reward_norm))
    return TransformedEnv(base, Compose(*transforms))


class ClipActionToBounds(Transform):
    """Clips the action the env receives to per-dimension bounds; the tensordict keeps the sample.

    (TorchRL's ClipTransform takes scalar bounds only; MuJoCo action bounds differ per joint.)
    """

    def __init__(self, low: torch.Tensor, high: torch.Tensor):
        super().__init__(in_keys=[], out_keys=[], in_keys_inv=["action"], out_keys_inv=["action"])
        self.register_buffer("low", torch.as_tensor(low).clone())
        self.register_buffer("high", torch.as_tensor(high).clone())

    def _inv_apply_transform(self, action: torch.Tensor) -> torch.Tensor:
        return torch.maximum(torch.minimum(action, self.high), self.low)


def seed_everything(seed: int) -> None:
    import random

    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def episode_seeds(seed: int, n: int) -> Sequence[int]:
    return [seed * 1000 + i for i in range(n)]
