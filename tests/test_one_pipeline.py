"""One pipeline at three scales: FastCollector is a TorchRL collector that TorchRL's own multi-process
collector runs, workers resume their episodes exactly, and the observation formula exists once."""

import functools

import numpy as np
import pytest
import torch
from torchrl.collectors import Collector, MultiSyncCollector

from ppo_torchrl.collectors import describe_backend, make_collector
from ppo_torchrl.collectors.fast import FastCollector
from ppo_torchrl.envs.make import env_spec, make_torchrl_env
from ppo_torchrl.rl.models import make_actor_critic
from ppo_torchrl.envs.normalization import make_observation_normalizer, standardize


def test_torchrls_multisync_collector_runs_the_fast_collector_as_its_collector_class(tiny_cfg):
    cfg = tiny_cfg()
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    assert issubclass(FastCollector, Collector)
    make_env = functools.partial(make_torchrl_env, cfg.env, clip_actions=ac.head == "normal", gamma=0.99)
    collector = MultiSyncCollector([make_env, make_env], ac.actor, collector_class=FastCollector,
                                   frames_per_batch=128, total_frames=256, cat_results="stack")
    try:
        batches = [batch for batch in collector]
    finally:
        collector.shutdown()
    assert len(batches) == 2 and tuple(batches[0].shape) == (2, 1, 64)  # [workers, envs, steps]
    for key in ("observation", "action", ("next", "reward"), ("next", "episode_reward"), ("collector", "traj_ids")):
        assert key in batches[0].keys(True)
    lows, highs = ac.action_low.numpy(), ac.action_high.numpy()
    actions = batches[1]["action"].numpy()
    assert np.isfinite(actions).all() and actions.std() > 0 and lows.shape == highs.shape


@pytest.mark.parametrize("scale", [["collector.workers=2", "collector.num_envs=2"], ["collector.num_envs=4"],
                                   ["collector.backend=torchrl", "collector.num_envs=4"],
                                   ["collector.backend=torchrl", "collector.workers=2", "collector.num_envs=2"]])
def test_a_resume_collects_the_batch_the_uninterrupted_run_collects(tiny_cfg, scale):
    """One resume path (Collection.load_state_dict -> the collector's load_state_dict -> each EnvState's
    snapshot and the collector's own RNG): each env's position, the statistics, running returns and
    exploration RNG come back from the checkpoint, the batch after a resume is the batch the uninterrupted
    run collects (each collector in workers or in one process; in one process the torch RNG also set as the
    trainer does)."""
    cfg = tiny_cfg(*scale, "env.max_episode_steps=40")
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    first = make_collector(cfg, ac, 3, torch.device("cpu"))
    second = None
    try:
        for _ in range(2):
            first.collect()
        state, rng = first.state_dict(), torch.get_rng_state()
        uninterrupted = first.collect()
        second = make_collector(cfg, ac, 77, torch.device("cpu"))  # another seed: everything must come from state
        second.load_state_dict(state)
        torch.set_rng_state(rng)  # the checkpoint's (TorchRL's Collector draws with torch in this process)
        resumed = second.collect()
        for key in uninterrupted.keys(True, True):
            assert torch.equal(uninterrupted[key], resumed[key]), key
        assert first.obs_stats()["count"] == second.obs_stats()["count"]
    finally:
        first.close()
        if second is not None:
            second.close()


def test_the_observation_formula_is_one_for_numpy_torch_the_transform_and_export(tiny_cfg):
    cfg = tiny_cfg()
    rng = np.random.default_rng(0)
    stats = {"mean": rng.normal(size=4), "var": rng.uniform(0.0, 3.0, size=4), "count": 50.0}
    norm = make_observation_normalizer(cfg.env.transforms, 4, stats, frozen=True)
    obs = rng.normal(scale=30, size=(100, 4))
    numpy_face = norm(obs)  # what the fast collector computes
    module = norm.module()(torch.as_tensor(obs)).float().numpy()  # what export bakes in
    env = make_torchrl_env(cfg.env, clip_actions=False, gamma=0.99, obs_stats=stats, train=False)
    transform = next(t for t in env.transform if type(t).__name__ == "ObservationNormalization")
    torchrl_face = transform._apply_transform(torch.as_tensor(obs)).numpy()
    assert np.array_equal(numpy_face, module) and np.array_equal(numpy_face, torchrl_face)
    scale = np.maximum(np.sqrt(stats["var"]), cfg.env.transforms.norm_epsilon)
    assert np.array_equal(standardize(obs, stats["mean"], scale, 10.0), np.clip((obs - stats["mean"]) / scale, -10, 10))
    assert np.abs(numpy_face).max() == 10.0  # clipped


def test_the_start_line_names_the_collector_and_why(tiny_cfg):
    assert describe_backend(tiny_cfg()) == ("FastCollector", "no env.transforms.extra")
    assert describe_backend(tiny_cfg("collector.workers=2")) == ("MultiSyncCollector(FastCollector x 2)",
                                                                 "no env.transforms.extra")
    extra = "env.transforms.extra=[{_target_: torchrl.envs.CatFrames, N: 3, dim: -1, in_keys: [observation]}]"
    name, why = describe_backend(tiny_cfg(extra, "collector.distributed=ray", "collector.workers=4"))
    assert name == "RayCollector(torchrl.Collector x 4)" and why.startswith("env.transforms.extra runs per step; ")
    assert "at collector.num_envs=1 ~42% of the fast collector's frames/s (measured at 1 env" in why
    _, why = describe_backend(tiny_cfg(extra, "collector.num_envs=12"))  # the nearest count measured below it
    assert "at collector.num_envs=12 ~72%" in why and "measured at 8 envs" in why and "amortize" in why


def test_a_change_to_the_one_formula_reaches_every_face(tiny_cfg, monkeypatch):
    """`normalization.standardize` changed in its one place: the fast rollout, TorchRL's Collector's env, the
    evaluation env and the exported module all follow."""
    import ppo_torchrl.envs.normalization as normalization

    monkeypatch.setattr(normalization, "standardize", lambda x, mean, scale, bound: x * 0 + 7)
    cfg = tiny_cfg()
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    stats = {"mean": np.zeros(4), "var": np.ones(4), "count": 1.0}
    fast = FastCollector(make_torchrl_env(cfg.env, clip_actions=ac.head == "normal", gamma=0.99, seed=0), ac.actor,
                         frames_per_batch=32, total_frames=32)
    stock = Collector(make_torchrl_env(cfg.env, clip_actions=ac.head == "normal", gamma=0.99, seed=0), ac.actor,
                      frames_per_batch=32, total_frames=32, auto_register_policy_transforms=False)
    evaluation = make_torchrl_env(cfg.env, clip_actions=False, gamma=0.99, obs_stats=stats, train=False)
    exported = make_observation_normalizer(cfg.env.transforms, 4, stats, frozen=True).module()
    try:
        for batch in (next(iter(fast)), next(iter(stock))):
            assert (batch["observation"] == 7).all() and (batch["next", "observation"] == 7).all()
        assert (evaluation.reset()["observation"] == 7).all()
        assert (exported(torch.randn(3, 4, dtype=torch.float64)) == 7).all()
    finally:
        fast.shutdown()
        stock.shutdown()


def test_episode_counts_have_one_owner_gymnasiums_counter_which_a_resumed_episode_carries_on(tiny_cfg):
    """TorchRL's path writes `episode_reward` / `step_count` from Gymnasium's RecordEpisodeStatistics (as
    the fast rollout reads them): the raw return so far, and after a restored position the saved episode
    goes on counting from where it was, not from 0."""
    from ppo_torchrl.envs.state import env_state_of

    cfg = tiny_cfg()
    stats = {"mean": np.zeros(4), "var": np.ones(4), "count": 2.0}
    make = functools.partial(make_torchrl_env, cfg.env, clip_actions=True, gamma=0.99, obs_stats=stats, train=False,
                             num_envs=2, seed=3)
    env = make()
    rollout = env.rollout(12, break_when_any_done=False)
    reward, done = rollout["next", "reward"].squeeze(-1), rollout["next", "done"].squeeze(-1)
    state = env_state_of(env)
    returns, lengths = state.episodes()
    for i in range(2):  # the episode so far since each env's last done
        start = int(done[i, :-1].nonzero().max()) + 1 if done[i, :-1].any() else 0
        assert rollout["next", "step_count"][i, -1].item() == lengths[i] == 12 - start
        assert rollout["next", "episode_reward"][i, -1].item() == pytest.approx(float(reward[i, start:].sum()), rel=1e-5)
    assert "RewardSum" not in str(env.transform) and "StepCounter" not in str(env.transform)

    again = make()
    again_state = env_state_of(again)
    again_state.restore({"positions": {"envs": state.positions(), "acted_on": None}})
    assert again_state.continue_episodes(now=False)
    first = again.reset()
    assert first["step_count"].squeeze(-1).tolist() == lengths.tolist()
    np.testing.assert_allclose(first["episode_reward"].squeeze(-1).numpy(), returns)


@pytest.mark.parametrize("scale", [[], ["collector.workers=2"]])
@pytest.mark.parametrize("backend", ["fast", "torchrl"])
def test_every_path_and_scale_counts_the_same(tiny_cfg, backend, scale):
    """The same accounting on every path (FastCollector, TorchRL's Collector) and scale (one process, two
    workers), 4 envs each: the observation statistics count each env's first observation once, every step's
    next observation and every reset after a done; the return statistics each frame once after their prior;
    each finished episode is logged once with Gymnasium's return and length; every env's position is in
    its EnvState's snapshot."""
    from ppo_torchrl.internals import env_snapshot, worker_parts

    envs = "collector.num_envs=2" if scale else "collector.num_envs=4"
    cfg = tiny_cfg(f"collector.backend={backend}", envs, *scale, "env.max_episode_steps=30")
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    collection = make_collector(cfg, ac, 5, torch.device("cpu"))
    try:
        batches = [collection.collect() for _ in range(3)]
        frames = sum(b.numel() for b in batches)
        dones = sum(int(b.get(("next", "done")).sum()) for b in batches)
        episodes = collection.pop_episodes()
        state = collection.state_dict()
        parts = worker_parts(state["collector"])
        positions = sum(len(env_snapshot(part, collection._key)["positions"]["envs"]) for part in parts)
    finally:
        collection.close()
    assert frames == 3 * cfg.collector.frames_per_batch and dones > 4
    assert state["obs"]["count"] == 4 + frames + dones
    assert state["return"]["count"] == pytest.approx(frames + 1e-4)
    assert len(episodes) == dones and all(0 < length <= 30 for _, length in episodes)
    assert positions == 4
