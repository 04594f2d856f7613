"""The fast backend: the TorchRL pipeline's math in a lean numpy loop over the same Gymnasium envs.

A numpy copy of the policy net (`NumpyPolicy`) draws each action, observations and rewards are
normalized in numpy with the same statistics VecNorm and `ReturnNormalization` compute, and there
is no per-step TensorDict or torch op: the per-step cost is close to the simulator's own. The batch
it returns has TorchRL's layout and keys.
"""

from __future__ import annotations

from typing import Dict, List, Optional, Tuple

import numpy as np
import torch
from tensordict import TensorDict

from ppo_torchrl.envs import get_env_state, make_gym_env, set_env_state
from ppo_torchrl.models import ActorCritic, NumpyPolicy
from ppo_torchrl.normalization import ObservationNormalizer, ReturnNormalizer, clip


class FastCollector:
    def __init__(self, cfg, ac: ActorCritic, seed: int, device: torch.device):
        t = cfg.env.transforms
        self.ac, self.device = ac, device
        self.policy = NumpyPolicy(ac)
        self.rng = np.random.default_rng(seed)  # the policy's exploration noise
        self.num_envs = cfg.collector.num_envs
        self.steps = cfg.collector.frames_per_batch // self.num_envs
        self.envs = [make_gym_env(cfg.env) for _ in range(self.num_envs)]
        obs_dim = self.envs[0].observation_space.shape[0]
        self.obs_norm = ObservationNormalizer((obs_dim,), t.obs_clip, t.norm_epsilon, enabled=t.obs_norm != "none")
        self.reward_mode = t.reward_norm
        self.reward_scale = t.reward_scale
        self.reward_clip = t.reward_clip
        self.return_norm = ReturnNormalizer(self.num_envs, cfg.advantage.gamma, t.reward_clip, t.norm_epsilon)
        for i, env in enumerate(self.envs):
            env.action_space.seed(seed + i)
        if t.obs_norm == "fixed":
            self._fit_fixed_obs_stats(t.obs_norm_init_frames, seed)
        raw = np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(self.envs)])
        self._first_raw_obs = raw  # re-normalized if stats are loaded before the first batch
        self._obs = self.obs_norm(raw)
        self._episode_return = np.zeros(self.num_envs)
        self._episode_length = np.zeros(self.num_envs, np.int64)
        self._finished: List[Tuple[float, int]] = []

    def _fit_fixed_obs_stats(self, frames: int, seed: int) -> None:
        """ObservationNorm-style stats from random-action rollouts, then frozen."""
        env = self.envs[0]
        obs = [env.reset(seed=seed)[0]]
        for _ in range(frames - 1):
            o, _, term, trunc, _ = env.step(env.action_space.sample())
            obs.append(env.reset()[0] if term or trunc else o)
        self.obs_norm.stats.update(np.stack(obs))
        self.obs_norm.stats.frozen = True

    def _scale_rewards(self, reward: np.ndarray, done: np.ndarray) -> np.ndarray:
        if self.reward_mode == "return":
            return self.return_norm(reward, done)
        if self.reward_mode == "scale":
            return clip(reward * self.reward_scale, self.reward_clip)
        return reward

    @torch.no_grad()
    def collect(self) -> TensorDict:
        n, steps = self.num_envs, self.steps
        obs_dim = self._obs.shape[1]
        act_dim = self.ac.action_low.shape[0]
        obs_buf = np.empty((steps, n, obs_dim), np.float32)
        next_buf = np.empty((steps, n, obs_dim), np.float32)
        act_buf = np.empty((steps, n, act_dim), np.float32)
        self.policy.sync()
        noise = self.rng.standard_normal((steps, n, act_dim), dtype=np.float32)
        rew_buf = np.empty((steps, n), np.float32)
        term_buf = np.zeros((steps, n), bool)
        trunc_buf = np.zeros((steps, n), bool)
        raw_next = np.empty((n, obs_dim))
        reward = np.empty(n)
        act, envs = self.policy.act, self.envs
        obs = self._obs
        for t in range(steps):
            obs_buf[t] = obs
            act_buf[t], to_env = act(obs, noise[t])
            reset_rows = []
            for i, env in enumerate(envs):
                o, r, term, trunc, _ = env.step(to_env[i])
                raw_next[i], reward[i] = o, r
                term_buf[t, i], trunc_buf[t, i] = term, trunc
                if term or trunc:
                    reset_rows.append((i, env.reset()[0]))
            self._episode_return += reward
            self._episode_length += 1
            # The stats see every observation the env emits, as VecNorm does on the TorchRL path: each
            # step's next observation (a final one too), then the reset observation where an episode ended.
            next_obs = self.obs_norm(raw_next)
            obs = next_obs
            if reset_rows:
                obs = next_obs.copy()
                for i, first in reset_rows:
                    obs[i] = self.obs_norm(first[None])[0]
                    self._finished.append((float(self._episode_return[i]), int(self._episode_length[i])))
                    self._episode_return[i] = 0.0
                    self._episode_length[i] = 0
            next_buf[t] = next_obs
            rew_buf[t] = self._scale_rewards(reward, term_buf[t] | trunc_buf[t])
        self._obs = obs
        self._first_raw_obs = None

        def tensor(x: np.ndarray) -> torch.Tensor:  # [steps, n, ...] -> [n, steps, ...]
            return torch.from_numpy(np.ascontiguousarray(np.swapaxes(x, 0, 1))).to(self.device)

        terminated = tensor(term_buf).unsqueeze(-1)
        truncated = tensor(trunc_buf).unsqueeze(-1)
        return TensorDict(
            {
                "observation": tensor(obs_buf),
                "action": tensor(act_buf),
                "next": {
                    "observation": tensor(next_buf),
                    "reward": tensor(rew_buf).unsqueeze(-1),
                    "terminated": terminated,
                    "truncated": truncated,
                    "done": terminated | truncated,
                },
            },
            batch_size=[n, steps],
            device=self.device,
        )

    def pop_episodes(self) -> List[Tuple[float, int]]:
        finished, self._finished = self._finished, []
        return finished

    def env_metrics(self) -> Dict[str, float]:
        reports = [env.unwrapped.terrain_metrics() for env in self.envs if hasattr(env.unwrapped, "terrain_metrics")]
        reports = [r for r in reports if r]
        return {key: float(np.mean([r[key] for r in reports])) for key in reports[0]} if reports else {}

    def obs_stats(self) -> Optional[dict]:
        return self.obs_norm.stats.state_dict() if self.obs_norm.enabled else None

    def state_dict(self) -> dict:
        """Normalization stats, plus where each env is, so a resumed run continues bit-exactly."""
        return {
            "obs": self.obs_stats(),
            "obs_frozen": self.obs_norm.stats.frozen,
            "return": self.return_norm.stats.state_dict(),
            "running_returns": self.return_norm.returns.copy(),
            "envs": [get_env_state(env) for env in self.envs],
            "current_obs": self._obs.copy(),
            "rng": self.rng.bit_generator.state,
            "episode_return": self._episode_return.copy(),
            "episode_length": self._episode_length.copy(),
        }

    def load_state_dict(self, state: dict) -> None:
        """Stats always; env positions too when the checkpoint has them for as many envs."""
        if state.get("obs") is not None and self.obs_norm.enabled:
            self.obs_norm.stats.load_state_dict(state["obs"])
            self.obs_norm.stats.frozen = bool(state.get("obs_frozen", False))
        if state.get("return") is not None:
            self.return_norm.stats.load_state_dict(state["return"])
        envs = state.get("envs")
        if envs is None and self._first_raw_obs is not None:  # stats only (init_from), nothing collected yet
            self._obs = self.obs_norm(self._first_raw_obs, update=False)
        if envs is not None and len(envs) == self.num_envs and state["current_obs"].shape == self._obs.shape:
            for env, env_state in zip(self.envs, envs):
                set_env_state(env, env_state)
            self._obs = state["current_obs"].copy()
            if "rng" in state:
                self.rng.bit_generator.state = state["rng"]
            self._episode_return = state["episode_return"].copy()
            self._episode_length = state["episode_length"].copy()
            self.return_norm.returns = state["running_returns"].copy()

    def close(self) -> None:
        for env in self.envs:
            env.close()
