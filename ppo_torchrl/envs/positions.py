"""Where one Gymnasium env is: its position, saved and restored (the env's EnvState, env_state.py, holds
the positions of all its envs).

- `get_env_state` / `set_env_state`: the simulator state, time-limit counter, RNG and the episode so far
  (Gymnasium's `RecordEpisodeStatistics`, the library's counter, which a resumed episode carries on): a
  resumed run continues its episodes as the uninterrupted run would;
- `ResumableReset`: a training env whose next reset can continue a saved episode, and which keeps the
  observation the policy acts on next.

Reaching into Gymnasium: a bit-exact continuation needs the `TimeLimit` counter (`_elapsed_steps`),
which Gymnasium keeps private; `get_env_state` / `set_env_state` are the one place that reads it.
"""

from __future__ import annotations

from typing import Optional

import gymnasium as gym
import numpy as np

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

