"""The rows of a training env: what EnvState (env_state.py) holds and the fast collector steps, one interface over
two kinds of env.

- `GymRows`: one Gymnasium env per row (`collector.num_envs` of them, each a positions.ResumableReset over
  Gymnasium's RecordEpisodeStatistics): the MuJoCo benchmark envs, env=mjcf's robots.
- `BatchRows`: one batched env of N rows (tasks/locomotion/batch.py, env=legged), stepped in one call.

Both give: `n`; `step(actions)` -> (observations, rewards, terminated, truncated) as arrays, no reset; `reset_row(i)`
(the row's next episode, or the position held for it); `last_obs()`; `episodes()` (each row's return and length so
far); `metrics()` (what each row reports: a step env's curriculum, a task's reward terms) and `metric_keys()` (the
keys beyond loggers.COLUMNS that metrics.csv gets a column for: the task's own, which the trainer never names);
`positions()`,
`restore(positions)` (now) and `hold(positions)` (at each row's next reset: TorchRL's Collector resets first);
`layout()`; `privileged_layout()` (the layout of the env's privileged observation, None without one: what
policy.critic_obs=privileged gives the critic) and `privileged(rows)` (that observation now, raw: after a step, or
after `reset_row(i)` for `rows=slice(i, i + 1)`); `gym_env()`, a Gymnasium env a TorchRL GymWrapper wraps.

The privileged observation, for any env kind: the env declares `privileged_layout()` (its Gymnasium env's unwrapped
env, or the batched env), the rows return it here, `make_torchrl_env(privileged=True)` gives EnvState a normalizer of
its own for it, and the env's collector writes it normalized into the batch under layout.PRIVILEGED and
("next", PRIVILEGED), which the critic reads: env=playground's rows (envs_playground.PlaygroundRows) and collector
(collectors/playground.py), and env=legged's batch (tasks/locomotion/task.py says what it holds) through the fast
collector. Gymnasium's envs declare none, so validation refuses policy.critic_obs=privileged for them.
"""

from __future__ import annotations

import functools
from typing import List, Optional

import gymnasium as gym
import numpy as np

from ppo_torchrl.envs.layout import ObservationLayout, layout_of, privileged_layout_of


class GymRows:
    def __init__(self, envs: list):
        self.envs = envs
        self.n = len(envs)

    def step(self, actions: np.ndarray) -> tuple:
        n = self.n
        obs, reward = None, np.empty(n)
        terminated, truncated = np.zeros(n, bool), np.zeros(n, bool)
        for i, env in enumerate(self.envs):
            o, r, term, trunc, _ = env.step(actions[i])
            if obs is None:
                obs = np.empty((n, len(o)))
            obs[i], reward[i], terminated[i], truncated[i] = o, r, term, trunc
        return obs, reward, terminated, truncated

    def reset_row(self, i: int) -> np.ndarray:
        return self.envs[i].reset()[0]

    def last_obs(self) -> np.ndarray:
        return np.stack([env.last_obs for env in self.envs])

    def episodes(self) -> tuple:
        records = [env.record for env in self.envs]
        return (np.array([r.episode_returns for r in records], np.float64),
                np.array([r.episode_lengths for r in records], np.int64))

    def metrics(self) -> List[dict]:
        reports = [env.unwrapped.terrain_metrics() for env in self.envs if hasattr(env.unwrapped, "terrain_metrics")]
        return [r for r in reports if r]

    def metric_keys(self) -> List[str]:
        return []

    def positions(self) -> list:
        return [env.position() for env in self.envs]

    def restore(self, positions: list) -> None:
        for env, position in zip(self.envs, positions):
            env.restore(position)

    def hold(self, positions: list) -> None:
        for env, position in zip(self.envs, positions):
            env.pending = position

    def layout(self) -> ObservationLayout:
        return layout_of(self.envs[0])

    def privileged_layout(self) -> Optional[ObservationLayout]:
        return privileged_layout_of(self.envs[0])

    def privileged(self, rows=slice(None)) -> np.ndarray:
        raise NotImplementedError("Gymnasium's envs of one env per row give no privileged observation")

    def gym_env(self) -> gym.Env:
        if self.n == 1:
            return self.envs[0]
        # one batched env over Gymnasium's vector env: one process, no per-env TensorDict (2.7x SerialEnv)
        return gym.vector.SyncVectorEnv([functools.partial(lambda e: e, env) for env in self.envs],
                                        autoreset_mode=gym.vector.AutoresetMode.DISABLED)

    def close(self) -> None:
        for env in self.envs:
            env.close()


class BatchRows:
    def __init__(self, batch):
        self.batch = batch
        self.n = batch.num_envs

    def step(self, actions: np.ndarray) -> tuple:
        obs, reward, terminated, truncated, _ = self.batch.step(actions)
        return obs, reward, terminated, truncated

    def reset_row(self, i: int) -> np.ndarray:
        return self.batch.reset_row(i).copy()

    def last_obs(self) -> np.ndarray:
        return self.batch.last_obs.copy()

    def episodes(self) -> tuple:
        return self.batch.episodes()

    def metrics(self) -> List[dict]:
        return self.batch.metrics()

    def metric_keys(self) -> List[str]:
        return self.batch.task.metric_keys()

    def positions(self) -> list:
        return self.batch.positions()

    def restore(self, positions: list) -> None:
        for i, position in enumerate(positions):
            self.batch.restore_row(i, position)

    def hold(self, positions: list) -> None:
        self.batch.pending = list(positions)

    def layout(self) -> ObservationLayout:
        return self.batch.observation_layout()

    def privileged_layout(self) -> Optional[ObservationLayout]:
        return privileged_layout_of(self.batch)

    def privileged(self, rows=slice(None)) -> np.ndarray:
        return self.batch.privileged(rows)

    def gym_env(self):
        return self.batch

    def close(self) -> None:
        self.batch.close()
