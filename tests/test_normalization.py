import numpy as np

from ppo_torchrl.envs.normalization import ReturnNormalizer, RunningMeanStd


def test_running_stats_match_numpy_whatever_the_batching():
    data = np.random.default_rng(0).normal(3.0, 2.0, size=(500, 4))
    one_by_one, in_chunks = RunningMeanStd((4,), prior_count=0), RunningMeanStd((4,), prior_count=0)
    for row in data:
        one_by_one.update(row[None])
    for chunk in np.split(data, 10):
        in_chunks.update(chunk)
    for stats in (one_by_one, in_chunks):
        np.testing.assert_allclose(stats.mean, data.mean(0), rtol=1e-6)
        np.testing.assert_allclose(stats.var, data.var(0), rtol=1e-9)  # exact: no prior count
    frozen = RunningMeanStd((4,))
    frozen.frozen = True
    frozen.update(data)
    assert frozen.count == 1e-4


def test_return_normalizer_scales_by_discounted_return_std_and_resets_on_done():
    norm = ReturnNormalizer(num_envs=1, gamma=0.5, clip=None)
    norm(np.array([1.0]), np.array([False]))
    norm(np.array([1.0]), np.array([True]))  # discounted return 1.5, then reset
    assert norm.returns[0] == 0.0
    np.testing.assert_allclose(norm.stats.mean, (1.0 + 1.5) / 2, rtol=1e-3)
    scaled = norm.scale(np.array([2.0]))
    np.testing.assert_allclose(scaled, 2.0 / np.sqrt(norm.stats.var + 1e-8))


def test_one_env_return_scaling_is_the_array_arithmetic_bit_for_bit():
    """One env takes a Python-float path (normalization.ReturnNormalizer); it must give exactly what the
    array arithmetic of several envs gives, step by step, clipping and resets included."""
    rng = np.random.default_rng(0)
    one = ReturnNormalizer(num_envs=1, gamma=0.99, clip=3.0)
    stats, returns = RunningMeanStd(()), np.zeros(1)
    for _ in range(2000):
        reward, done = rng.normal(size=1) * 5.0, np.array([rng.random() < 0.02])
        got = one(reward, done)
        returns = returns * 0.99 + reward
        stats.update(returns)
        returns[done] = 0.0
        want = np.minimum(np.maximum(reward / np.sqrt(stats.var + 1e-8), -3.0), 3.0)
        assert got == want[0] and one.returns[0] == returns[0]
    assert (one.stats.mean, one.stats.var, one.stats.count) == (stats.mean, stats.var, stats.count)
    assert np.array_equal(one.stats.state_dict()["var"], stats.state_dict()["var"])


def test_both_backends_normalizers_give_numpys_mean_and_var_of_the_same_stream():
    """A real Hopper-v4 stream (random actions, resets included) through the ObservationNormalization
    transform, as TorchRL's Collector runs it, and through its numpy face, as the fast collector calls it:
    both equal numpy's."""
    import torch
    from torchrl.envs import RenameTransform

    from ppo_torchrl.envs.make import make_torchrl_env
    from ppo_torchrl.envs.state import env_state_of
    from ppo_torchrl.envs.normalization import ObservationNormalizer, obs_scale

    from conftest import compose_config

    cfg = compose_config(["env=gym", "env.id=Hopper-v4", "env.max_episode_steps=50"])
    env = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99)
    # a copy of the raw observation ahead of the normalizer: the stream it sees
    env.insert_transform(0, RenameTransform(["observation"], ["raw"], create_copy=True))
    env.set_seed(0)
    torch.manual_seed(0)
    rollout = env.rollout(2000, break_when_any_done=False)
    raw, nxt, done = rollout["raw"], rollout["next", "raw"], rollout["next", "done"].squeeze(-1)
    stream = [raw[0]]  # the first reset, then each step's next observation and each reset's
    for t in range(len(rollout)):
        stream.append(nxt[t])
        if done[t] and t + 1 < len(rollout):
            stream.append(raw[t + 1])
    stream = torch.stack(stream).double().numpy()
    assert done.sum() >= 20 and stream.shape[0] == 1 + 2000 + int(done[:-1].sum())

    vecnorm = env_state_of(env).obs_norm.state_dict()
    assert vecnorm["count"] == len(stream)
    fast = ObservationNormalizer((stream.shape[1],), clip=None)
    for row in stream:
        fast(row[None])
    for stats in (vecnorm, fast.stats.state_dict()):
        np.testing.assert_allclose(stats["mean"], stream.mean(0), rtol=1e-6)
        np.testing.assert_allclose(stats["var"], stream.var(0), rtol=1e-6)
    # and the same scale on both paths
    np.testing.assert_allclose(obs_scale(fast.stats.var, 1e-8), np.sqrt(vecnorm["var"]), rtol=1e-6)
