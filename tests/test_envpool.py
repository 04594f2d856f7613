"""EnvPool (C++ MuJoCo, `collector.backend=envpool`) against Gymnasium: the same task, measured (issue 62, item 2).

Both start from the same state (reset_noise_scale=0 in both: the model's initial pose), take the same actions
(uniform in the action bounds) and restart at every episode's end (EnvPool's auto-reset step, whose action it
ignores, is stepped apart and compared with Gymnasium's reset). 2,000 steps per env, 10,000 in all.

What holds (EnvPool 1.2.5 runs MuJoCo 3.6.0; Gymnasium here runs mujoco 4.0.0):
- Hopper-v4, Walker2d-v4: whole episodes (about 90 each) agree: observations to ~1e-12 (relative to max(1, |x|)),
  rewards to ~1e-7 (EnvPool returns float32 rewards), terminations identical;
- HalfCheetah-v4: the same to ~1e-12 over the first 10 steps of an episode, ~1e-9 at 20; round-off then grows
  (chaotic dynamics): 3e-4 at step 50, O(1) by 100. Compared over 20-step episodes (time limit 20 in both);
- Ant-v4, Humanoid-v4: ~1e-5 after one step from the same state (the contact solver of two MuJoCo versions),
  ~1e-4 after three, O(0.1-1) within 5-10 steps. Compared over 3-step episodes.
The long-run agreement of the contact-rich envs is therefore statistical (learning), not per step.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

envpool = pytest.importorskip("envpool")
import gymnasium as gym  # noqa: E402

STEPS = 2000
# env id -> (episode length compared (None: the env's own episodes), obs tolerance, reward tolerance)
CASES = {
    "Hopper-v4": (None, 1e-9, 1e-6),
    "Walker2d-v4": (None, 1e-9, 1e-6),
    "HalfCheetah-v4": (20, 1e-7, 1e-6),
    "Ant-v4": (3, 5e-4, 5e-4),
    "Humanoid-v4": (3, 5e-4, 5e-4),
}


def compare(env_id: str, horizon, steps: int = STEPS) -> dict:
    limit = {} if horizon is None else {"max_episode_steps": horizon}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = gym.make(env_id, reset_noise_scale=0.0, disable_env_checker=True, **limit)
    p = envpool.make(env_id, env_type="gymnasium", num_envs=1, seed=0, reset_noise_scale=0.0, **limit)
    obs, _ = g.reset(seed=0)
    pobs, _ = p.reset()
    rng = np.random.default_rng(0)
    low, high = g.action_space.low, g.action_space.high
    worst = {"obs": float(np.abs(obs - pobs[0]).max()), "reward": 0.0, "done_mismatch": 0, "episodes": 0,
             "reset_obs": 0.0}
    for _ in range(steps):
        action = rng.uniform(low, high)
        obs, reward, term, trunc, _ = g.step(action)
        pobs, preward, pterm, ptrunc, _ = p.step(action[None])
        worst["obs"] = max(worst["obs"], float((np.abs(obs - pobs[0]) / np.maximum(1.0, np.abs(obs))).max()))
        worst["reward"] = max(worst["reward"], abs(float(reward) - float(preward[0])))
        worst["done_mismatch"] += int(term != pterm[0] or trunc != ptrunc[0])
        if term or trunc:
            worst["episodes"] += 1
            obs, _ = g.reset()
            # EnvPool's auto-reset step: the action is ignored, the reward is 0, the observation the new start
            pobs, preward, pterm, ptrunc, info = p.step(np.zeros((1, low.shape[0])))
            assert info["elapsed_step"][0] == 0 and preward[0] == 0 and not (pterm[0] or ptrunc[0])
            worst["reset_obs"] = max(worst["reset_obs"], float(np.abs(obs - pobs[0]).max()))
    p.close()
    g.close()
    return worst


@pytest.mark.parametrize("env_id", list(CASES))
def test_same_task_as_gymnasium(env_id):
    horizon, obs_tol, reward_tol = CASES[env_id]
    worst = compare(env_id, horizon)
    print(env_id, worst)
    assert worst["done_mismatch"] == 0, worst
    assert worst["reset_obs"] <= 1e-12, worst  # the same start (Humanoid: 1e-16 in derived quantities)
    assert worst["obs"] <= obs_tol, worst
    assert worst["reward"] <= reward_tol, worst
    assert worst["episodes"] >= (10 if horizon is None else STEPS // horizon - 1), worst


# ---------------------------------------------------------------------------- collector.backend=envpool
def test_the_reset_step_never_enters_a_batch(tiny_cfg):
    """Every transition of a batch is a real step: within an episode each next observation is the next step's
    observation, the episode counters count 1, 2, 3, ... and restart at 1 after an end; every pool step that was
    EnvPool's auto-reset step (elapsed_step 0) went to the ended envs alone and is in no batch."""
    import torch

    from ppo_torchrl.collectors import make_collector
    from ppo_torchrl.collectors.envpool_backend import EnvpoolCollector
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.rl.models import make_actor_critic

    cfg = tiny_cfg("env=Hopper-v4", "collector.backend=envpool", "collector.num_envs=4",
                   "collector.frames_per_batch=1024", "env.max_episode_steps=30")
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    collection = make_collector(cfg, ac, 3, torch.device("cpu"))
    try:
        assert isinstance(collection.collector, EnvpoolCollector)
        collection.collector._current_obs()  # the pool, built
        pool = collection.collector.pool
        calls = []
        step = pool.step

        def counted(action, env_id=None):
            out = step(action, env_id)
            calls.append((len(env_id), bool((out[4]["elapsed_step"] == 0).all())))
            return out

        pool.step = counted
        batches = [collection.collect() for _ in range(3)]
        episodes = collection.pop_episodes()
    finally:
        collection.close()
    resets = [n for n, reset in calls if reset]
    assert resets  # auto-reset steps happened, each for the ended envs alone ...
    assert sum(1 for n, reset in calls if not reset) == 3 * 256  # ... and only batch steps are full steps
    ended = 0
    for batch in batches:
        done = batch["next", "done"].squeeze(-1)
        obs, nxt = batch["observation"], batch["next", "observation"]
        for i in range(batch.shape[0]):
            for t in range(batch.shape[1] - 1):
                if not done[i, t]:  # the next transition starts where this one ended
                    assert torch.equal(nxt[i, t], obs[i, t + 1])
        ended += int(done.sum())
    assert ended == sum(resets) and len(episodes) == ended  # each end: one reset step, one logged episode
    assert all(length <= 30 for _, length in episodes) and any(length == 30 for _, length in episodes)


def test_a_bad_combination_is_one_line():
    from ppo_torchrl.collectors import resolve_backend
    from ppo_torchrl.errors import ConfigError

    from conftest import compose_config

    for overrides, says in [(["env=InvertedPendulum-v4", "env.id=MountainCarContinuous-v0"], "not env.id"),
                            (["env=Hopper-v4", "+env.make_kwargs.foo=1"], "env.make_kwargs.foo")]:
        cfg = compose_config([*overrides, "collector.backend=envpool"])
        with pytest.raises(ConfigError, match=says):
            resolve_backend(cfg)


def test_a_resume_keeps_statistics_and_rng_and_starts_new_episodes(tiny_cfg):
    """The stated limit: EnvPool cannot restore a simulator state. A resumed collector has the checkpoint's
    statistics and RNG; each env starts a new episode (its first step counts 1); two resumes from one
    checkpoint collect the same batch."""
    import torch

    from ppo_torchrl.collectors import make_collector
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.rl.models import make_actor_critic

    cfg = tiny_cfg("env=Hopper-v4", "collector.backend=envpool", "collector.num_envs=2")
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    first = make_collector(cfg, ac, 3, torch.device("cpu"))
    try:
        first.collect()
        first.collect()
        state = first.state_dict()
    finally:
        first.close()
    batches = []
    for seed in (77, 78):  # other seeds: everything must come from the state
        resumed = make_collector(cfg, ac, seed, torch.device("cpu"))
        try:
            resumed.load_state_dict(state)
            assert resumed.obs_stats()["count"] == state["obs"]["count"]
            batches.append(resumed.collect())
            assert (resumed.collector._out["next", "step_count"][:, 0] == 1).all()  # new episodes (the full batch)
        finally:
            resumed.close()
    for key in batches[0].keys(True, True):
        assert torch.equal(batches[0][key], batches[1][key]), key


def test_the_cli_trains_checkpoints_evaluates_and_resumes_with_envpool(tmp_path):
    from conftest import TINY, run_cli
    from ppo_torchrl.collectors.envpool_backend import RESUME_LIMIT

    result = run_cli("env=Hopper-v4", "collector.backend=envpool", *TINY, f"hydra.run.dir={tmp_path}")
    assert result.returncode == 0, result.stderr[-2000:]
    assert "EnvpoolCollector" in result.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["frames"] == 512 and summary["eval_return_mean"] is not None
    assert (tmp_path / "checkpoints" / "last.pt").is_file()
    more = run_cli(f"resume={tmp_path}", "collector.total_frames=768")
    assert more.returncode == 0, more.stderr[-2000:]
    assert RESUME_LIMIT in more.stderr
    assert json.loads((tmp_path / "summary.json").read_text())["frames"] == 768
    bad = run_cli("env=gym", "env.id=MountainCarContinuous-v0", "collector.backend=envpool", *TINY,
                  f"hydra.run.dir={tmp_path / 'bad'}")
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines()[-1].startswith("error: collector.backend=envpool"), bad.stderr[-500:]


def test_torchrls_multisync_collector_runs_it_in_workers(tiny_cfg):
    """collector.workers=2: TorchRL's MultiSyncCollector builds EnvpoolCollector in each worker; the workers'
    statistics are pooled as on the Gymnasium path."""
    import torch

    from ppo_torchrl.collectors import make_collector
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.rl.models import make_actor_critic

    cfg = tiny_cfg("env=Hopper-v4", "collector.backend=envpool", "collector.workers=2", "collector.num_envs=2")
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    collection = make_collector(cfg, ac, 3, torch.device("cpu"))
    try:
        batches = [collection.collect() for _ in range(2)]
        count = collection.obs_stats()["count"]
    finally:
        collection.close()
    assert tuple(batches[0].shape) == (4, 64)
    assert count >= 2 * 256  # every worker's observations, pooled
    assert not torch.equal(batches[1]["observation"][0], batches[1]["observation"][2])  # the workers differ
