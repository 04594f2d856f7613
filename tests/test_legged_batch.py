"""The batched legged env (issue 72) against the locomotion env it replaces for env=legged (robots/env.py, Ant-v5's
class with its mixins): the same model, and from the same state under the same actions the same physics states
bit for bit, the observations and every reward term to float tolerance, the same episode ends and resets, over
2,000 control steps on two robots; N rows are N such envs, whatever the number of physics threads; a resumed run
logs what the uninterrupted one would.
"""

import numpy as np
import pytest

from ppo_torchrl.envs import gym_make_kwargs, make_gym_env
from ppo_torchrl.tasks.locomotion.batch import LeggedBatchEnv

from conftest import compose_config

GO1, ANYMAL = "menagerie/unitree_go1/scene.xml", "menagerie/anybotics_anymal_b/scene.xml"
EVERY_TERM = ["env.legged.stumble_cost_weight=2.0", "env.locomotion.feet_air_time_weight=0.3",
              "env.locomotion.joint_speed_limit=20.0", "env.locomotion.joint_speed_limit_cost_weight=0.05",
              "env.locomotion.torque_limit=30.0"]


def legged_config(xml: str, *overrides, recipe: str = "legged_trot_v2"):
    return compose_config([f"experiment={recipe}", f"env.xml_file={xml}", *overrides])


def lockstep(cfg, steps: int, seed: int = 5, scale: float = 0.3) -> dict:
    """Steps the old env and a one-row batch with the same actions; the largest difference of each figure."""
    old = make_gym_env(cfg.env)
    new = LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=1, threads=1)
    o_obs, _ = old.reset(seed=seed)
    n_obs, _ = new.reset(seed=[seed])
    worst = {"obs": float(np.abs(o_obs - n_obs[0]).max()), "reward": 0.0, "resets": 0}
    rng = np.random.default_rng(seed)
    nu = new.world.model.nu
    for t in range(steps):
        action = (scale * rng.standard_normal(nu)).clip(-1, 1).astype(np.float32)
        o, r, term, trunc, info = old.step(action)
        n, nr, nterm, ntrunc, _ = new.step(action[None])
        od, nd = old.unwrapped.data, new.datas[0]
        assert np.array_equal(od.qpos, nd.qpos) and np.array_equal(od.qvel, nd.qvel), f"physics differ at step {t}"
        assert (term, trunc) == (bool(nterm[0]), bool(ntrunc[0])), f"episode ends differ at step {t}"
        worst["obs"] = max(worst["obs"], float(np.abs(o - n[0]).max()))
        worst["reward"] = max(worst["reward"], abs(r - float(nr[0])))
        for k, name in enumerate(new.task.names):
            key = f"reward_{name}"
            assert key in info, f"{key}: the old env has no such term"
            worst[key] = max(worst.get(key, 0.0), abs(info[key] - new.task.last_terms[0, k]))
        if term or trunc:
            assert info["termination"] == new.task.termination(0)
            worst["resets"] += 1
            o, _ = old.reset()
            n, _ = new.reset(options={"reset_mask": np.array([True])})
            assert np.array_equal(o, n[0]), f"the reset after step {t} differs"
    old.close()
    new.close()
    return worst


def assert_close(worst: dict, terms: set) -> None:
    assert worst["obs"] == 0.0  # the observation is computed from the same floats in the same order
    assert worst["reward"] < 1e-7  # the control cost: float64 here, float32 there (NumPy 2's promotion), ~3e-9
    assert {k[len("reward_"):] for k in worst if k.startswith("reward_")} == terms
    assert all(worst[k] < 1e-7 for k in worst if k.startswith("reward_"))


def test_the_batch_compiles_the_model_the_old_env_steps():
    cfg = legged_config(GO1)
    old, new = make_gym_env(cfg.env).unwrapped.model, LeggedBatchEnv(gym_make_kwargs(cfg.env)).models[0]
    fields = [f for f in dir(old) if not f.startswith("_") and isinstance(getattr(old, f, None), np.ndarray)]
    assert len(fields) > 100
    assert [f for f in fields if not np.array_equal(getattr(old, f), getattr(new, f), equal_nan=True)] == []


V2_TERMS = {"forward", "survive", "ctrl", "contact", "torque", "joint_speed", "action_rate", "base_height",
            "orientation", "foot_slip", "body_contact", "long_swing", "gait_clock"}


@pytest.mark.parametrize("xml", [GO1, ANYMAL], ids=["go1", "anymal_b"])
def test_two_thousand_steps_match_the_old_env_exactly(xml):
    worst = lockstep(legged_config(xml), 2000)
    assert_close(worst, V2_TERMS)
    assert worst["resets"] >= 2  # the episode ends and the resets were compared too


def test_every_reward_term_and_issue_46s_recipe_match():
    worst = lockstep(legged_config(GO1, *EVERY_TERM), 600, seed=3)
    assert_close(worst, V2_TERMS | {"stumble", "air_time", "joint_speed_limit"})
    worst = lockstep(legged_config(ANYMAL, recipe="legged_trot"), 600, seed=4)  # every contact, the model's step
    assert_close(worst, V2_TERMS - {"long_swing"})


def test_the_in_house_quadruped_presets_match_too():
    """env=mjcf's robots (the model as it is, the action its controls): the zoo's climbing quadruped's recipe."""
    worst = lockstep(compose_config(["experiment=quadruped_climb"]), 600, seed=2)
    assert_close(worst, {"forward", "survive", "ctrl", "contact", "torque", "joint_speed", "joint_speed_limit",
                         "action_rate", "base_height", "orientation", "foot_slip", "air_time", "body_contact"})


def test_n_rows_are_n_envs_whatever_the_threads():
    cfg = legged_config(GO1)
    olds = [make_gym_env(cfg.env) for _ in range(3)]
    for i, env in enumerate(olds):
        env.reset(seed=20 + i)
    batches = [LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=3, threads=threads) for threads in (1, 2)]
    for batch in batches:
        batch.reset(seed=20)
    rng = np.random.default_rng(1)
    for t in range(300):
        actions = (0.4 * rng.standard_normal((3, 12))).clip(-1, 1).astype(np.float32)
        results = [env.step(a) for env, a in zip(olds, actions)]
        for batch in batches:
            obs, reward, term, trunc, _ = batch.step(actions)
            for i, (o, r, te, tr, _) in enumerate(results):
                assert np.array_equal(olds[i].unwrapped.data.qpos, batch.datas[i].qpos)
                np.testing.assert_allclose(obs[i], o, rtol=0, atol=1e-12)
                assert abs(reward[i] - r) < 1e-7 and (te, tr) == (term[i], trunc[i])
            done = term | trunc
            if done.any():
                batch.reset(options={"reset_mask": done})
        for i, (_, _, te, tr, _) in enumerate(results):
            if te or tr:
                olds[i].reset()


TINY_LEGGED = ["collector.frames_per_batch=256", "collector.total_frames=1024", "loss.epochs=1",
               "loss.minibatch_size=128", "eval.every_frames=512", "eval.episodes=2", "eval.final_episodes=2",
               "checkpoint.every_frames=0", "logger=csv", "env.max_episode_steps=40"]


@pytest.mark.parametrize("scale", [["collector.num_envs=4"], ["collector.num_envs=4", "collector.backend=torchrl"],
                                   ["collector.num_envs=2", "collector.workers=2"],
                                   ["collector.num_envs=4", "policy.critic_obs=privileged"]],
                         ids=["fast", "torchrl", "workers", "privileged"])
def test_a_resume_collects_the_batch_the_uninterrupted_run_collects(scale):
    """Each row's position, the statistics and the exploration RNG come back from the collector's state: the batch
    after a resume is the uninterrupted run's, on the fast path, TorchRL's Collector and worker processes, and with
    the asymmetric critic's privileged observation (its statistics and the one the critic reads next)."""
    import torch

    from ppo_torchrl.collectors import make_collector
    from ppo_torchrl.envs import env_spec
    from ppo_torchrl.models import make_actor_critic

    cfg = legged_config(GO1, *TINY_LEGGED, "env.max_episode_steps=20", *scale)
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    first = make_collector(cfg, ac, 3, torch.device("cpu"))
    second = None
    try:
        for _ in range(2):
            first.collect()
        state, rng = first.state_dict(), torch.get_rng_state()
        uninterrupted = first.collect()
        second = make_collector(cfg, ac, 77, torch.device("cpu"))
        second.load_state_dict(state)
        torch.set_rng_state(rng)
        resumed = second.collect()
        for key in uninterrupted.keys(True, True):
            assert torch.equal(uninterrupted[key], resumed[key]), key
        assert first.env_metrics() == second.env_metrics()  # the curriculum and the reward terms' sums too
    finally:
        first.close()
        if second is not None:
            second.close()


def test_an_interrupted_legged_run_resumed_logs_what_the_uninterrupted_one_logs(tmp_path):
    import json
    import os
    import signal

    from ppo_torchrl import checkpoint
    from ppo_torchrl.lifecycle import resume_config
    from ppo_torchrl.errors import Interrupted
    from ppo_torchrl.trainer import Trainer

    cfg = legged_config(GO1, *TINY_LEGGED, "collector.num_envs=4")
    Trainer(cfg, tmp_path / "straight").train()
    interrupted = Trainer(legged_config(GO1, *TINY_LEGGED, "collector.num_envs=4"), tmp_path / "cut")
    collect = interrupted.collector.collect

    def collect_then_signal():
        batch = collect()
        if interrupted.iteration == 1:
            os.kill(os.getpid(), signal.SIGINT)
        return batch

    interrupted.collector.collect = collect_then_signal
    with pytest.raises(Interrupted):
        interrupted.train()
    assert json.loads((tmp_path / "cut" / "summary.json").read_text())["status"] == "interrupted"
    state = checkpoint.load(tmp_path / "cut" / "checkpoints" / "last.pt")
    Trainer(resume_config(tmp_path / "cut", [], state), tmp_path / "cut", resume=state).train()

    def rows(run):
        lines = (run / "metrics.csv").read_text().splitlines()
        header = lines[0].split(",")
        skip = {header.index("time_s"), header.index("sps")}
        return [[v for i, v in enumerate(line.split(",")) if i not in skip] for line in lines[1:]]

    straight, resumed = rows(tmp_path / "straight"), rows(tmp_path / "cut")
    assert len(resumed) == 4 and resumed == straight
