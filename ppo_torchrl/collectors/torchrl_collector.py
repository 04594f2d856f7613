"""The torchrl backend: `torchrl.collectors.Collector` over `TransformedEnv(GymWrapper)`, the reference
pipeline, which takes any TorchRL transform (`env.transforms.extra`)."""

from __future__ import annotations

from typing import List, Optional, Tuple

import torch
from tensordict import TensorDict
from torchrl.collectors import Collector
from torchrl.envs import ObservationNorm, VecNormV2  # VecNorm(new_api=True) builds a VecNormV2

from ppo_torchrl.envs import make_torchrl_env, observation_norm, torchrl_obs_stats
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.models import ActorCritic
from ppo_torchrl.normalization import ReturnNormalization, obs_scale


class TorchRLCollector:
    """`torchrl.collectors.Collector` over `TransformedEnv(GymWrapper)`, same batch layout."""

    def __init__(self, cfg, ac: ActorCritic, seed: int, device: torch.device):
        self.env = make_torchrl_env(cfg.env, clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma,
                                    train=True, device="cpu", num_envs=cfg.collector.num_envs)
        self.env.set_seed(seed)
        self.epsilon = cfg.env.transforms.norm_epsilon
        self.collector = Collector(
            self.env,
            ac.actor,
            frames_per_batch=cfg.collector.frames_per_batch,
            total_frames=-1,
            policy_device=device,
            env_device="cpu",
            storing_device=device,
        )
        self._start(cfg.collector.num_envs)

    def _start(self, envs: int) -> None:
        """What every TorchRL collector keeps beside `self.env` (the stats) and `self.collector`."""
        self._iterator = iter(self.collector)
        self._finished: List[Tuple[float, int]] = []
        self.obs_norm = observation_norm(self.env)
        self._seen = envs  # observations the normalizer has seen: the first resets

    def collect(self) -> TensorDict:
        batch = next(self._iterator)
        # one env: [steps]; batched envs: [num_envs, steps]; workers add a leading dim: all -> [envs, steps]
        batch = batch.reshape(-1, batch.shape[-1])
        done = batch.get(("next", "done")).squeeze(-1)
        self._seen += batch.numel() + int(done.sum())  # each step's observation, and each reset's
        returns = batch.get(("next", "episode_reward"))[done].reshape(-1).tolist()
        lengths = batch.get(("next", "step_count"))[done].reshape(-1).tolist()
        self._finished += list(zip(returns, lengths))
        keys = ["observation", "action", ("next", "observation"), ("next", "reward"), ("next", "done"),
                ("next", "terminated"), ("next", "truncated")]
        return batch.select(*keys)

    def pop_episodes(self) -> List[Tuple[float, int]]:
        finished, self._finished = self._finished, []
        return finished

    def _return_norm(self) -> Optional[ReturnNormalization]:
        return next((t for t in self.env.transform if isinstance(t, ReturnNormalization)), None)

    def obs_stats(self) -> Optional[dict]:
        return torchrl_obs_stats(self.obs_norm, self._seen)

    def state_dict(self) -> dict:
        """The stats in the shared format, and VecNorm's own state_dict for an exact resume."""
        rn = self._return_norm()
        return {"obs": self.obs_stats(), "return": rn.normalizer.stats.state_dict() if rn else None,
                "vecnorm": self.obs_norm.state_dict() if isinstance(self.obs_norm, VecNormV2) else None}

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

    def close(self) -> None:
        self.collector.shutdown()
