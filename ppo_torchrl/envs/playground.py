"""env=playground: MuJoCo Playground's tasks as EnvPool ships them, as Gymnasium envs of the app's one pipeline.

`envpool` 1.2.5 has C++ ports of Playground's tasks (`envpool.list_all_envs()`, the `MuJoCoPlayground/<task>-v1`
aliases: Go1JoystickFlatTerrain-v1, SpotFlatTerrainJoystick-v1, BarkourJoystick-v1, ...), checked by their authors
against Playground's Python. `python -m ppo_torchrl env=playground env.id=Go1JoystickFlatTerrain-v1` trains one.

What the app sees of a task:
- the observation: the dict's `env.playground.observation_key` (`state`, 48 for the Go1 joystick) is the
  Gymnasium observation, the actor's input, one running segment of that name (layout.py); the dict's
  `privileged_key` (`privileged_state`, 123) is the env's privileged observation (`privileged_layout()`), which
  `policy.critic_obs=privileged` gives the critic. A task whose observation is one vector (BarkourJoystick-v1,
  the Panda tasks) gives it all to the actor and has no privileged one;
- actions in the task's own range (the EnvPool spec's action space; [-1, 1] for every Playground task);
- episode ends: EnvPool's own time limit (truncated) and the task's termination; EnvPool's auto-reset step (the
  step after an end: the action ignored, reward 0) never enters a batch: the training collector takes it for the
  ended envs alone, at once (collectors/playground.py), as collectors/envpool_backend.py does;
- each `info["reward_<term>"]` (the task's weighted terms before Playground's x ctrl_dt and clip at 0, as
  Playground's own `reward/<term>` metrics have them) summed over the episode, logged as `reward/<term>`, and the
  command (`info["command"]`: vx, vy, yaw rate) as the episode's mean commanded speed and |yaw rate| (`command/`):
  `metric_names()` declares them, the collector reports each finished episode's through EnvState.

One pool, many views: EnvPool's memory is per env (~55 MB for a Go1) and a pool takes seconds to build, so the
`num_envs` Gymnasium envs of one TransformedEnv are views (`PlaygroundEnv`) of one `PlaygroundPool` of num_envs
envs: env i steps and resets pool env i; the training collector steps all of them at once. EnvPool seeds env i of
a pool built with seed s as s + i (Gymnasium's vector convention), and a pool cannot be reseeded, so a seeded
reset rebuilds the pool (`reset(seed=s)` of env i: a pool seeded s - i) unless env i is still at the start of the
first episode of a pool so seeded; a reset of an env not stepped since its last reset leaves it where it is.

Filming: EnvPool renders its own MuJoCo state (`render_mode="rgb_array"`, the model's first camera: the Go1's
`track`, which follows the trunk; EnvPool's free camera for a model without one), in an OpenGL context made current
here (internals.gl_context, MUJOCO_GL=egl).
EnvPool gives no access to the task's MjModel or MjData: nothing that reads the simulator (forward velocity,
gait figures, a restored position) works on these tasks.
"""

from __future__ import annotations

import functools
import os
from typing import Optional

import gymnasium as gym
import numpy as np

from ppo_torchrl.envs.rows import GymRows
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.envs.layout import ObservationLayout, Segment

INSTALL = 'pip install -e ".[envpool]" (make setup installs it; EnvPool has wheels for Python >= 3.11)'
ALIAS = "MuJoCoPlayground/"  # EnvPool's alias prefix of its Playground tasks
# EnvPool settings the app sets itself (a pool's size, threads, seeds, rendering): not env.make_kwargs'
OWN_SETTINGS = ("num_envs", "batch_size", "num_threads", "max_num_players", "thread_affinity_offset", "seed",
                "env_seed", "base_path", "gym_reset_return_info", "max_episode_steps", "frame_stack", "task_name")
COMMAND = "command"  # info key of a joystick task's command (vx, vy, yaw rate)


def _envpool():
    try:
        import envpool
    except ImportError:
        raise ConfigError(f"env=playground needs EnvPool, which is not installed: {INSTALL}") from None
    return envpool


@functools.lru_cache(maxsize=None)
def playground_ids() -> tuple:
    """The Playground task ids EnvPool has (its MuJoCoPlayground/ aliases, without the prefix)."""
    return tuple(sorted(e[len(ALIAS):] for e in _envpool().list_all_envs() if e.startswith(ALIAS)))


def task_id(env_id: str) -> str:
    """Go1JoystickFlatTerrain-v1 for it or its alias MuJoCoPlayground/Go1JoystickFlatTerrain-v1."""
    return str(env_id)[len(ALIAS):] if str(env_id).startswith(ALIAS) else str(env_id)


def playground_hint(env_id: str) -> str:
    """'; ... is a MuJoCo Playground task: env=playground env.id=...' when it is one (EnvPool installed), else ''."""
    try:
        known = task_id(env_id) in playground_ids()
    except ConfigError:
        return ""
    return f"; {env_id} is a MuJoCo Playground task: env=playground env.id={env_id}" if known else ""


def _plain(value):
    from omegaconf import OmegaConf

    return OmegaConf.to_container(value, resolve=True) if OmegaConf.is_config(value) else value


def pool_settings(env_cfg) -> dict:
    """The checked EnvPool settings of env_cfg: {"task", "kwargs", "keys": (actor key, privileged key or None)};
    one ConfigError line for an unknown id (naming the known ones), a setting the task does not have, or a key
    of the app's env config that a Playground task does not read."""
    from ppo_torchrl.config import LocomotionConfig, TerrainConfig

    task = task_id(env_cfg.id)
    known = playground_ids()
    if task not in known:
        raise ConfigError(f"env.id={env_cfg.id} is not one of EnvPool's MuJoCo Playground tasks: {', '.join(known)}")
    for key in ("xml_file", "legged"):
        if env_cfg.get(key) is not None:
            raise ConfigError(f"env.{key} is for MuJoCo models the app builds (env=mjcf, env=legged); a Playground "
                              f"task brings its own model (env.id={env_cfg.id})")
    from omegaconf import OmegaConf

    for name, default in (("locomotion", LocomotionConfig()), ("terrain", TerrainConfig())):
        node, default = env_cfg.get(name) or {}, OmegaConf.to_container(OmegaConf.structured(default))
        changed = [k for k in node if _plain(node[k]) != default.get(k)]  # nested ones (command, ...) as plain data
        if changed:  # a key this env does not read is refused, never ignored
            raise ConfigError(f"env.{name}.{changed[0]} works on MJCF robots (env=mjcf, env=legged), not on a "
                              f"Playground task; its own settings are env.make_kwargs.<EnvPool setting>")
    spec = _envpool().make_spec(task)
    settings = [f for f in spec.config._fields if f not in OWN_SETTINGS]
    kwargs = dict(_plain(env_cfg.make_kwargs) or {})
    for key in kwargs:
        if key not in settings:
            raise ConfigError(f"env.make_kwargs.{key} is not a setting of EnvPool's {task}; it has: {', '.join(settings)}")
    if env_cfg.max_episode_steps is not None:
        kwargs["max_episode_steps"] = int(env_cfg.max_episode_steps)
    p = env_cfg.playground
    space = spec.gymnasium_observation_space
    if isinstance(space, gym.spaces.Dict):
        if p.observation_key not in space.spaces:
            raise ConfigError(f"env.playground.observation_key={p.observation_key}: {task}'s observation has "
                              f"{', '.join(space.spaces)}")
        keys = (p.observation_key, p.privileged_key if p.privileged_key in space.spaces else None)
    else:
        keys = (None, None)  # one vector: all of it the actor's
    if p.threads is not None and p.threads < 1:
        raise ConfigError(f"env.playground.threads={p.threads} must be >= 1 (or null: one per env, up to the CPUs)")
    return {"task": task, "kwargs": kwargs, "keys": keys, "threads": p.threads}


def cpus() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


class PlaygroundPool:
    """One EnvPool of `n` envs of a task, built at the first reset and shared by its n views (PlaygroundEnv) and the
    training collector (module doc). It keeps each env's current observation (`current`), and for each env whether
    it is at the start of an episode (`fresh`: no step since its reset) and of the pool's first one (`first`)."""

    def __init__(self, settings: dict, n: int, render: Optional[dict] = None):
        envpool = _envpool()
        self.task, self.kwargs, self.n = settings["task"], settings["kwargs"], n
        self.keys = settings["keys"]
        self.threads_asked = settings.get("threads")  # env.playground.threads (None: min(n, CPUs))
        self.threads = int(self.threads_asked or min(n, cpus()))
        self.render_kwargs = render or {}
        self.spec = envpool.make_spec(self.task, **self.kwargs)
        space = self.spec.gymnasium_observation_space
        self.sizes = {k: int(space[k].shape[0]) for k in self.keys if k is not None} if self.keys[0] else \
            {None: int(space.shape[0])}
        action = self.spec.gymnasium_action_space
        self.action_low, self.action_high = action.low.astype(np.float32), action.high.astype(np.float32)
        self.dt = float(self.spec.config.ctrl_dt)
        state = self.spec.state_array_spec
        self.terms = tuple(k[len("info:reward_"):] for k in state if k.startswith("info:reward_"))
        self.has_command = f"info:{COMMAND}" in state and tuple(state[f"info:{COMMAND}"].shape[-1:]) == (3,)
        self.pool, self.seed = None, None
        self._camera = 0  # the model's first camera (-1: EnvPool's free one, for a model without cameras)
        self.current = {k: np.zeros((n, size)) for k, size in self.sizes.items()}
        self.fresh, self.first = np.zeros(n, bool), np.zeros(n, bool)
        self._open = n  # views not closed

    # ------------------------------------------------------------------ building
    def build(self, seed: int) -> None:
        """A new pool seeded `seed` (env i: seed + i; EnvPool takes int32 seeds, so seed modulo 2^31 - 1 - n, the same
        pool for the same seed); every env at the start of its first episode."""
        self.close_pool()
        if self.render_kwargs:
            from ppo_torchrl.internals import gl_context

            gl_context(self.render_kwargs["render_width"], self.render_kwargs["render_height"])
        self.pool = _envpool().make(self.task, env_type="gymnasium", num_envs=self.n, num_threads=self.threads,
                                    seed=int(seed) % (2**31 - 1 - self.n), **self.kwargs, **self.render_kwargs)
        self.seed = int(seed)
        obs, info = self.pool.reset()
        self._keep(obs, np.argsort(info["env_id"]), np.arange(self.n))
        self.fresh[:], self.first[:] = True, True

    def close_pool(self) -> None:
        if self.pool is not None:
            self.pool.close()
        self.pool = None

    def _keep(self, obs, order: np.ndarray, rows: np.ndarray) -> dict:
        """Each key's observation of `rows` (EnvPool's answer put in env order), kept as their current one."""
        out = {}
        for key in self.sizes:
            value = np.asarray(obs[key] if key is not None else obs, np.float64)[order]
            self.current[key][rows] = value
            out[key] = value
        return out

    # ------------------------------------------------------------------ stepping
    def reset(self, i: int, seed: Optional[int] = None) -> dict:
        """Env i's observation after a reset (module doc: a seeded one rebuilds the pool unless env i is at the
        start of the first episode of a pool seeded seed - i; an env not stepped since its last reset stays)."""
        if seed is not None:
            if not (self.pool is not None and self.seed == seed - i and self.first[i] and self.fresh[i]):
                self.build(seed - i)
        elif self.pool is None:
            self.build(int(np.random.SeedSequence().generate_state(1)[0] >> 1))
        elif not self.fresh[i]:
            obs, info = self.pool.reset(env_id=np.array([i]))
            self._keep(obs, np.argsort(info["env_id"]), np.array([i]))
            self.fresh[i], self.first[i] = True, False
        return {key: value[i].copy() for key, value in self.current.items()}

    def step(self, actions: np.ndarray, rows: np.ndarray) -> tuple:
        """Step envs `rows` (sorted); (obs {key: [len(rows), size]}, reward, terminated, truncated, info), each in the
        order of rows (EnvPool answers in its own)."""
        obs, reward, term, trunc, info = self.pool.step(np.asarray(actions, np.float64), rows)
        order = np.argsort(info["env_id"])
        if not np.array_equal(info["env_id"][order], rows):
            raise RuntimeError(f"EnvPool answered envs {info['env_id']} for {rows}")
        info = {k: v[order] for k, v in info.items() if isinstance(v, np.ndarray) and v.shape[:1] == reward.shape}
        reset_step = info["elapsed_step"] == 0  # EnvPool's auto-reset step: a new episode's start
        self.fresh[rows], self.first[rows] = reset_step, False
        return self._keep(obs, order, rows), reward[order], term[order], trunc[order], info

    def episode_terms(self, info: dict) -> np.ndarray:
        """[rows, len(terms)]: each reward term of a step."""
        return np.stack([info[f"reward_{t}"] for t in self.terms], axis=-1) if self.terms else \
            np.zeros((len(info["env_id"]), 0))

    def command_figures(self, info: dict) -> np.ndarray:
        """[rows, 2]: the commanded speed sqrt(vx^2 + vy^2) and |yaw rate| of a step ([rows, 0] without a command)."""
        if not self.has_command:
            return np.zeros((len(info["env_id"]), 0))
        command = info[COMMAND]
        return np.stack([np.hypot(command[:, 0], command[:, 1]), np.abs(command[:, 2])], axis=-1)

    def metric_names(self) -> list:
        return [f"reward/{t}" for t in self.terms] + (["command/speed", "command/yaw_rate"] if self.has_command else [])

    def episode_metrics(self, term_sums: np.ndarray, command_sums: np.ndarray, lengths: np.ndarray) -> list:
        """One dict per ended episode: each term's sum, the mean commanded speed and |yaw rate|."""
        names = self.metric_names()
        rows = []
        for terms, command, n in zip(term_sums, command_sums, lengths):
            values = [*terms, *(command / max(int(n), 1))]
            rows.append({name: float(v) for name, v in zip(names, values)})
        return rows

    def render(self, i: int) -> np.ndarray:
        """Env i's frame from the model's first camera, or EnvPool's free camera for a model without one
        (PandaRobotiqPushCube-v1: EnvPool raises IndexError for camera 0)."""
        try:
            return self.pool.render(env_ids=np.array([i]), camera_id=self._camera)[0]
        except IndexError:
            if self._camera == -1:
                raise
            self._camera = -1
            return self.pool.render(env_ids=np.array([i]), camera_id=-1)[0]

    def release(self) -> None:
        """A view closed: the pool goes with the last one."""
        self._open -= 1
        if self._open <= 0:
            self.close_pool()


class PlaygroundEnv(gym.Env):
    """Env `index` of a PlaygroundPool as a Gymnasium env (module doc): the actor's observation as a float64 vector,
    the task's action range, its time limit and termination; reset(seed=...) as the pool allows. It keeps the
    current episode's reward terms (`episode_metrics`: what evaluate reports)."""

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(self, shared: PlaygroundPool, index: int, render_mode: Optional[str] = None):
        self.shared, self.index, self.render_mode = shared, index, render_mode
        self.key, self.privileged_key = shared.keys
        size = shared.sizes[self.key]
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float64)
        self.action_space = gym.spaces.Box(shared.action_low, shared.action_high, dtype=np.float32)
        self.metadata = {**self.metadata, "render_fps": 1.0 / shared.dt}
        self.dt = shared.dt
        self._sums = self._command = None
        self._steps = 0

    def observation_layout(self) -> ObservationLayout:
        return ObservationLayout((Segment.running(self.key or "state", self.observation_space.shape[0]),))

    def privileged_layout(self) -> Optional[ObservationLayout]:
        if self.privileged_key is None:
            return None
        return ObservationLayout((Segment.running(self.privileged_key, self.shared.sizes[self.privileged_key]),))

    def metric_names(self) -> list:
        return self.shared.metric_names()

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        obs = self.shared.reset(self.index, seed)
        self._sums, self._command, self._steps = np.zeros(len(self.shared.terms)), np.zeros(2), 0
        return obs[self.key], self._info(obs)

    def _info(self, obs: dict) -> dict:
        return {"privileged_observation": obs[self.privileged_key]} if self.privileged_key is not None else {}

    def step(self, action):
        rows = np.array([self.index])
        obs, reward, term, trunc, info = self.shared.step(np.asarray(action, np.float64)[None], rows)
        self._sums = self._sums + self.shared.episode_terms(info)[0]
        command = self.shared.command_figures(info)[0]
        self._command = self._command + command if command.size else self._command
        self._steps += 1
        return obs[self.key][0], float(reward[0]), bool(term[0]), bool(trunc[0]), \
            self._info({k: v[0] for k, v in obs.items()})

    def episode_metrics(self) -> dict:
        """The episode so far: each reward term's sum (reward/<term>), the mean command (command/)."""
        command = self._command if self.shared.has_command else np.zeros(0)
        return self.shared.episode_metrics(self._sums[None], command[None], np.array([self._steps]))[0]

    def render(self):
        if self.render_mode != "rgb_array":
            raise RuntimeError("this Playground env was made without render_mode='rgb_array'")
        return self.shared.render(self.index)

    def close(self):
        if self.shared is not None:
            self.shared.release()
            self.shared = None


def make_playground_env(env_cfg, render_mode: Optional[str] = None, **render_kwargs) -> PlaygroundEnv:
    """env_cfg's task as one Gymnasium env, the view of a pool of its own (not built until its first reset)."""
    render = None
    if render_mode is not None:
        render = {"render_mode": render_mode, "render_width": int(render_kwargs.get("width", 480)),
                  "render_height": int(render_kwargs.get("height", 360))}
    return PlaygroundEnv(PlaygroundPool(pool_settings(env_cfg), 1, render), 0, render_mode)


def one_pool(views: list) -> None:
    """Views of one task (make_playground_env's, their pools not built yet) made views of one pool of len(views)
    envs, view i of env i: a training env's num_envs envs step as one EnvPool (module doc)."""
    first = views[0].shared
    settings = {"task": first.task, "kwargs": first.kwargs, "keys": first.keys, "threads": first.threads_asked}
    shared = PlaygroundPool(settings, len(views), first.render_kwargs)
    for i, view in enumerate(views):
        if view.shared.pool is not None:
            raise RuntimeError("one_pool: a view's own pool was built already")
        view.shared.release()
        view.shared, view.index = shared, i


class PlaygroundRows(GymRows):
    """env=playground's rows (env_rows.py): the num_envs Gymnasium envs (make_playground_env's, each under
    positions.resumable) made views of one PlaygroundPool (`one_pool`). TorchRL's GymWrapper, evaluation and filming
    step them view by view; the training collector (collectors/playground.py) steps the pool whole and hands each
    finished episode's figures here (`add_episodes`), which `metrics()` gives EnvState once. Beyond GymRows: the
    privileged observation's layout and the reward terms' metrics.csv columns (reward/<term>, command/...)."""

    def __init__(self, envs: list):
        super().__init__(envs)
        one_pool([env.unwrapped for env in envs])
        self.shared = envs[0].unwrapped.shared
        self._finished: list = []

    def add_episodes(self, figures: list) -> None:
        self._finished.extend(figures)

    def metrics(self) -> list:
        finished, self._finished = self._finished, []
        return finished

    def metric_keys(self) -> list:
        return self.shared.metric_names()

    def privileged_layout(self) -> Optional[ObservationLayout]:
        return self.envs[0].unwrapped.privileged_layout()
