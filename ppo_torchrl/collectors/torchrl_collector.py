"""The torchrl backend: `torchrl.collectors.Collector` over `TransformedEnv(GymWrapper)`, the reference
pipeline, which takes any TorchRL transform (`env.transforms.extra`)."""

from __future__ import annotations

import functools
from typing import List, Optional, Tuple

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.collectors import Collector
from torchrl.envs import ObservationNorm, VecNormV2  # VecNorm(new_api=True) builds a VecNormV2

from ppo_torchrl.envs import make_torchrl_env, observation_norm, torchrl_obs_stats
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.models import ActorCritic
from ppo_torchrl.normalization import ReturnNormalization, obs_scale


class TorchRLCollector:
    """`torchrl.collectors.Collector` over `TransformedEnv(GymWrapper)`, same batch layout.

    A checkpoint holds where each env is (`ResumableReset`), the episode so far and the running
    discounted returns, so a resumed run continues its episodes as the uninterrupted run would."""

    RESUMES_EPISODES = True

    def __init__(self, cfg, ac: ActorCritic, seed: int, device: torch.device):
        self.gym_envs: list = []  # the gymnasium envs under the wrapper, in env order
        self.env = make_torchrl_env(cfg.env, clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma,
                                    train=True, device="cpu", num_envs=cfg.collector.num_envs,
                                    resumable=self.gym_envs)
        self.env.set_seed(seed)
        self.epsilon = cfg.env.transforms.norm_epsilon
        self._new_collector = functools.partial(
            Collector, policy=ac.actor, frames_per_batch=cfg.collector.frames_per_batch, total_frames=-1,
            policy_device=device, env_device="cpu", storing_device=device)
        self.collector = self._new_collector(self.env)
        self._start(cfg.collector.num_envs)

    def _start(self, envs: int) -> None:
        """What every TorchRL collector keeps beside `self.env` (the stats) and `self.collector`."""
        self._iterator = iter(self.collector)
        self._finished: List[Tuple[float, int]] = []
        self.obs_norm = observation_norm(self.env)
        self._seen = envs  # observations the normalizer has seen: the first resets
        self._episode = np.zeros((2, envs))  # (return, length) of each env's episode so far, at batch end
        self._before_resume = np.zeros((2, envs))  # what a resumed episode had done before the checkpoint

    def collect(self) -> TensorDict:
        batch = next(self._iterator)
        # one env: [steps]; batched envs: [num_envs, steps]; workers add a leading dim: all -> [envs, steps]
        batch = batch.reshape(-1, batch.shape[-1])
        done = batch.get(("next", "done")).squeeze(-1)
        self._seen += batch.numel() + int(done.sum())  # each step's observation, and each reset's
        returns = batch.get(("next", "episode_reward")).squeeze(-1)
        lengths = batch.get(("next", "step_count")).squeeze(-1)
        for i in range(batch.shape[0]):  # episodes in env order, as they ended
            ended = done[i].nonzero().squeeze(-1).tolist()
            for k, t in enumerate(ended):
                before = self._before_resume[:, i] if k == 0 else (0.0, 0)
                self._finished.append((float(returns[i, t]) + before[0], int(lengths[i, t]) + int(before[1])))
            if ended:
                self._before_resume[:, i] = 0.0
        last_done = done[:, -1].numpy()
        self._episode = np.where(last_done, 0.0, np.stack([returns[:, -1].double().numpy(),
                                                           lengths[:, -1].double().numpy()]))
        self._episode += np.where(last_done, 0.0, self._before_resume)
        keys = ["observation", "action", ("next", "observation"), ("next", "reward"), ("next", "done"),
                ("next", "terminated"), ("next", "truncated")]
        return batch.select(*keys)

    def pop_episodes(self) -> List[Tuple[float, int]]:
        finished, self._finished = self._finished, []
        return finished

    def _return_norm(self) -> Optional[ReturnNormalization]:
        return next((t for t in self.env.transform if isinstance(t, ReturnNormalization)), None)

    def env_metrics(self) -> dict:
        return {}  # the Gymnasium envs sit inside TorchRL's wrapper (and, with workers, in other processes)

    def obs_stats(self) -> Optional[dict]:
        return torchrl_obs_stats(self.obs_norm, self._seen)

    def state_dict(self) -> dict:
        """The stats in the shared format, and VecNorm's own state_dict for an exact resume."""
        rn = self._return_norm()
        state = {"obs": self.obs_stats(), "return": rn.normalizer.stats.state_dict() if rn else None,
                 "vecnorm": self.obs_norm.state_dict() if isinstance(self.obs_norm, VecNormV2) else None}
        if self.RESUMES_EPISODES:
            state.update(positions=[env.position() for env in self.gym_envs], episode=self._episode.copy(),
                         running_returns=rn.normalizer.returns.copy() if rn else None)
        return state

    def load_state_dict(self, state: dict) -> None:
        obs = state.get("obs")
        if isinstance(self.obs_norm, VecNormV2) and state.get("vecnorm") is not None:
            self.obs_norm.load_state_dict(state["vecnorm"])
            self._seen = int(obs["count"]) if obs else self._seen
        elif isinstance(self.obs_norm, VecNormV2) and obs is not None:
            raise ConfigError("these observation statistics come from a collector.backend=fast run; VecNorm "
                              "(collector.backend=torchrl) can only continue its own: use the same backend")
        elif isinstance(self.obs_norm, ObservationNorm) and obs is not None:
            self.obs_norm.loc.copy_(torch.as_tensor(obs["mean"]))
            self.obs_norm.scale.copy_(torch.as_tensor(obs_scale(obs["var"], self.epsilon)))
        rn = self._return_norm()
        if rn is not None and state.get("return") is not None:
            rn.normalizer.stats.load_state_dict(state["return"])
        positions = state.get("positions")
        if self.RESUMES_EPISODES and positions is not None and len(positions) == len(self.gym_envs):
            self._continue_episodes(state, rn)

    def _continue_episodes(self, state: dict, rn: Optional[ReturnNormalization]) -> None:
        """A new TorchRL Collector whose first reset restores each env's saved position; the saved
        observation is not counted again by VecNorm (frozen for that reset)."""
        for env, position in zip(self.gym_envs, state["positions"]):
            env.pending = position
        if rn is not None and state.get("running_returns") is not None:
            rn.normalizer.returns = np.asarray(state["running_returns"], np.float64).copy()
        was_frozen = getattr(self.obs_norm, "frozen", True)
        if isinstance(self.obs_norm, VecNormV2):
            self.obs_norm.freeze()
        self.collector.shutdown(close_env=False)
        self.collector = self._new_collector(self.env)
        if isinstance(self.obs_norm, VecNormV2) and not was_frozen:
            self.obs_norm.unfreeze()
        self._iterator = iter(self.collector)
        self._before_resume = np.asarray(state["episode"], np.float64).copy()
        self._episode = self._before_resume.copy()

    def close(self) -> None:
        self.collector.shutdown()
