import numpy as np

from ppo_torchrl.normalization import ReturnNormalizer, RunningMeanStd


def test_running_stats_match_numpy_whatever_the_batching():
    data = np.random.default_rng(0).normal(3.0, 2.0, size=(500, 4))
    one_by_one, in_chunks = RunningMeanStd((4,)), RunningMeanStd((4,))
    for row in data:
        one_by_one.update(row[None])
    for chunk in np.split(data, 10):
        in_chunks.update(chunk)
    for stats in (one_by_one, in_chunks):
        np.testing.assert_allclose(stats.mean, data.mean(0), rtol=1e-6)
        np.testing.assert_allclose(stats.var, data.var(0), rtol=1e-4)  # the 1e-4 prior count
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
