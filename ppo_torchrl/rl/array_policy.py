"""The evaluation's policy on raw observation arrays (any env: the batched robot env, a Playground pool): frozen
statistics in, actions out, deterministic or sampled."""
from typing import Optional

import numpy as np
import torch


def policy_of(cfg, ac, obs_stats: Optional[dict], obs_dim: int, layout, act_dim: int, rows: int, deterministic: bool,
              seed: int = 0):
    """The evaluation's policy for any env whose raw observations (`obs_dim`, in `layout`) come as [rows, obs_dim]
    arrays."""
    from ppo_torchrl.rl.models import NumpyPolicy
    from ppo_torchrl.envs.normalization import make_observation_normalizer

    t = cfg.env.transforms
    norm = make_observation_normalizer(t, obs_dim, obs_stats, frozen=True, layout=layout)
    if obs_stats is None:
        norm.enabled = False
    if ac.action_low.device.type != "cpu":
        import copy

        ac = copy.deepcopy(ac)
        ac.actor.cpu()
        ac.action_low, ac.action_high = ac.action_low.cpu(), ac.action_high.cpu()
    if deterministic:  # what a one-env evaluation's TorchRL env and actor compute, so its episodes to the bit
        from tensordict import TensorDict

        from ppo_torchrl.rl.models import deterministic_policy

        actor = deterministic_policy(ac)
        low, high = ac.action_low.numpy(), ac.action_high.numpy()

        def act(obs):  # row by row: a batched matmul rounds otherwise, and an episode would depend on its row count
            normalized = torch.from_numpy(norm(obs, update=False))
            out = [actor(TensorDict({"observation": normalized[i:i + 1]}, batch_size=[1]))["action"] for i in range(rows)]
            action = torch.cat(out).numpy()
            return np.clip(action, low, high) if ac.head == "normal" else action
    else:
        sampler, rng = NumpyPolicy.from_actor(ac.actor), np.random.default_rng(seed)
        sampler.sync()

        def act(obs):
            return sampler.act(norm(obs), rng.standard_normal((rows, act_dim), dtype=np.float32))[1]
    return act
