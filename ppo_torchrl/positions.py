"""Where each env is: the one owner of the Gymnasium envs under TorchRL's wrapper.

`GymEnvs` is a TorchRL transform that changes nothing in the data; it holds the Gymnasium envs of a
`TransformedEnv(GymWrapper(...))` (built by `envs.make_torchrl_env`), so that every path reaches them
through the public transform chain:
- the fast collector steps them directly;
- `positions()` / `continue_from()` save and restore each env (simulator state, time-limit counter,
  RNG, the episode so far, the observation the policy acts on next): a resumed run continues its
  episodes as the uninterrupted run would;
- `env_metrics()`: the scalars a step env keeps (curriculum level, recent success rate);
- `evaluate` films and measures the env through `gym_envs[0]`;
- the episode so far: each env's return and length are Gymnasium's `RecordEpisodeStatistics` (the
  library's counter, which a resumed episode carries on), written to every step and reset as TorchRL's
  `episode_reward` / `step_count` (RewardSum's and StepCounter's keys). The fast collector reads the same
  counters, so every path logs the same episodes.

Reaching into Gymnasium: a bit-exact continuation needs the `TimeLimit` counter (`_elapsed_steps`),
which Gymnasium keeps private; `get_env_state` / `set_env_state` are the one place that reads it.
"""

from __future__ import annotations

from typing import Dict, List, Optional

import gymnasium as gym
import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs.transforms import Transform

from ppo_torchrl.errors import ConfigError


def _find_wrapper(env: gym.Env, kind: type) -> Optional[gym.Wrapper]:
    while isinstance(env, gym.Wrapper):
        if isinstance(env, kind):
            return env
        env = env.env
    return None


def get_env_state(env: gym.Env) -> dict:
    """What a bit-exact continuation of this episode needs: the MuJoCo integration state
    (qpos, qvel, act, time, warm start), the time-limit counter, the env's RNG and the episode so far."""
    state = {"np_random": env.unwrapped.np_random.bit_generator.state}
    if hasattr(env.unwrapped, "get_extra_state"):  # robots/env.py: the step, curriculum, last action, air times
        state["extra"] = env.unwrapped.get_extra_state()
    limit = _find_wrapper(env, gym.wrappers.TimeLimit)
    if limit is not None:
        state["elapsed_steps"] = limit._elapsed_steps
    record = _find_wrapper(env, gym.wrappers.RecordEpisodeStatistics)
    if record is not None:
        state["episode"] = (float(record.episode_returns), int(record.episode_lengths))
    model, data = getattr(env.unwrapped, "model", None), getattr(env.unwrapped, "data", None)
    if model is not None and data is not None:
        import mujoco

        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        physics = np.empty(mujoco.mj_stateSize(model, spec))
        mujoco.mj_getState(model, data, physics, spec)
        state["mujoco"] = physics
    return state


def set_env_state(env: gym.Env, state: dict) -> None:
    env.unwrapped.np_random.bit_generator.state = state["np_random"]
    limit = _find_wrapper(env, gym.wrappers.TimeLimit)
    if limit is not None and "elapsed_steps" in state:
        limit._elapsed_steps = state["elapsed_steps"]
    record = _find_wrapper(env, gym.wrappers.RecordEpisodeStatistics)
    if record is not None and "episode" in state:
        record.episode_returns, record.episode_lengths = state["episode"]
    if "mujoco" in state:
        import mujoco

        model, data = env.unwrapped.model, env.unwrapped.data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        if state["mujoco"].shape[0] != mujoco.mj_stateSize(model, spec):
            raise ConfigError("the checkpoint's simulator state does not fit this env's model")
        mujoco.mj_setState(model, data, state["mujoco"], spec)
        mujoco.mj_forward(model, data)
    if "extra" in state and hasattr(env.unwrapped, "set_extra_state"):
        env.unwrapped.set_extra_state(state["extra"])


class ResumableReset(gym.Wrapper):
    """Its next reset() can continue a saved episode instead of starting one (how TorchRL's own
    Collector picks up each env where a checkpoint left it); `last_obs` is the observation the policy
    acts on next, and `episode` the return and length of the episode so far."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.pending: Optional[dict] = None
        self.last_obs: Optional[np.ndarray] = None
        self.record = _find_wrapper(env, gym.wrappers.RecordEpisodeStatistics)

    def position(self) -> dict:
        return {"env": get_env_state(self.env), "obs": self.last_obs.copy()}

    def restore(self, position: dict) -> None:
        set_env_state(self.env, position["env"])
        self.last_obs = np.asarray(position["obs"]).copy()

    def reset(self, **kwargs):
        if self.pending is None:
            self.last_obs, info = self.env.reset(**kwargs)
            return self.last_obs, info
        position, self.pending = self.pending, None
        self.restore(position)
        return self.last_obs.copy(), {}

    def step(self, action):
        self.last_obs, reward, terminated, truncated, info = self.env.step(action)
        return self.last_obs, reward, terminated, truncated, info


def resumable(env: gym.Env) -> ResumableReset:
    """A training env: Gymnasium's episode counter, and a reset that can continue a saved episode."""
    return ResumableReset(gym.wrappers.RecordEpisodeStatistics(env))


EPISODE_KEYS = ("episode_reward", "step_count")


class GymEnvs(Transform):
    """Holds the Gymnasium envs under the wrapper (in env order) and writes each env's episode so far
    (`episode_reward`, `step_count`: raw return and length) from their counters."""

    def __init__(self, envs: List[ResumableReset]):
        super().__init__(in_keys=[], out_keys=list(EPISODE_KEYS))
        self.gym_envs = envs

    def episodes(self) -> tuple:
        """The return and length of each env's episode so far: ([n], [n]) arrays."""
        records = [env.record for env in self.gym_envs]
        return (np.array([r.episode_returns for r in records], np.float64),
                np.array([r.episode_lengths for r in records], np.int64))

    def _write_episodes(self, data: TensorDictBase) -> TensorDictBase:
        shape = self.parent.batch_size + (1,)
        returns, lengths = self.episodes()
        data.set("episode_reward", torch.from_numpy(returns).reshape(shape))
        data.set("step_count", torch.from_numpy(lengths).reshape(shape))
        return data

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        return self._write_episodes(next_tensordict)

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._write_episodes(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        shape = self.parent.batch_size + (1,)
        observation_spec["episode_reward"] = Unbounded(shape=shape, dtype=torch.float64)  # as Gymnasium sums it
        observation_spec["step_count"] = Unbounded(shape=shape, dtype=torch.int64)
        return observation_spec

    def positions(self) -> list:
        return [env.position() for env in self.gym_envs]

    def continue_from(self, positions: list, now: bool) -> bool:
        """Each env continues its saved episode: `now` (the fast collector), or at its next reset (TorchRL's
        Collector resets its envs when it starts). False, changing nothing, when the count differs."""
        if positions is None or len(positions) != len(self.gym_envs):
            return False
        for env, position in zip(self.gym_envs, positions):
            if now:
                env.restore(position)
            else:
                env.pending = position
        return True

    def env_metrics(self) -> Dict[str, float]:
        """Scalars the envs keep, logged each iteration: a step env's curriculum level and recent success
        rate (`LocomotionEnv.terrain_metrics`); {} where the envs say nothing."""
        reports = [env.unwrapped.terrain_metrics() for env in self.gym_envs
                   if hasattr(env.unwrapped, "terrain_metrics")]
        reports = [r for r in reports if r]
        return {key: float(np.mean([r[key] for r in reports])) for key in reports[0]} if reports else {}
