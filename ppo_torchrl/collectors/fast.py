"""The fast collector: a `torchrl.collectors.Collector` whose rollout steps lean.

It is TorchRL's Collector over the same `TransformedEnv(GymWrapper(...))` as every path, built with the
arguments TorchRL's `MultiSyncCollector`, `MultiAsyncCollector` and `RayCollector` pass to a
`collector_class` (so they run it in each worker), weights arriving through TorchRL's weight sync. Only
`rollout()` differs: a numpy copy of the actor's net (`NumpyPolicy`) draws each action, and the env's
Gymnasium envs (held by its `EnvState`, env_state.py) are stepped directly, the observation and reward going
through the numpy face of the env's own normalizers; no per-step TensorDict or torch op, so the per-step
cost is close to the simulator's own. The batch has TorchRL's layout and keys, [num_envs, steps],
`episode_reward` / `step_count` included (Gymnasium's RecordEpisodeStatistics, as EnvState writes them on
TorchRL's path). Its state is TorchRL's (EnvState's snapshot in `env_state_dict`) and its own: the
observation each env's policy acts on next and the exploration RNG, so a resumed run continues bit-exactly.

policy.critic_obs=privileged (an env whose rows give a privileged observation: env=legged's batch): the rows'
privileged observation goes through the env's `EnvState.privileged_norm` into the batch's `privileged_observation`
and ("next", "privileged_observation"), the critic's input, as collectors/playground.py writes EnvPool's; the one
the critic reads next is saved with the observation (`EnvState.emit`), so a resume stays bit-exact.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.collectors import Collector
from torchrl.envs import EnvBase

from ppo_torchrl.internals import OWN, keep_counters, worker_parts
from ppo_torchrl.envs.state import env_state_of, pack
from ppo_torchrl.envs.layout import PRIVILEGED
from ppo_torchrl.rl.models import NumpyPolicy


class Buffers:
    """One rollout's arrays, [steps, num_envs, ...], written step by step; FastCollector._fill makes them the batch.
    `privileged` and `privileged_next` only where the critic reads the privileged observation (privileged_dim)."""

    def __init__(self, steps: int, n: int, obs_dim: int, act_dim: int, privileged_dim: Optional[int] = None):
        self.obs = np.empty((steps, n, obs_dim), np.float32)
        self.next_obs = np.empty((steps, n, obs_dim), np.float32)
        self.action = np.empty((steps, n, act_dim), np.float32)
        self.reward = np.empty((steps, n), np.float32)
        self.ep_return = np.empty((steps, n), np.float64)  # the counters as Gymnasium keeps them: logged exactly
        self.ep_length = np.empty((steps, n), np.int64)
        self.traj = np.empty((steps, n), np.int64)
        self.terminated = np.zeros((steps, n), bool)
        self.truncated = np.zeros((steps, n), bool)
        self.privileged = self.privileged_next = None
        if privileged_dim is not None:
            self.privileged = np.empty((steps, n, privileged_dim), np.float32)
            self.privileged_next = np.empty_like(self.privileged)


class FastCollector(Collector):
    def __init__(self, create_env_fn, policy=None, *, frames_per_batch: int, **kwargs):
        # One output TensorDict, filled in place by each rollout: TorchRL's worker processes then share its memory
        # with the main process once, not each batch's new tensors (use_buffers).
        kwargs["use_buffers"] = True
        kwargs.setdefault("auto_register_policy_transforms", False)
        env = create_env_fn if isinstance(create_env_fn, EnvBase) else create_env_fn(**(kwargs.pop("create_env_kwargs", None) or {}))
        self.env_state = env_state_of(env)  # TypeError for an env not of envs.make_torchrl_env
        self.obs_norm, self.reward_norm = self.env_state.obs_norm, self.env_state.reward_norm
        self.privileged_norm = self.env_state.privileged_norm  # None unless the critic reads the privileged observation
        self._privileged: Optional[np.ndarray] = None  # the normalized privileged observation each env is at
        # TorchRL's Collector resets the env once (its carrier), which this rollout does not use: the
        # statistics count each env's first observation when the first rollout acts on it.
        with self.env_state.uncounted():
            super().__init__(env, policy, frames_per_batch=frames_per_batch, **kwargs)
        self.num_envs = self.env_state.rows.n
        self.steps = frames_per_batch // self.num_envs
        self.numpy_policy = NumpyPolicy.from_actor(self.policy)
        self.rng = np.random.default_rng(0)  # the policy's exploration noise (set_seed reseeds it)
        self._obs: Optional[np.ndarray] = None  # the normalized observation each env's policy acts on next
        self._counted = False  # whether the statistics have seen the envs' current observations
        self._traj_ids = np.arange(self.num_envs)  # ("collector", "traj_ids"): a new id for each new episode
        self._out: Optional[TensorDict] = None

    def set_seed(self, seed: int, static_seed: bool = False) -> int:
        out = super().set_seed(seed, static_seed)
        self.rng = np.random.default_rng(seed)
        self._obs, self._counted = None, False  # the envs were reset by the wrapper, under the transforms
        return out

    def reset(self, index=None, **kwargs) -> None:
        """TorchRL's reset (through the transforms, which count the new observations): the next rollout
        starts from it."""
        super().reset(index, **kwargs)
        self._obs, self._counted = None, True

    def _current_obs(self) -> np.ndarray:
        if self._obs is None:
            self._obs = self.obs_norm(self.env_state.rows.last_obs(), update=not self._counted)
            if self.privileged_norm is not None:  # no TorchRL transform counts it on a reset: counted here, once
                self._privileged = self.privileged_norm(self.env_state.rows.privileged(), update=True)
            self.env_state.stepped()  # acted on: a reset before this one stays counted
            # what EnvState saves as the observation each policy acts on next (and the critic's with it)
            self.env_state.emit(self._obs, privileged=self._privileged)
        return self._obs

    @torch.no_grad()
    def rollout(self) -> TensorDict:
        n, steps = self.num_envs, self.steps
        obs = self._current_obs()
        if steps:
            self.env_state.stepped()  # the steps below act on the last reset's observations
        policy = self.numpy_policy
        policy.sync()
        act_dim = policy.low.shape[0]
        rows = self.env_state.rows
        act, normalize, scale_rewards = policy.act, self.obs_norm, self.reward_norm
        pnorm, privileged = self.privileged_norm, self._privileged
        b = Buffers(steps, n, obs.shape[1], act_dim, None if pnorm is None else privileged.shape[1])
        noise = self.rng.standard_normal((steps, n, act_dim), dtype=np.float32)
        for t in range(steps):
            b.obs[t] = obs
            if pnorm is not None:
                b.privileged[t] = privileged
            b.traj[t] = self._traj_ids
            b.action[t], to_env = act(obs, noise[t])
            raw_next, reward, b.terminated[t], b.truncated[t] = rows.step(to_env)  # every row, none reset
            reset_rows = np.flatnonzero(b.terminated[t] | b.truncated[t]).tolist()
            b.ep_return[t], b.ep_length[t] = self.env_state.episodes()  # each env's episode so far (before any reset)
            # The stats see every observation the env emits, as on TorchRL's path: each step's next
            # observation (a final one too), then the reset observation where an episode ended.
            next_obs = normalize(raw_next)
            obs = next_obs
            if pnorm is not None:
                next_privileged = privileged = pnorm(rows.privileged())
            if reset_rows:
                obs = next_obs.copy()
                if pnorm is not None:
                    privileged = next_privileged.copy()
                for i in reset_rows:
                    obs[i] = normalize(rows.reset_row(i)[None])[0]
                    if pnorm is not None:
                        privileged[i] = pnorm(rows.privileged(slice(i, i + 1)))[0]
                    self._traj_ids[i] = self._traj_ids.max() + 1
            b.next_obs[t] = next_obs
            if pnorm is not None:
                b.privileged_next[t] = next_privileged
            b.reward[t] = scale_rewards(reward, b.terminated[t] | b.truncated[t])
        self._obs, self._privileged = obs, privileged
        self.env_state.emit(obs, privileged=privileged)
        return self._fill(b)

    def _fill(self, b: Buffers) -> TensorDict:
        """The batch in TorchRL's layout and keys, [num_envs, steps], from the rollout's [steps, num_envs] buffers,
        written into the one output TensorDict (the privileged observations too, where the critic reads them)."""
        n, steps = self.num_envs, self.steps

        def tensor(x: np.ndarray) -> torch.Tensor:  # [steps, n, ...] -> [n, steps, ...]
            return torch.from_numpy(np.ascontiguousarray(np.swapaxes(x, 0, 1)))

        terminated, truncated = tensor(b.terminated).unsqueeze(-1), tensor(b.truncated).unsqueeze(-1)
        batch = {
            "observation": tensor(b.obs),
            "action": tensor(b.action),
            ("collector", "traj_ids"): tensor(b.traj),
            ("next", "observation"): tensor(b.next_obs),
            ("next", "reward"): tensor(b.reward).unsqueeze(-1),
            ("next", "terminated"): terminated,
            ("next", "truncated"): truncated,
            ("next", "done"): terminated | truncated,
            ("next", "episode_reward"): tensor(b.ep_return).unsqueeze(-1),
            ("next", "step_count"): tensor(b.ep_length).unsqueeze(-1),
        }
        if b.privileged is not None:
            batch[PRIVILEGED], batch[("next", PRIVILEGED)] = tensor(b.privileged), tensor(b.privileged_next)
        if self._out is None:
            self._out = TensorDict(batch_size=[n, steps], device=self.storing_device)
        for key, value in batch.items():
            if key in self._out.keys(True):
                self._out.get(key).copy_(value)
            else:
                self._out.set(key, value.to(self.storing_device))
        return self._out

    def state_dict(self):
        """TorchRL's (the env's EnvState: statistics, episodes, positions, the observation each env's policy acts
        on next) and this collector's own ("fast": the exploration RNG), packed in one entry
        (env_state.pack). The policy's weights are left out: the learner holds them and sends them."""
        self._current_obs()  # in the EnvState's snapshot below: the observation each policy acts on next
        state = super().state_dict()
        state.pop("policy_state_dict", None)
        state[OWN] = {"rng": self.rng.bit_generator.state}
        return pack(state)

    def load_state_dict(self, state_dict, **kwargs) -> None:
        """A saved state (resume): the statistics and each env where it was; the merged statistics between
        batches (no positions, no "fast"): each env stays where it is."""
        state = worker_parts(state_dict)[0]  # opened
        own = state.pop(OWN, None)
        kwargs.setdefault("strict", False)
        super().load_state_dict(keep_counters(self, state), **kwargs)
        if own is not None and self.env_state.continue_episodes(now=True):
            self._obs = np.asarray(self.env_state.acted_on(), np.float32).reshape(self.num_envs, -1).copy()
            self._privileged = self.env_state.privileged_acted_on()
            self.rng.bit_generator.state = own["rng"]
