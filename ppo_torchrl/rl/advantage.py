"""Advantage estimation: TorchRL's GAE over a [num_envs, time] batch.

Truncation is not termination: GAE bootstraps from V(next observation) unless `terminated`, and
cuts the recursion at `done` (terminated or truncated). The collectors store the true final
observation of a truncated episode as `("next", "observation")`, so the bootstrap value is right.
"""

from __future__ import annotations

from tensordict import TensorDictBase
from torchrl.objectives.value import GAE
from torchrl.objectives.value.functional import reward2go


class MonteCarloReturn:
    """advantage = value_target = discounted reward-to-go within each episode, no baseline and no
    bootstrap (REINFORCE as in Gymnasium's tutorial). An episode cut by the batch end counts only
    the rewards inside the batch, so batches should hold whole episodes."""

    def __init__(self, gamma: float, critic):
        self.gamma = gamma
        self.critic = critic  # still evaluated: explained variance and the critic's own loss

    def __call__(self, batch: TensorDictBase) -> TensorDictBase:
        reward = batch.get(("next", "reward"))
        done = batch.get(("next", "done"))
        returns = reward2go(reward, done, self.gamma, time_dim=-2)
        batch.set("advantage", returns)
        batch.set("value_target", returns)
        self.critic(batch)
        return batch


ESTIMATORS = ("gae", "mc")  # advantage=gae|mc (validated in validation.py)


def make_advantage(cfg, critic):
    if cfg.name == "mc":
        return MonteCarloReturn(cfg.gamma, critic)
    # vectorized: TorchRL's closed-form GAE (a discounted cumulative sum), not its per-step loop;
    # the same advantages to ~1e-6, 18 ms -> 3 ms per 2048-frame batch here.
    return GAE(gamma=cfg.gamma, lmbda=cfg.lmbda, value_network=critic, average_gae=False, vectorized=True)


def explained_variance(batch: TensorDictBase) -> float:
    """1 - Var[returns - values] / Var[returns], from GAE's outputs (CleanRL's diagnostic)."""
    values = batch.get("state_value").reshape(-1)
    targets = batch.get("value_target").reshape(-1)
    var = targets.var()
    return float("nan") if var == 0 else float(1 - (targets - values).var() / var)
