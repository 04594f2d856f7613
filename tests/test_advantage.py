"""GAE against a hand-computed example: bootstrap on truncation, not on termination."""

import torch
from tensordict import TensorDict
from torch import nn
from torchrl.modules import ValueOperator

from ppo_torchrl.rl.advantage import explained_variance, make_advantage
from conftest import compose_config


class ObsIsValue(nn.Module):
    def forward(self, obs):
        return obs[..., :1]


def test_gae_bootstraps_on_truncation_and_not_on_termination():
    gamma, lmbda = 0.9, 0.8
    cfg = compose_config([f"advantage.gamma={gamma}", f"advantage.lmbda={lmbda}"]).advantage
    critic = ValueOperator(ObsIsValue(), in_keys=["observation"])
    # One env, 4 steps. The value of a state is its observation.
    # t=0: ordinary step; t=1: terminated (no bootstrap); t=2: new episode, truncated at t=2
    # (bootstrap from the final observation, value 5.0); t=3: ordinary step, batch ends (bootstrap 7.0).
    v = [1.0, 2.0, 3.0, 4.0]
    v_next = [2.0, 9.0, 5.0, 7.0]  # 9.0 after termination must be ignored
    r = [1.0, 1.0, 1.0, 1.0]
    term = [False, True, False, False]
    trunc = [False, False, True, False]
    td = TensorDict(
        {
            "observation": torch.tensor(v).view(1, 4, 1),
            "next": {
                "observation": torch.tensor(v_next).view(1, 4, 1),
                "reward": torch.tensor(r).view(1, 4, 1),
                "terminated": torch.tensor(term).view(1, 4, 1),
                "truncated": torch.tensor(trunc).view(1, 4, 1),
                "done": (torch.tensor(term) | torch.tensor(trunc)).view(1, 4, 1),
            },
        },
        batch_size=[1, 4],
    )
    make_advantage(cfg, critic)(td)

    # by hand, backwards
    d3 = 1 + gamma * 7.0 - 4.0            # bootstrap at the batch end
    a3 = d3
    d2 = 1 + gamma * 5.0 - 3.0            # truncated: bootstrap from the final obs
    a2 = d2                                # ...but the recursion stops at done
    d1 = 1 + 0.0 - 2.0                    # terminated: no bootstrap
    a1 = d1
    d0 = 1 + gamma * 2.0 - 1.0
    a0 = d0 + gamma * lmbda * a1
    expected = torch.tensor([a0, a1, a2, a3])
    torch.testing.assert_close(td["advantage"].view(-1), expected)
    torch.testing.assert_close(td["value_target"].view(-1), expected + torch.tensor(v))


def test_explained_variance():
    td = TensorDict({"state_value": torch.tensor([1.0, 2.0, 3.0]), "value_target": torch.tensor([1.0, 2.0, 3.0])}, [3])
    assert explained_variance(td) == 1.0
    td["state_value"] = torch.zeros(3)
    assert explained_variance(td) < 0.01


def test_monte_carlo_return_resets_at_episode_ends():
    cfg = compose_config(["advantage=mc", "advantage.gamma=0.5"]).advantage
    critic = ValueOperator(ObsIsValue(), in_keys=["observation"])
    done = torch.tensor([False, True, False, False]).view(1, 4, 1)
    td = TensorDict({"observation": torch.zeros(1, 4, 1),
                     "next": {"reward": torch.ones(1, 4, 1), "done": done, "terminated": done}}, [1, 4])
    make_advantage(cfg, critic)(td)
    torch.testing.assert_close(td["advantage"].view(-1), torch.tensor([1.5, 1.0, 1.5, 1.0]))
    assert "state_value" in td.keys()
