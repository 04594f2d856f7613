"""Deterministic evaluation on a separate TorchRL env with frozen normalization statistics.

The eval env is `TransformedEnv(GymEnv)` with an `ObservationNorm` holding the training stats (no
updates) and raw rewards, and the actor runs in DETERMINISTIC exploration mode (the mean, squashed
or clipped to the bounds). It shares no state with the training envs.
"""

from __future__ import annotations

import copy
from typing import Optional

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl.envs import episode_seeds, make_torchrl_env
from ppo_torchrl.models import ActorCritic


@torch.no_grad()
def evaluate_policy(cfg, ac: ActorCritic, obs_stats: Optional[dict], episodes: int, seed: int,
                    deterministic: bool = True) -> dict:
    env = make_torchrl_env(cfg.env, clip_actions=ac.head == "normal", gamma=cfg.advantage.gamma,
                           obs_stats=obs_stats, train=False)
    # The simulator runs on CPU; a CPU copy of the (small) actor avoids device hops per step.
    actor = ac.actor if ac.action_low.device.type == "cpu" else copy.deepcopy(ac.actor).cpu()
    mode = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    returns, lengths = [], []
    try:
        with set_exploration_type(mode):
            for episode_seed in episode_seeds(seed, episodes):
                env.set_seed(episode_seed)
                rollout = env.rollout(max_steps=1_000_000, policy=actor, break_when_any_done=True)
                returns.append(float(rollout.get(("next", "reward")).sum()))
                lengths.append(int(rollout.shape[-1]))
    finally:
        env.close()
    return {
        "return_mean": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "length_mean": float(np.mean(lengths)),
        "returns": returns,
        "lengths": lengths,
    }
