import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.modules import TanhNormal

from ppo_torchrl.envs import EnvSpec
from ppo_torchrl.models import deterministic_action, make_actor_critic, sample_action
from conftest import compose_config

SPEC = EnvSpec(obs_dim=5, action_dim=2, action_low=np.array([-1.0, -3.0], np.float32),
               action_high=np.array([1.0, 3.0], np.float32))


def build(*overrides):
    return make_actor_critic(compose_config(list(overrides)).policy, SPEC)


def test_tanh_sample_matches_torchrl_tanh_normal():
    ac = build("policy=tanh_normal")
    loc, scale = torch.randn(64, 2), torch.rand(64, 2) + 0.1
    torch.manual_seed(0)
    ours, to_env = sample_action(ac, loc, scale)
    torch.manual_seed(0)
    theirs = TanhNormal(loc, scale, low=ac.action_low, high=ac.action_high).rsample()
    torch.testing.assert_close(ours, theirs)
    assert torch.equal(ours, to_env)
    assert (ours >= ac.action_low).all() and (ours <= ac.action_high).all()


def test_normal_stores_raw_sample_and_clips_what_the_env_gets():
    ac = build("policy=normal")
    loc = torch.tensor([[5.0, -5.0]])
    stored, to_env = sample_action(ac, loc, torch.full((1, 2), 1e-3))
    assert stored[0, 0] > 4.9 and stored[0, 1] < -4.9
    torch.testing.assert_close(to_env, torch.tensor([[1.0, -3.0]]))
    torch.testing.assert_close(deterministic_action(ac, loc), torch.tensor([[1.0, -3.0]]))


def test_actor_log_prob_of_fast_path_actions_is_finite():
    for head in ("normal", "tanh_normal"):
        ac = build(f"policy={head}")
        obs = torch.randn(32, 5)
        loc, scale = ac.policy_net(obs)
        action, _ = sample_action(ac, loc, scale)
        td = TensorDict({"observation": obs, "action": action}, [32])
        lp = ac.actor.get_dist(td).log_prob(action)
        assert lp.shape == (32,) and torch.isfinite(lp).all()


def test_initialization_and_std_options():
    ac = build()
    head = ac.policy_net[1]
    assert head.loc.weight.abs().max() < 0.05  # policy head gain 0.01
    torch.testing.assert_close(head.log_std, torch.zeros(2))
    ac = build("policy.std=state_dependent", "policy.std_min=0.6", "policy.log_std_init=-1.0")
    _, scale = ac.policy_net(torch.zeros(4, 5))
    torch.testing.assert_close(scale, torch.full((4, 2), float(np.exp(-1.0)) + 0.6), atol=1e-4, rtol=0)


def test_shared_trunk_shares_parameters():
    ac = build("policy.shared_trunk=true")
    actor_params = {id(p) for p in ac.actor.parameters()}
    critic_params = {id(p) for p in ac.critic.parameters()}
    assert actor_params & critic_params  # the trunk
    assert actor_params - critic_params and critic_params - actor_params  # the heads
    td = ac.critic(TensorDict({"observation": torch.randn(3, 5)}, [3]))
    assert td["state_value"].shape == (3, 1)


def test_bad_policy_option_is_a_config_error():
    from ppo_torchrl.errors import ConfigError

    with pytest.raises(ConfigError, match="policy.head"):
        build("policy.head=beta")


def test_torchrl_env_clips_the_action_it_receives_per_dimension():
    from ppo_torchrl.envs import ClipActionToBounds

    clip = ClipActionToBounds(torch.tensor([-1.0, -0.4]), torch.tensor([1.0, 0.4]))
    td = clip.inv(TensorDict({"action": torch.tensor([[3.0, -3.0]])}, [1]))
    torch.testing.assert_close(td["action"], torch.tensor([[1.0, -0.4]]))
