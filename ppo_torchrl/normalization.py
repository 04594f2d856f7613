"""Running statistics for observation and reward normalization.

Observations: the TorchRL pipeline normalizes with TorchRL's `VecNorm` (decay 1: the exact running
mean and variance of every observation the env emits, reset observations included, with the std
floored at `eps`); the fast collector computes the same numbers in numpy (`ObservationNormalizer`,
no prior count). Both report `{"mean", "var", "count"}`, the one format checkpoints, evaluation,
export and init_from read, and `obs_scale` is the one formula that turns it into a scale.

Rewards: TorchRL has no return-based scaling, so `ReturnNormalization` below is a TorchRL
`Transform` around `ReturnNormalizer`, which the fast collector calls directly: the same code on
both paths (SB3 VecNormalize's rule, with its prior count).
"""

from __future__ import annotations

import math
from typing import Dict, Optional

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs.transforms import Transform


def obs_scale(var, epsilon: float):
    """The std a normalizer divides by: sqrt(var) floored at epsilon, as VecNorm does."""
    return np.maximum(np.sqrt(np.asarray(var, np.float64)), epsilon)


def clip(x: np.ndarray, bound: Optional[float]) -> np.ndarray:
    """Clip to [-bound, bound]; None leaves x as it is. (np.clip's values; its Python wrapper costs
    a few microseconds more per call, and this runs several times per env step.)"""
    return x if bound is None else np.minimum(np.maximum(x, -bound), bound)


class RunningMeanStd:
    """Mean and variance of a stream of vectors, merged batch by batch."""

    def __init__(self, shape: tuple = (), prior_count: float = 1e-4):
        # prior_count > 0 (SB3): the stats start as mean 0, var 1 seen prior_count times, which avoids
        # a division by zero before the first update; 0: the exact mean and variance of what was seen.
        self.mean = np.zeros(shape, np.float64)
        self.var = np.ones(shape, np.float64) if prior_count else np.zeros(shape, np.float64)
        self.count = prior_count
        self.frozen = False

    def update(self, batch: np.ndarray) -> None:
        if self.frozen:
            return
        batch = np.asarray(batch, np.float64)
        if batch.size == self.mean.size:  # the per-step case, one vector: the merge below with a
            # batch of one (b_var 0, b_count 1), whose dropped terms are exact zeros and ones
            delta = batch.reshape(self.mean.shape) - self.mean
            total = self.count + 1
            self.mean = self.mean + delta / total
            self.var = (self.var * self.count + delta**2 * self.count / total) / total
            self.count = total
            return
        batch = batch.reshape(-1, *self.mean.shape)
        b_mean, b_var, b_count = batch.mean(0), batch.var(0), batch.shape[0]
        delta = b_mean - self.mean
        total = self.count + b_count
        self.mean = self.mean + delta * b_count / total
        m2 = self.var * self.count + b_var * b_count + delta**2 * self.count * b_count / total
        self.var = m2 / total
        self.count = total

    def update_scalar(self, x: float) -> None:
        """update() of a scalar statistic with one value, on Python floats: the same IEEE-double
        arithmetic as the per-step case above (x * x is what numpy's square computes), without the
        cost of numpy calls on 0-d arrays (~3 us a step; the fast collector with one env)."""
        if self.frozen:
            return
        mean, var, count = float(self.mean), float(self.var), self.count
        delta = x - mean
        total = count + 1
        self.mean = np.float64(mean + delta / total)
        self.var = np.float64((var * count + delta * delta * count / total) / total)
        self.count = total

    def state_dict(self) -> Dict[str, object]:
        return {"mean": self.mean.copy(), "var": self.var.copy(), "count": float(self.count)}

    def load_state_dict(self, state: Dict[str, object]) -> None:
        mean = np.asarray(state["mean"], np.float64)
        if mean.shape != self.mean.shape:
            raise ValueError(f"normalization stats have shape {mean.shape}, expected {self.mean.shape}")
        self.mean = mean.copy()
        self.var = np.asarray(state["var"], np.float64).copy()
        self.count = float(state["count"])


class ObservationNormalizer:
    """(obs - mean) / max(std, eps), clipped, as TorchRL's VecNorm(decay=1) and ClipTransform do;
    stats update on every observation unless frozen."""

    def __init__(self, shape: tuple, clip: Optional[float], epsilon: float = 1e-8, enabled: bool = True):
        self.stats = RunningMeanStd(shape, prior_count=0.0)
        self.clip = clip
        self.epsilon = epsilon
        self.enabled = enabled

    def __call__(self, obs: np.ndarray, update: bool = True) -> np.ndarray:
        if not self.enabled:
            return obs.astype(np.float32)
        if update:
            self.stats.update(obs)
        out = (obs - self.stats.mean) / obs_scale(self.stats.var, self.epsilon)
        return clip(out, self.clip).astype(np.float32)


class ReturnNormalizer:
    """Scales rewards by the std of the discounted return (not the reward): PPO's reward scaling.

    `returns` is the per-env discounted return so far; it restarts when an episode ends.
    """

    def __init__(self, num_envs: int, gamma: float, clip: Optional[float], epsilon: float = 1e-8):
        self.stats = RunningMeanStd(())
        self.returns = np.zeros(num_envs, np.float64)
        self.gamma = gamma
        self.clip = clip
        self.epsilon = epsilon

    def __call__(self, reward: np.ndarray, done: np.ndarray) -> np.ndarray:
        if self.returns.size == 1:  # one env: the same arithmetic on Python floats, ~7x cheaper a step
            r = float(reward[0])
            ret = float(self.returns[0]) * self.gamma + r
            self.stats.update_scalar(ret)
            self.returns[0] = 0.0 if done[0] else ret
            scaled = r / math.sqrt(float(self.stats.var) + self.epsilon)
            return scaled if self.clip is None else min(max(scaled, -self.clip), self.clip)
        self.returns = self.returns * self.gamma + reward
        self.stats.update(self.returns)
        self.returns[done] = 0.0
        return self.scale(reward)

    def scale(self, reward: np.ndarray) -> np.ndarray:
        return clip(reward / np.sqrt(self.stats.var + self.epsilon), self.clip)


class ReturnNormalization(Transform):
    """TorchRL transform: divide `reward` by the running std of the discounted return.

    TorchRL ships `VecNorm` (reward std) and `RewardScaling` (fixed), not the return-based scaling
    that PPO's MuJoCo results rely on, so this wraps `ReturnNormalizer` as a transform.
    """

    def __init__(self, gamma: float, clip: Optional[float], num_envs: int = 1, epsilon: float = 1e-8):
        super().__init__(in_keys=["reward"], out_keys=["reward"])
        self.normalizer = ReturnNormalizer(num_envs, gamma, clip, epsilon)

    def get_extra_state(self) -> Dict[str, torch.Tensor]:
        """In the module's state_dict (and so in a TorchRL collector's): the return statistics and
        each env's discounted return so far, which is how worker processes hand them over to merge."""
        stats = self.normalizer.stats
        return {"mean": torch.tensor(stats.mean), "var": torch.tensor(stats.var),
                "count": torch.tensor(stats.count, dtype=torch.float64),
                "returns": torch.from_numpy(self.normalizer.returns.copy())}

    def set_extra_state(self, state) -> None:
        if not state:
            return
        self.normalizer.stats.load_state_dict({k: np.asarray(state[k]) for k in ("mean", "var", "count")})
        if "returns" in state:
            self.normalizer.returns = np.asarray(state["returns"], np.float64).copy()

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        reward = next_tensordict.get("reward")
        done = next_tensordict.get("done").reshape(-1).cpu().numpy()
        scaled = self.normalizer(reward.reshape(-1).double().cpu().numpy(), done)
        next_tensordict.set("reward", torch.as_tensor(scaled, dtype=reward.dtype).reshape(reward.shape))
        return next_tensordict
