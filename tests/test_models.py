import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.modules import TanhNormal

from ppo_torchrl.envs.make import EnvSpec
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl.rl.models import NumpyPolicy, deterministic_action, deterministic_policy, make_actor_critic
from conftest import compose_config

SPEC = EnvSpec(obs_dim=5, action_dim=2, action_low=np.array([-1.0, -3.0], np.float32),
               action_high=np.array([1.0, 3.0], np.float32))


def build(*overrides):
    return make_actor_critic(compose_config(list(overrides)).policy, SPEC)


def draw(ac, obs: torch.Tensor, seed: int = 0):
    """NumpyPolicy's draw with the noise torch's own rsample would use under the same seed."""
    torch.manual_seed(seed)
    noise = torch.randn(obs.shape[0], SPEC.action_dim).numpy()
    return NumpyPolicy.from_actor(ac.actor).act(obs.numpy(), noise)


@pytest.mark.parametrize("overrides", [["policy=tanh_normal"], ["policy=tanh_normal", "policy.std=state_dependent",
                                                                 "policy.activation=elu", "policy.std_min=0.2"]])
def test_numpy_policy_draws_what_torchrl_tanh_normal_draws(overrides):
    ac = build(*overrides)
    obs = torch.randn(64, 5)
    with torch.no_grad():
        loc, scale = ac.policy_net(obs)
        torch.manual_seed(0)
        theirs = TanhNormal(loc, scale, low=ac.action_low, high=ac.action_high).rsample()
    ours, to_env = draw(ac, obs)
    torch.testing.assert_close(torch.from_numpy(ours), theirs, atol=1e-5, rtol=1e-5)
    assert np.array_equal(ours, to_env)
    assert (ours >= SPEC.action_low).all() and (ours <= SPEC.action_high).all()


def test_numpy_policy_follows_the_weights_after_sync():
    ac = build("policy=tanh_normal", "policy.activation=relu", "policy.shared_trunk=true")
    policy = NumpyPolicy.from_actor(ac.actor)
    obs = torch.randn(8, 5)
    with torch.no_grad():
        for p in ac.policy_net.parameters():
            p.add_(0.1)
        loc, scale = ac.policy_net(obs)
    assert not np.allclose(policy.loc_scale(obs.numpy())[0], loc.numpy(), atol=1e-4)  # still the old copy
    policy.sync()
    new_loc, new_scale = policy.loc_scale(obs.numpy())
    np.testing.assert_allclose(new_loc, loc.numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(np.broadcast_to(new_scale, scale.shape), scale.numpy(), rtol=1e-5, atol=1e-5)


def test_normal_stores_raw_sample_and_clips_what_the_env_gets():
    ac = build("policy=normal")
    policy = NumpyPolicy.from_actor(ac.actor)
    policy.loc_scale = lambda obs: (np.array([[5.0, -5.0]], np.float32), np.full((1, 2), 1e-3, np.float32))
    stored, to_env = policy.act(np.zeros((1, 5), np.float32), np.zeros((1, 2), np.float32))
    assert stored[0, 0] > 4.9 and stored[0, 1] < -4.9
    np.testing.assert_allclose(to_env, [[1.0, -3.0]])
    torch.testing.assert_close(deterministic_action(ac, torch.tensor([[5.0, -5.0]])), torch.tensor([[1.0, -3.0]]))


def test_actor_log_prob_of_fast_path_actions_is_finite():
    for head in ("normal", "tanh_normal"):
        ac = build(f"policy={head}")
        obs = torch.randn(32, 5)
        action, _ = draw(ac, obs)
        action = torch.from_numpy(action)
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
    from ppo_torchrl.envs.make import ClipActionToBounds

    clip = ClipActionToBounds(torch.tensor([-1.0, -0.4]), torch.tensor([1.0, 0.4]))
    td = clip.inv(TensorDict({"action": torch.tensor([[3.0, -3.0]])}, [1]))
    torch.testing.assert_close(td["action"], torch.tensor([[1.0, -0.4]]))


@pytest.mark.parametrize("head", ["normal", "tanh_normal"])
def test_deterministic_policy_is_the_actor_in_deterministic_mode(head):
    """The eval's light policy gives the env exactly what the ProbabilisticActor does in DETERMINISTIC mode
    (a normal head's action clipped to the bounds, as the eval env's ClipActionToBounds does)."""
    ac = build(f"policy={head}", "policy.policy_head_gain=3.0")  # big means: some actions out of bounds
    obs = torch.randn(256, 5) * 3
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        theirs = ac.actor(TensorDict({"observation": obs}, [256]))["action"]
        ours = deterministic_policy(ac)(TensorDict({"observation": obs}, [256]))["action"]
    low, high = torch.as_tensor(SPEC.action_low), torch.as_tensor(SPEC.action_high)
    if head == "normal":
        assert ((theirs < low) | (theirs > high)).any()
        theirs = torch.maximum(torch.minimum(theirs, high), low)
    assert torch.equal(ours, theirs)


def test_evaluate_and_the_exported_policy_act_alike_to_the_bit(tmp_path):
    """One map from mean to action (models.to_bounds) and one normalization arithmetic (float64, as the eval
    env's ObservationNorm): on 1,000 observations, most of them saturating the bounds, the same actions."""
    from ppo_torchrl.envs.make import env_spec, make_torchrl_env
    from ppo_torchrl.export import export_policy

    cfg = compose_config(["env=Hopper-v4"])
    spec = env_spec(cfg.env)
    torch.manual_seed(0)
    ac = make_actor_critic(cfg.policy, spec)
    with torch.no_grad():  # a large last layer: most actions at the bounds
        [m for m in ac.policy_net.modules() if isinstance(m, torch.nn.Linear)][-1].weight.mul_(500.0)
    rng = np.random.default_rng(0)
    stats = {"mean": rng.normal(size=spec.obs_dim), "var": rng.uniform(0.01, 4, size=spec.obs_dim), "count": 100.0}
    obs = torch.as_tensor(rng.normal(scale=5, size=(1000, spec.obs_dim)))
    td = TensorDict({"observation": obs}, [1000])
    env = make_torchrl_env(cfg.env, clip_actions=False, gamma=0.99, obs_stats=stats, train=False)
    for transform in env.transform:  # the eval env's observation path: frozen norm, clip, to float32
        if "observation" in transform.in_keys:
            td = transform(td)
    evaluated = deterministic_policy(ac)(td)["action"]
    exported = torch.jit.load(str(export_policy(cfg, ac, stats, tmp_path / "policy.pt")))(obs)
    assert (evaluated.abs() > 0.999).float().mean() > 0.5
    assert torch.equal(evaluated, exported)


def test_std_max_caps_the_std_on_every_face_and_stops_the_entropy_pull():
    """policy.std_max (recipe v2's exploration cap): the torch net, the numpy copy the fast collector samples with,
    and the gradient of an entropy bonus past the cap (none: the std cannot grow without bound)."""
    from ppo_torchrl.errors import ConfigError

    for std in ("state_independent", "state_dependent"):
        ac = build("policy.std=" + std, "policy.log_std_init=0.5", "policy.std_min=0.1", "policy.std_max=0.6")
        obs = torch.randn(5, SPEC.obs_dim)
        loc, scale = ac.policy_net(obs)
        assert torch.allclose(scale, torch.full_like(scale, 0.6))  # exp(0.5) + 0.1 = 1.75, capped at 0.6
        _, np_scale = NumpyPolicy.from_actor(ac.actor).loc_scale(obs.numpy())
        assert np.allclose(np_scale, 0.6)
        scale.log().sum().backward()  # an entropy bonus's pull on the std
        grads = [p.grad for n, p in ac.policy_net.named_parameters() if "std" in n or "scale" in n]
        assert grads and all(g is None or not g.any() for g in grads)
    with pytest.raises(ConfigError, match="std_max"):
        build("policy.std_min=0.2", "policy.std_max=0.1")
