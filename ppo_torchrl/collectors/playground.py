"""env=playground's collector: FastCollector's rollout over the EnvPool that steps a MuJoCo Playground task in C++.

What it is: a `torchrl.collectors.Collector` (a FastCollector subclass: the same batch keys, policy, RNG, state and
weight sync, so TorchRL's `MultiSyncCollector` and `RayCollector` run it in workers) over the same
`TransformedEnv(GymWrapper(...))` as every path, whose `EnvState` keeps the statistics, the episodes' figures and
the metrics. The env's Gymnasium envs are the views of one `PlaygroundPool` (envs_playground.py); this collector
steps all of the pool's envs at once, the observation through `EnvState.obs_norm`, the privileged observation
(policy.critic_obs=privileged) through `EnvState.privileged_norm` into the batch's `privileged_observation` and
("next", "privileged_observation"), which the critic's ValueOperator reads (GAE and the loss through its in_keys).

Episode ends: EnvPool's step after an end is its auto-reset step (action ignored, reward 0, elapsed_step 0). It is
taken at once for the ended envs alone and gives the new episode's first observation, as
collectors/envpool_backend.py does: it never enters a batch. Each ended episode's reward terms (summed) and mean
command go to the rows (`PlaygroundRows.add_episodes`, EnvState's `env_metrics`); the trainer logs their mean over a batch's episodes.

Resume: EnvPool cannot restore a simulator state (RESUME_LIMIT). A resumed run keeps the statistics (the critic's
too), the RNG and the frame count; its pool is rebuilt from the restored RNG, so each env starts a new episode
(the start line says so), the same ones on every resume of one checkpoint.
"""

from __future__ import annotations

import numpy as np
import torch

from ppo_torchrl.collectors.fast import Buffers, FastCollector
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.internals import OWN, worker_parts

RESUME_LIMIT = ("env=playground cannot restore EnvPool's simulator state: the statistics, RNG and frame count carry "
                "on, each env starts a new episode")
BACKENDS = ("auto", "envpool", "playground")  # collector.backend values that run a Playground task (this collector)


def check_playground(cfg) -> None:
    """One line unless this collector can run cfg: env=playground (its task, EnvPool installed, settings it has), a
    backend that is this collector, no per-step TorchRL transforms, a privileged observation where the critic is
    asked to read one (and statistics it can keep: running or none)."""
    from ppo_torchrl.envs.playground import pool_settings

    env = cfg.env
    if env.get("playground") is None:
        raise ConfigError(f"collector.backend=playground steps MuJoCo Playground tasks: env=playground env.id=<task>, "
                          f"not env.id={env.id}")
    if cfg.collector.backend not in BACKENDS:
        raise ConfigError(f"collector.backend={cfg.collector.backend}: env=playground runs on its EnvPool's collector "
                          "(collector.backend=auto)")
    if env.transforms.extra:
        raise ConfigError("env.transforms.extra needs TorchRL's per-step transforms, which env=playground's collector "
                          "does not run")
    settings = pool_settings(env)
    if cfg.policy.get("critic_obs", "observation") == "privileged":
        if settings["keys"][1] is None:
            raise ConfigError(f"policy.critic_obs=privileged: {settings['task']}'s observation has no "
                              f"{env.playground.privileged_key}")
        if env.transforms.obs_norm == "fixed":
            raise ConfigError("env.transforms.obs_norm=fixed fits the actor's observation only; use running (or none) "
                              "with policy.critic_obs=privileged")


class PlaygroundCollector(FastCollector):
    """FastCollector's rollout with all envs stepped by the env's one PlaygroundPool (module doc)."""

    def __init__(self, create_env_fn, policy=None, **kwargs):
        super().__init__(create_env_fn, policy, **kwargs)
        self.shared = self.env_state.gym_envs[0].unwrapped.shared
        self._new_episodes = False  # a resume: the next rollout rebuilds the pool from self.rng
        # each env's episode so far: return and length (Gymnasium's counters, kept here), each reward term's sum, and
        # the sums of the commanded speed and |yaw rate| (envs_playground.PlaygroundPool.command_figures)
        n = self.num_envs
        self.returns, self.lengths = np.zeros(n), np.zeros(n, np.int64)
        self.term_sums = np.zeros((n, len(self.shared.terms)))
        self.command_sums = np.zeros((n, 2 if self.shared.has_command else 0))

    def _zero_counters(self, rows) -> None:
        self.returns[rows], self.lengths[rows], self.term_sums[rows], self.command_sums[rows] = 0.0, 0, 0.0, 0.0

    def set_seed(self, seed: int, static_seed: bool = False) -> int:
        out = super().set_seed(seed, static_seed)  # the views reset with seed + i: the pool seeded so (its first episodes)
        self._zero_counters(np.arange(self.num_envs))
        return out

    def _current_obs(self) -> np.ndarray:
        if self._obs is None:
            counted = self._counted
            if self._new_episodes:
                self.shared.build(int(self.rng.integers(2**31 - 1)))
                self._new_episodes, counted = False, False
                self._zero_counters(np.arange(self.num_envs))
            key, privileged_key = self.shared.keys
            self._obs = self.obs_norm(self.shared.current[key], update=not counted)
            if self.privileged_norm is not None:  # no TorchRL transform counts it on a reset: counted here, once
                self._privileged = self.privileged_norm(self.shared.current[privileged_key], update=True)
            self.env_state.stepped()
            self.env_state.emit(self._obs, privileged=self._privileged)
        return self._obs

    @torch.no_grad()
    def rollout(self):
        n, steps, shared = self.num_envs, self.steps, self.shared
        obs = self._current_obs()
        privileged = self._privileged
        policy = self.numpy_policy
        policy.sync()
        key, privileged_key = shared.keys
        act_dim = policy.low.shape[0]
        pnorm = self.privileged_norm
        b = Buffers(steps, n, obs.shape[1], act_dim, None if pnorm is None else privileged.shape[1])
        noise = self.rng.standard_normal((steps, n, act_dim), dtype=np.float32)
        every = np.arange(n)
        act, normalize, scale_rewards = policy.act, self.obs_norm, self.reward_norm
        for t in range(steps):
            b.obs[t] = obs
            if pnorm is not None:
                b.privileged[t] = privileged
            b.traj[t] = self._traj_ids
            b.action[t], to_env = act(obs, noise[t])
            raw, reward, term, trunc, info = shared.step(to_env, every)
            reward = reward.astype(np.float64)
            self.returns += reward
            self.lengths += 1
            self.term_sums += shared.episode_terms(info)
            self.command_sums += shared.command_figures(info)
            b.ep_return[t], b.ep_length[t] = self.returns, self.lengths
            b.terminated[t], b.truncated[t] = term, trunc
            done = term | trunc
            next_obs = obs = normalize(raw[key])
            if pnorm is not None:
                next_privileged = privileged = pnorm(raw[privileged_key])
            if done.any():
                ended = np.flatnonzero(done)
                # EnvPool's reset step for the ended envs alone: the new episodes' first observations (module doc)
                first, r0, _, _, info0 = shared.step(np.zeros((len(ended), act_dim)), ended)
                if info0["elapsed_step"].any() or r0.any():
                    raise RuntimeError("EnvPool's step after an episode's end was not its reset step")
                obs = next_obs.copy()
                obs[ended] = normalize(first[key])
                if pnorm is not None:
                    privileged = next_privileged.copy()
                    privileged[ended] = pnorm(first[privileged_key])
                self.env_state.rows.add_episodes(shared.episode_metrics(
                    self.term_sums[ended], self.command_sums[ended], self.lengths[ended]))
                self._zero_counters(ended)
                for i in ended:
                    self._traj_ids[i] = self._traj_ids.max() + 1
            b.next_obs[t] = next_obs
            if pnorm is not None:
                b.privileged_next[t] = next_privileged
            b.reward[t] = scale_rewards(reward, done)
        self._obs, self._privileged = obs, privileged
        self.env_state.emit(obs, privileged=privileged)
        return self._fill(b)

    def load_state_dict(self, state_dict, **kwargs) -> None:
        """A saved state: the statistics (the critic's too) and the RNG; EnvPool cannot restore a simulator state, so
        each env starts a new episode from a pool rebuilt from the restored RNG (RESUME_LIMIT). The merged statistics
        between batches (no OWN entry): each env goes on where it is."""
        own = worker_parts(state_dict)[0].get(OWN)
        super().load_state_dict(state_dict, **kwargs)
        self.env_state.held_positions = None  # the views' positions: EnvPool keeps the simulator
        if own is not None:
            self.rng.bit_generator.state = own["rng"]
            self._obs, self._privileged, self._new_episodes = None, None, True

    def shutdown(self, *args, **kwargs) -> None:
        self.shared.close_pool()
        super().shutdown(*args, **kwargs)
