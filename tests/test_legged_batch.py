"""The batched legged env (issue 72) against the locomotion env it replaced (robots/env.py, Ant-v5's class with its
mixins), through that env's recorded trajectories (tests/legged_reference.py; tests/data/): the same model, and from
the same state under the same actions the same physics states bit for bit, the rewards, every reward term's sum and
the observations to float tolerance, the same episode ends and why, over 2,000 control steps on two robots and 600 on
three more recipes; N rows are N one-row batches, whatever the number of physics threads; a resumed run logs what
the uninterrupted one would.
"""

import json

import numpy as np
import pytest

from ppo_torchrl.envs.make import gym_make_kwargs
from ppo_torchrl.tasks.locomotion.batch import LeggedBatchEnv

from conftest import compose_config
from legged_reference import CASES, DATA, EVERY, MODELS, actions, model_digests, physics_digest

GO1, ANYMAL = "menagerie/unitree_go1/scene.xml", "menagerie/anybotics_anymal_b/scene.xml"
REFERENCE = np.load(DATA)


def legged_config(xml: str, *overrides, recipe: str = "legged_trot_v2"):
    return compose_config([f"experiment={recipe}", f"env.xml_file={xml}", *overrides])


def replay(case: str) -> set:
    """Steps a one-row batch as the old env was stepped in `case` and compares every step with its record; the
    names of the batch's reward terms."""
    overrides, steps, seed = CASES[case]
    ref = {key.split("/", 1)[1]: REFERENCE[key] for key in REFERENCE.files if key.startswith(case + "/")}
    batch = LeggedBatchEnv(gym_make_kwargs(compose_config(overrides).env), num_envs=1, threads=1)
    obs, _ = batch.reset(seed=[seed])
    np.testing.assert_allclose(obs[0], ref["obs"][0], rtol=0, atol=1e-12)
    sums = np.zeros(len(batch.task.names))
    ended, why, resets, kept = [], [], 0, 1
    for t, action in enumerate(actions(seed, steps, batch.world.model.nu)):
        obs, reward, term, trunc, _ = batch.step(action[None])
        assert physics_digest(batch.datas[0]) == ref["digest"][t], f"{case}: the physics differ at step {t}"
        assert abs(float(reward[0]) - ref["reward"][t]) < 1e-7, f"{case}: the reward differs at step {t}"
        assert abs(obs[0].sum() - ref["obs_sum"][t]) < 1e-9 * max(1.0, abs(ref["obs_sum"][t]))
        sums += batch.task.last_terms[0]
        if (t + 1) % EVERY == 0:
            np.testing.assert_allclose(obs[0], ref["obs"][kept], rtol=0, atol=1e-12)
            kept += 1
        if term[0] or trunc[0]:
            ended.append([t, int(term[0]), int(trunc[0])])
            why.append(str(batch.task.termination(0)))
            obs, _ = batch.reset(options={"reset_mask": np.array([True])})
            assert physics_digest(batch.datas[0]) == ref["reset_digest"][resets], f"{case}: the reset after {t} differs"
            assert abs(obs[0].sum() - ref["reset_obs_sum"][resets]) < 1e-9 * max(1.0, abs(ref["reset_obs_sum"][resets]))
            resets += 1
    batch.close()
    assert ended == ref["ended"].tolist() and why == ref["why"].tolist()
    assert sorted(batch.task.names) == ref["terms"].tolist()
    recorded = dict(zip(ref["terms"].tolist(), ref["term_sums"]))
    for name, total in zip(batch.task.names, sums):
        assert abs(total - recorded[name]) < 1e-6 * max(1.0, abs(recorded[name])), name
    return set(batch.task.names), resets


def test_the_batch_compiles_the_model_the_old_env_stepped():
    recorded = json.loads(MODELS.read_text())["go1"]
    new = model_digests(LeggedBatchEnv(gym_make_kwargs(legged_config(GO1).env)).models[0])
    assert len(recorded) > 100 and set(new) == set(recorded)
    assert [f for f in recorded if new[f] != recorded[f]] == []


V2_TERMS = {"forward", "survive", "ctrl", "contact", "torque", "joint_speed", "action_rate", "base_height",
            "orientation", "foot_slip", "body_contact", "long_swing", "gait_clock"}


@pytest.mark.parametrize("case", ["go1", "anymal_b"])
def test_two_thousand_steps_match_the_old_env_exactly(case):
    terms, resets = replay(case)
    assert terms == V2_TERMS
    assert resets >= 2  # the episode ends and the resets were compared too


def test_every_reward_term_and_issue_46s_recipe_match():
    assert replay("go1_every_term")[0] == V2_TERMS | {"stumble", "air_time", "joint_speed_limit"}
    assert replay("anymal_b_issue46")[0] == V2_TERMS - {"long_swing"}  # every contact, the model's step


def test_the_in_house_quadruped_presets_match_too():
    """env=mjcf's robots (the model as it is, the action its controls): the zoo's climbing quadruped's recipe."""
    assert replay("quadruped_climb")[0] == {"forward", "survive", "ctrl", "contact", "torque", "joint_speed",
                                            "joint_speed_limit", "action_rate", "base_height", "orientation",
                                            "foot_slip", "air_time", "body_contact"}


def test_n_rows_are_n_envs_whatever_the_threads():
    cfg = legged_config(GO1)
    singles = [LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=1, threads=1) for _ in range(3)]
    for i, env in enumerate(singles):
        env.reset(seed=[20 + i])
    batches = [LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=3, threads=threads) for threads in (1, 2)]
    for batch in batches:
        batch.reset(seed=20)
    rng = np.random.default_rng(1)
    ends = 0
    for t in range(300):
        actions_now = (0.4 * rng.standard_normal((3, 12))).clip(-1, 1).astype(np.float32)
        results = [env.step(a[None]) for env, a in zip(singles, actions_now)]
        for batch in batches:
            obs, reward, term, trunc, _ = batch.step(actions_now)
            for i, (o, r, te, tr, _) in enumerate(results):
                assert np.array_equal(singles[i].datas[0].qpos, batch.datas[i].qpos)
                np.testing.assert_allclose(obs[i], o[0], rtol=0, atol=1e-12)
                assert abs(reward[i] - r[0]) < 1e-7 and (te[0], tr[0]) == (term[i], trunc[i])
            done = term | trunc
            if done.any():
                batch.reset(options={"reset_mask": done})
        ends += sum(bool(te[0] or tr[0]) for _, _, te, tr, _ in results)
        for i, (_, _, te, tr, _) in enumerate(results):
            if te[0] or tr[0]:
                singles[i].reset(options={"reset_mask": np.array([True])})
    assert ends >= 1  # a row's own reset, in the middle of the others' episodes, was compared too


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
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.rl.models import make_actor_critic

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

    from ppo_torchrl.run import checkpoint
    from ppo_torchrl.run.lifecycle import resume_config
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


def test_fixed_observation_statistics_are_fitted_on_a_one_row_batch_of_the_task():
    """env.transforms.obs_norm=fixed on env=legged: the statistics are the moments of random-action rollouts of a
    batch of one row of the task (envs.make_batch), reset where an episode ends, then frozen (a robot of a model file
    has no single Gymnasium env to fit them on)."""
    from ppo_torchrl.envs.make import make_batch, make_torchrl_env

    cfg = legged_config(GO1, "env.transforms.obs_norm=fixed", "env.transforms.obs_norm_init_frames=300")
    env = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99, seed=3)
    norm = env.transform[0].obs_norm
    batch = make_batch(cfg.env)
    obs = [batch.reset(seed=3)[0][0]]
    batch.action_space.seed(3)
    for _ in range(299):
        o, _, term, trunc, _ = batch.step(batch.action_space.sample())
        obs.append(batch.reset()[0][0] if term[0] or trunc[0] else o[0])
    assert norm.frozen
    np.testing.assert_allclose(norm.stats.mean, np.mean(obs, axis=0), rtol=1e-9, atol=1e-12)
    env.close()


def test_metrics_csv_columns_of_a_task_are_the_tasks_own_not_the_loggers():
    """The logger's columns name no task (issue 72: the trainer logs what a task returns without naming it); a legged
    task declares its eval figures, its curriculum's level and success and each reward term's sum."""
    from ppo_torchrl.envs.rows import BatchRows
    from ppo_torchrl.run.loggers import COLUMNS

    assert not [c for c in COLUMNS if c.startswith(("env/", "reward/")) or c in ("eval/forward_velocity",
                                                                                 "eval/success_rate")]
    keys = BatchRows(LeggedBatchEnv(gym_make_kwargs(legged_config(GO1).env))).metric_keys()
    assert keys[:4] == ["eval/forward_velocity", "eval/success_rate", "env/terrain_level", "env/terrain_success"]
    assert len(keys) > 4 and all(k.startswith("reward/") for k in keys[4:])
    flat = BatchRows(LeggedBatchEnv(gym_make_kwargs(legged_config(GO1, "env.terrain.curriculum=false").env)))
    assert "env/terrain_level" not in flat.metric_keys()
