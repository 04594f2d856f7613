"""Observation and reward normalization: the one owner of the statistics, for every path.

`ObservationNormalizer` and `RewardNormalizer` hold the numbers (numpy, float64) and the formulas;
each has two faces over the same object:
- the numpy face, `__call__`, which the fast collector calls once per env step;
- the TorchRL face, `ObservationNormalization` / `RewardNormalization` (`Transform`s), which the card's
  pipeline `TransformedEnv(GymWrapper(...))` runs. The env's `EnvState` (env_state.py) owns both
  normalizers: their state travels in its snapshot, in any TorchRL collector's `state_dict()`.
Observations: `standardize` is the formula, once, for numpy arrays and torch tensors alike; the
statistics are the exact running mean and variance of every observation the envs emit (reset ones
included), or ("fixed") moments fitted on random-action rollouts by `fit_fixed`, then frozen. The env's
`ObservationLayout` (layout.py) says which elements they scale: a segment with a treatment of its own
(terrain heights in leg lengths, flags as they are) takes it, as per-element vectors made once, so the
per-step cost stays a few vector ops whatever the segments. The normalizer holds statistics only; what the
policy acts on next, and anything else of the envs', is `EnvState`'s (env_state.py).
`pool` merges what several workers added to one set, exactly. `ObservationNormalizer.module()` is the
frozen normalization as a torch module, which `export` bakes into policy.pt.
Rewards: return-based scaling (SB3 VecNormalize's rule, with its prior count) or a fixed scale, then
clipping. TorchRL has no return-based scaling, hence the transform here.
"""

from __future__ import annotations

import math
from typing import Dict, List, Optional, Sequence

import numpy as np
import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.data import Unbounded
from torchrl.envs.transforms import ObservationTransform, Transform

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.envs.layout import ObservationLayout

OBS_MODES = ("running", "fixed", "none")  # env.transforms.obs_norm
REWARD_MODES = ("return", "scale", "none")  # env.transforms.reward_norm


def transforms_checks(t) -> list:
    """(ok, the one line if not) for each value of `env.transforms` (config.TransformsConfig) read here."""
    def positive_or_null(v):
        return v is None or v > 0

    return [
        (t.obs_norm in OBS_MODES, f"env.transforms.obs_norm='{t.obs_norm}' is not known; use one of {', '.join(OBS_MODES)}"),
        (t.reward_norm in REWARD_MODES,
         f"env.transforms.reward_norm='{t.reward_norm}' is not known; use one of {', '.join(REWARD_MODES)}"),
        (t.obs_norm_init_frames >= 2, f"env.transforms.obs_norm_init_frames={t.obs_norm_init_frames} must be >= 2"),
        (positive_or_null(t.obs_clip), f"env.transforms.obs_clip={t.obs_clip} must be > 0 (or null: no clipping)"),
        (positive_or_null(t.reward_clip), f"env.transforms.reward_clip={t.reward_clip} must be > 0 (or null: no clipping)"),
        (t.reward_scale > 0, f"env.transforms.reward_scale={t.reward_scale} must be > 0"),
        (t.norm_epsilon > 0, f"env.transforms.norm_epsilon={t.norm_epsilon} must be > 0"),
    ]


def obs_scale(var, epsilon: float):
    """The std a normalizer divides by: sqrt(var) floored at epsilon."""
    return np.maximum(np.sqrt(np.asarray(var, np.float64)), epsilon)


def clip(x, bound: Optional[float]):
    """Clip to [-bound, bound]; None leaves x as it is. (np.clip's values; its Python wrapper costs
    a few microseconds more per call, and this runs several times per env step.)"""
    if bound is None:
        return x
    if isinstance(x, torch.Tensor):
        return x.clamp(-bound, bound)
    return np.minimum(np.maximum(x, -bound), bound)


def standardize(x, mean, scale, bound: Optional[float]):
    """THE observation formula, for numpy arrays and torch tensors: (x - mean) / scale, clipped."""
    return clip((x - mean) / scale, bound)


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
        self.count = float(state.get("count", 0.0))


def pool(base: Optional[dict], parts: Sequence[dict]) -> dict:
    """Statistics {"mean", "var", "count"}: each part is `base` plus what one worker added since; the
    result is `base` plus all of it, the exact moments of every value any worker saw (count-weighted
    first and second moments, whatever the workers' timing). base None: the parts share nothing."""
    def moments(s):
        count, mean = float(s["count"]), np.asarray(s["mean"], np.float64)
        return count, mean, np.asarray(s["var"], np.float64) + mean**2

    c0, m0, s0 = moments(base) if base is not None else (0.0, 0.0, 0.0)
    parts = [moments(p) for p in parts]
    count = c0 + sum(c - c0 for c, _, _ in parts)
    if count <= 0:
        return dict(base) if base is not None else dict(parts and parts[0] or {})
    mean = (c0 * m0 + sum(c * m - c0 * m0 for c, m, _ in parts)) / count
    square = (c0 * s0 + sum(c * s - c0 * s0 for c, _, s in parts)) / count
    return {"mean": np.asarray(mean, np.float64), "var": np.maximum(square - mean**2, 0.0), "count": count}


class ObservationNormalizer:
    """`standardize(obs, mean, max(std, eps), clip)` with running statistics that update on every
    observation unless frozen, on the running segments of its `layout`; the other segments take their
    fixed treatment (layout.py). The numpy face: `__call__`; the torch faces: `module()` and the
    `ObservationNormalization` transform. Statistics only: the fields are the statistics, the formula's
    constants (clip, epsilon, enabled) and the layout with its vectors, made once."""

    def __init__(self, shape: tuple, clip: Optional[float], epsilon: float = 1e-8, enabled: bool = True,
                 layout: Optional[ObservationLayout] = None):
        # every element's moments are kept (the running segments' are used): the saved format, `pool` and an
        # init_from across layouts stay those of one vector
        self.stats = RunningMeanStd(shape, prior_count=0.0)
        self.clip = clip
        self.epsilon = epsilon
        self.enabled = enabled
        self.layout = layout if layout is not None else ObservationLayout.whole(int(np.prod(shape)))
        if self.layout.size != self.stats.mean.size:
            raise ValueError(f"observation layout of {self.layout.size} elements for statistics of {shape}")
        self._vectors = self.layout.vectors(clip)  # None: every element running, the scalar formula

    @property
    def frozen(self) -> bool:
        return self.stats.frozen

    def freeze(self, frozen: bool = True) -> None:
        self.stats.frozen = frozen

    def __call__(self, obs: np.ndarray, update: bool = True) -> np.ndarray:
        if not self.enabled:
            return obs.astype(np.float32)
        if update:
            self.stats.update(obs)
        return self.apply(obs).astype(np.float32)

    def apply(self, obs):
        """The normalized observation in the input's dtype (float64 for the envs' observations)."""
        if not self.enabled:
            return obs
        return standardize(obs, *self.coefficients())

    def coefficients(self) -> tuple:
        """(mean, scale, bound) of `standardize` now: the statistics' on the running elements, each fixed segment's
        offset, scale and clip on its own, 0, 1 and no bound (inf) on the others; the bound a scalar (obs_clip)
        where every element is running."""
        mean, scale = self.stats.mean, obs_scale(self.stats.var, self.epsilon)
        if self._vectors is None:
            return mean, scale, self.clip
        running, offset, fixed_scale, bound = self._vectors
        return np.where(running, mean, offset), np.where(running, scale, fixed_scale), bound

    def fit_fixed(self, gym_env, frames: int, seed: int) -> None:
        """obs_norm=fixed: the moments of `frames` observations of random-action rollouts, then frozen. gym_env: one
        Gymnasium env, or a batch of one row (envs.make_batch: a vector env, its arrays one row high)."""
        dim = self.stats.mean.shape[-1]
        obs = [np.reshape(gym_env.reset(seed=seed)[0], dim)]
        gym_env.action_space.seed(seed)
        for _ in range(frames - 1):
            o, _, term, trunc, _ = gym_env.step(gym_env.action_space.sample())
            obs.append(np.reshape(gym_env.reset()[0] if np.any(term) or np.any(trunc) else o, dim))
        self.stats.update(np.stack(obs))
        self.freeze()

    def state_dict(self) -> Optional[dict]:
        """{"mean", "var", "count", "layout"}: the one format checkpoints, evaluation, export and init_from read."""
        if not self.enabled:
            return None
        return {**self.stats.state_dict(), "frozen": self.frozen, "layout": self.layout.to_state()}

    def load_state_dict(self, state: Optional[dict]) -> None:
        """The statistics. A state saved with a layout must have this one (statistics scaled one way are not the
        policy's input scaled another); one saved without (before layouts) loads into any of its size."""
        if state is None or not self.enabled:
            return
        if state.get("layout"):
            saved = ObservationLayout.from_state(state["layout"], self.layout.size)
            if saved != self.layout:
                raise ConfigError(f"the saved observation statistics were kept for the layout {saved.describe()}, "
                                  f"not this env's {self.layout.describe()}")
        self.stats.load_state_dict(state)
        self.freeze(bool(state.get("frozen", self.frozen)))

    def module(self) -> nn.Module:
        """The frozen normalization as a torch module (float64 in, float64 out), for export."""
        return FrozenNormalization(self)


class FrozenNormalization(nn.Module):
    """The normalizer's `coefficients()` as buffers: the same per-segment formula, frozen (export)."""

    def __init__(self, normalizer: ObservationNormalizer):
        super().__init__()
        mean, scale, bound = normalizer.coefficients()
        if not normalizer.enabled:
            mean, scale, bound = np.zeros_like(mean), np.ones_like(mean), None
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float64))
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float64))
        if isinstance(bound, np.ndarray):  # per element (a layout with segments of their own)
            self.register_buffer("bound", torch.as_tensor(bound, dtype=torch.float64))
        else:
            self.bound = bound

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return standardize(obs.double(), self.mean, self.scale, self.bound)


def make_observation_normalizer(transforms_cfg, obs_dim: int, stats: Optional[dict] = None,
                                frozen: bool = False, fit_env=None, seed: int = 0,
                                layout: Optional[ObservationLayout] = None) -> ObservationNormalizer:
    """From `env.transforms` and the env's `layout` (without one: the layout `stats` were saved with, else one
    running segment); with `stats` (a checkpoint's), loaded, and frozen if asked. A training env's `fixed`
    statistics without `stats`: fitted on random rollouts of `fit_env()` (an env of their own), then frozen."""
    t = transforms_cfg
    if layout is None:
        layout = ObservationLayout.from_state((stats or {}).get("layout"), obs_dim)
    norm = ObservationNormalizer((obs_dim,), t.obs_clip, t.norm_epsilon, enabled=t.obs_norm != "none", layout=layout)
    if stats is not None:
        norm.load_state_dict(stats)
    elif t.obs_norm == "fixed" and fit_env is not None:
        env = fit_env()
        norm.fit_fixed(env, t.obs_norm_init_frames, seed)
        env.close()
    if frozen:
        norm.freeze()
    return norm


class ObservationNormalization(ObservationTransform):
    """The TorchRL face of an `ObservationNormalizer`: normalizes "observation" on reset and step (in float64,
    then to float32, as the networks take it), and updates the statistics with each observation the envs emit
    (with a partial reset of batched envs, only the new ones).
    An observation no policy acted on is not counted: a reset of every env that follows another with no step
    between (TorchRL's multi-process collectors reset each worker's envs after seeding them, the Collector
    having reset them once when built) puts back the statistics from before the first, so every path and
    scale counts each env's first observation once, as the fast collector does.
    What the policy acts on next, and when a reset is counted, are the env's `EnvState`'s (env_state.py): this
    transform tells it through its API (`stepped`, `emit`, `full_reset`, `take_replay`), holding nothing."""

    def __init__(self, state):
        super().__init__(in_keys=["observation"], out_keys=["observation"])
        # the env's EnvState (env_state.py, which imports this module), not as a child module: its state is saved
        # once, as the chain's first transform (a child's extra state would be saved, and loaded, twice)
        object.__setattr__(self, "state", state)
        self.normalizer: ObservationNormalizer = state.obs_norm

    def _normalize(self, obs: torch.Tensor, mask: Optional[torch.Tensor] = None) -> torch.Tensor:
        norm = self.normalizer
        x = obs.numpy() if obs.dtype == torch.float64 and obs.device.type == "cpu" else obs.detach().cpu().double().numpy()
        if norm.enabled and not norm.frozen:
            rows = x.reshape(-1, x.shape[-1])
            if mask is not None:
                rows = rows[mask.reshape(-1).cpu().numpy()]
            if rows.shape[0]:
                norm.stats.update(rows)
        out = torch.from_numpy(np.asarray(norm.apply(x), np.float32))
        return out if obs.device.type == "cpu" else out.to(obs.device)

    def transform_observation_spec(self, observation_spec):
        spec = observation_spec["observation"]
        observation_spec["observation"] = Unbounded(shape=spec.shape, dtype=torch.float32, device=spec.device)
        return observation_spec

    def _apply_transform(self, obs: torch.Tensor) -> torch.Tensor:
        """Outside an env (a module call, a replay buffer): normalize, leaving the statistics as they are."""
        x = obs.detach().cpu().double().numpy()
        return torch.as_tensor(self.normalizer.apply(x), dtype=torch.float32, device=obs.device)

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        self.state.stepped()
        out = self._normalize(next_tensordict.get("observation"))
        self.state.emit(out.cpu().numpy())
        return next_tensordict.set("observation", out)

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        mask = tensordict.get("_reset", None) if tensordict is not None else None
        obs = tensordict_reset.get("observation")
        if mask is not None:
            mask = mask.reshape(obs.shape[:-1])
        state = self.state
        full = mask is None or bool(mask.all())
        if full:
            replay = state.take_replay()
            if replay is not None:  # saved episodes continue: what the policy was to act on, uncounted
                rows = np.asarray(replay, np.float32).reshape(obs.shape)
                state.emit(rows)
                return tensordict_reset.set("observation", torch.from_numpy(rows.copy()).to(obs.device))
            state.full_reset()  # the statistics of a reset that no step followed are taken back
        out = self._normalize(obs, mask)
        state.emit(out.cpu().numpy(), None if full else mask.cpu().numpy())
        return tensordict_reset.set("observation", out)


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


class RewardNormalizer:
    """env.transforms.reward_norm: "return" (ReturnNormalizer), "scale" (reward x reward_scale, clipped)
    or "none" (raw). The numpy face `__call__(reward, done)` is what every path runs."""

    def __init__(self, mode: str, num_envs: int, gamma: float, scale: float, clip: Optional[float],
                 epsilon: float = 1e-8):
        self.mode = mode
        self.scale_factor = scale
        self.clip = clip
        self.returns = ReturnNormalizer(num_envs, gamma, clip, epsilon)

    def __call__(self, reward: np.ndarray, done: np.ndarray):
        if self.mode == "return":
            return self.returns(reward, done)
        if self.mode == "scale":
            return clip(reward * self.scale_factor, self.clip)
        return reward

    def state_dict(self) -> dict:
        return {**self.returns.stats.state_dict(), "returns": self.returns.returns.copy()}

    def load_state_dict(self, state: Optional[dict], running: bool = True) -> None:
        """The return statistics; each env's discounted return so far too when `running` and given."""
        if not state:
            return
        self.returns.stats.load_state_dict(state)
        returns = None if state.get("returns") is None else np.asarray(state["returns"], np.float64)
        if running and returns is not None and returns.size == self.returns.returns.size:
            self.returns.returns = returns.reshape(self.returns.returns.shape).copy()


def make_reward_normalizer(transforms_cfg, num_envs: int, gamma: float) -> RewardNormalizer:
    t = transforms_cfg
    return RewardNormalizer(t.reward_norm, num_envs, gamma, t.reward_scale, t.reward_clip, t.norm_epsilon)


class RewardNormalization(Transform):
    """The TorchRL face of a `RewardNormalizer`: rewrites "reward" on each step."""

    def __init__(self, normalizer: RewardNormalizer):
        super().__init__(in_keys=["reward"], out_keys=["reward"])
        self.normalizer = normalizer

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        reward = next_tensordict.get("reward")
        done = next_tensordict.get("done").reshape(-1).cpu().numpy()
        scaled = self.normalizer(reward.reshape(-1).double().cpu().numpy(), done)
        next_tensordict.set("reward", torch.as_tensor(scaled, dtype=reward.dtype).reshape(reward.shape))
        return next_tensordict


def pooled(base: Optional[dict], parts: List[Optional[dict]]) -> Optional[dict]:
    """`pool` of state dicts that may be None (no normalization) or frozen (nothing to merge)."""
    if not parts or parts[0] is None or parts[0].get("frozen"):
        return parts[0] if parts else None
    extra = {k: v for k, v in parts[0].items() if k not in ("mean", "var", "count")}
    return {**extra, **pool(base, parts)}
