"""Issue 74 (items 1-2): env=playground, MuJoCo Playground's tasks as EnvPool ships them, on the app's one pipeline, and
the asymmetric critic (policy.critic_obs=privileged), on real EnvPool envs (Go1JoystickFlatTerrain-v1: a dict
observation, state 48 and privileged_state 123, 12 actions in [-1, 1]; BarkourJoystick-v1: one vector of 465)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

envpool = pytest.importorskip("envpool")

from conftest import TINY, compose_config, run_cli  # noqa: E402
from ppo_torchrl.errors import ConfigError  # noqa: E402
from ppo_torchrl.envs.layout import PRIVILEGED  # noqa: E402

GO1 = "Go1JoystickFlatTerrain-v1"


def go1_cfg(*overrides):
    return compose_config(["env=playground", f"env.id={GO1}", *TINY, *overrides])


def collection_of(cfg, seed=3, ac=None):
    """(actor-critic, Collection) of cfg; `ac`: this one's weights (a resume's networks are the checkpoint's)."""
    from ppo_torchrl.collectors import make_collector
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.rl.models import make_actor_critic

    ac = ac if ac is not None else make_actor_critic(cfg.policy, env_spec(cfg.env))
    return ac, make_collector(cfg, ac, seed, torch.device("cpu"))


def test_a_playground_tasks_dict_observation_is_the_actors_layout_and_the_critics_privileged_one():
    """state is the observation (one running segment of that name, the actor's), privileged_state the privileged
    observation with a layout and statistics of its own; the actions are the task's range, read from EnvPool's spec;
    num_envs envs are views of one pool, env i stepping pool env i; a task of one vector has no privileged one."""
    from ppo_torchrl.envs.state import env_state_of
    from ppo_torchrl.envs.make import env_spec, make_torchrl_env

    cfg = go1_cfg()
    spec = env_spec(cfg.env)
    pool_spec = envpool.make_spec(GO1)
    assert (spec.obs_dim, spec.privileged_dim, spec.action_dim) == (48, 123, 12)
    assert np.array_equal(spec.action_low, pool_spec.gymnasium_action_space.low.astype(np.float32))
    assert np.array_equal(spec.action_high, pool_spec.gymnasium_action_space.high.astype(np.float32))
    env = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99, num_envs=2, seed=5, privileged=True)
    try:
        state = env_state_of(env)
        assert [(s.name, s.size, s.treatment) for s in state.obs_norm.layout.segments] == [("state", 48, "running")]
        assert [(s.name, s.size, s.treatment) for s in state.privileged_norm.layout.segments] == [
            ("privileged_state", 123, "running")]
        views = [e.unwrapped for e in state.gym_envs]
        shared = views[0].shared
        assert views[1].shared is shared and shared.n == 2  # one pool for both
        reference = envpool.make(GO1, env_type="gymnasium", num_envs=2, num_threads=1, seed=5)
        expected, _ = reference.reset()  # env i of a pool seeded 5: what env i's reset(seed=5 + i) gave
        for i in range(2):
            assert np.array_equal(state.gym_envs[i].last_obs, expected["state"][i])
            assert np.array_equal(shared.current["privileged_state"][i], expected["privileged_state"][i])
        action = np.full(12, 0.3, np.float32)
        obs, reward, _, _, info = state.gym_envs[1].step(action)
        ref_obs, ref_reward, _, _, _ = reference.step(np.array([action], np.float64), np.array([1]))
        assert np.array_equal(obs, ref_obs["state"][0]) and reward == pytest.approx(float(ref_reward[0]))
        assert np.array_equal(info["privileged_observation"], ref_obs["privileged_state"][0])
        reference.close()
    finally:
        env.close()
    flat = env_spec(compose_config(["env=playground", "env.id=BarkourJoystick-v1"]).env)
    assert (flat.obs_dim, flat.privileged_dim) == (465, None)


def test_the_auto_reset_step_never_enters_a_batch_and_each_episodes_reward_terms_are_summed(tiny_cfg):
    """Every transition of a batch is a real step (the next observation, privileged one too, is the next step's
    within an episode; the counters restart at 1 after an end); each of EnvPool's auto-reset steps (elapsed_step 0)
    went to the ended envs alone and is in no batch; each batch's reward/<term> metrics are the mean over its ended
    episodes of the sum of EnvPool's info['reward_<term>'] over each episode, recomputed here from the pool's own
    answers."""
    cfg = go1_cfg("collector.num_envs=4", "collector.frames_per_batch=256", "env.max_episode_steps=20",
                  "policy.critic_obs=privileged")
    ac, collection = collection_of(cfg)
    terms = [k[len("info:reward_"):] for k in envpool.make_spec(GO1).state_array_spec if k.startswith("info:reward_")]
    try:
        assert collection.metric_keys() == [f"reward/{t}" for t in terms] + ["command/speed", "command/yaw_rate"]
        collection.collector._current_obs()
        pool = collection.collector.shared.pool
        calls = []
        step = pool.step

        def recorded(action, env_id=None):
            out = step(action, env_id)
            calls.append((np.array(env_id), out[4]["env_id"].copy(), out[4]["elapsed_step"].copy(),
                          out[2] | out[3], {t: out[4][f"reward_{t}"].copy() for t in terms}))
            return out

        pool.step = recorded
        batches, counts, metrics = [], [], []
        for _ in range(3):
            batches.append(collection.collect())
            counts.append(collection.collector._out["next", "step_count"].squeeze(-1).clone())
            metrics.append(dict(collection.env_metrics()))
            calls.append(None)  # a batch's end
        episodes = collection.pop_episodes()
    finally:
        collection.close()
    resets = [len(sent) for sent, _, elapsed, _, _ in filter(None, calls) if (elapsed == 0).all()]
    assert resets and sum(1 for c in calls if c is not None and not (c[2] == 0).all()) == 3 * 64
    ended = 0
    for batch, count in zip(batches, counts):
        done = batch["next", "done"].squeeze(-1)
        for key in ("observation", PRIVILEGED):
            now, nxt = batch[key], batch["next", key]
            for i in range(4):
                for t in range(63):
                    if not done[i, t]:
                        assert torch.equal(nxt[i, t], now[i, t + 1])
                        assert count[i, t + 1] == count[i, t] + 1
                    else:
                        assert count[i, t + 1] == 1
        ended += int(done.sum())
    assert ended == sum(resets) == len(episodes) and all(length <= 20 for _, length in episodes)
    # each batch's metrics from the pool's raw answers: per env, a term's sum over each ended episode
    sums, per_batch = {i: dict.fromkeys(terms, 0.0) for i in range(4)}, [[]]
    for call in calls:
        if call is None:
            per_batch.append([])
            continue
        _, env_ids, elapsed, done, values = call
        if (elapsed == 0).all():
            continue  # the auto-reset step: in no episode
        for j, i in enumerate(env_ids):
            for t in terms:
                sums[i][t] += float(values[t][j])
            if done[j]:
                per_batch[-1].append(sums[i])
                sums[i] = dict.fromkeys(terms, 0.0)
    for logged, rows in zip(metrics, per_batch):
        assert rows
        for t in terms:
            assert logged[f"reward/{t}"] == pytest.approx(np.mean([r[t] for r in rows]), rel=1e-9, abs=1e-12)


def test_a_resume_keeps_both_statistics_and_the_rng_and_starts_new_episodes():
    """The stated limit (RESUME_LIMIT): EnvPool cannot restore a simulator state. A resumed collector has the
    checkpoint's statistics (the critic's privileged ones too) and RNG; each env starts a new episode (its first step
    counts 1) from a pool rebuilt from that RNG; two resumes of one checkpoint collect the same first batch."""
    cfg = go1_cfg("collector.num_envs=2", "policy.critic_obs=privileged")
    ac, first = collection_of(cfg)
    try:
        first.collect()
        first.collect()
        state = first.state_dict()
    finally:
        first.close()
    assert state["privileged"]["count"] == state["obs"]["count"] > 0
    batches = []
    for seed in (77, 78):  # other seeds: everything must come from the state
        _, resumed = collection_of(cfg, seed, ac)
        try:
            resumed.load_state_dict(state)
            assert resumed.obs_stats()["count"] == state["obs"]["count"]
            assert resumed.state.privileged_norm.state_dict()["count"] == state["privileged"]["count"]
            np.testing.assert_array_equal(resumed.state.privileged_norm.stats.mean, state["privileged"]["mean"])
            batches.append(resumed.collect())
            assert (resumed.collector._out["next", "step_count"][:, 0] == 1).all()
        finally:
            resumed.close()
    for key in batches[0].keys(True, True):
        assert torch.equal(batches[0][key], batches[1][key]), key


def test_the_asymmetric_critic_reads_the_privileged_observation_and_the_actor_does_not():
    """policy.critic_obs=privileged: the ValueOperator's in_keys are privileged_observation (123 wide), the actor's
    observation (48); GAE and ClipPPOLoss read the critic's key through them. On a collected batch: changing the
    privileged observation changes the values, the advantages and the critic's loss, not the actor's output;
    changing the observation changes the actor's, not the values. The default critic reads the observation."""
    from ppo_torchrl.rl.advantage import make_advantage
    from ppo_torchrl.rl.losses import make_loss

    cfg = go1_cfg("collector.num_envs=2", "policy.critic_obs=privileged")
    ac, collection = collection_of(cfg)
    try:
        batch = collection.collect()
    finally:
        collection.close()
    assert list(ac.critic.in_keys) == [PRIVILEGED] and list(ac.actor.in_keys) == ["observation"]
    assert ac.critic.module[0][0].in_features == 123 and ac.policy_net[0][0].in_features == 48
    gae, loss = make_advantage(cfg.advantage, ac.critic), make_loss(cfg.loss, ac)
    assert PRIVILEGED in loss.in_keys and ("next", PRIVILEGED) in gae.in_keys
    with torch.no_grad():
        ac.actor(batch)
        gae(batch)
    other = batch.clone()
    other.set(PRIVILEGED, batch[PRIVILEGED] + 1.0)
    other.set(("next", PRIVILEGED), batch["next", PRIVILEGED] + 1.0)
    with torch.no_grad():
        ac.actor(other)
        gae(other)
    assert torch.equal(other["loc"], batch["loc"])
    assert not torch.allclose(other["state_value"], batch["state_value"])
    assert not torch.allclose(other["advantage"], batch["advantage"])
    moved = batch.clone()
    moved.set("observation", batch["observation"] + 1.0)
    with torch.no_grad():
        ac.actor(moved)
        ac.critic(moved)
    assert not torch.allclose(moved["loc"], batch["loc"]) and torch.equal(moved["state_value"], batch["state_value"])
    flat = batch.reshape(-1)
    flat.set("action_log_prob", ac.actor.get_dist(flat).log_prob(flat["action"]).detach())
    critic_loss = loss(flat)["loss_critic"]
    shifted = flat.clone()
    shifted.set(PRIVILEGED, flat[PRIVILEGED] + 1.0)
    assert not torch.allclose(loss(shifted)["loss_critic"], critic_loss)
    from ppo_torchrl.rl.models import make_actor_critic
    from ppo_torchrl.envs.make import env_spec

    default = make_actor_critic(go1_cfg().policy, env_spec(go1_cfg().env))
    assert list(default.critic.in_keys) == ["observation"] and default.critic.module[0][0].in_features == 48


def test_export_carries_the_actor_only(tmp_path):
    """policy.pt of an asymmetric-critic run: `state`-sized input (48) in, the deterministic action out, the actor's
    weights and nothing of the critic's; a privileged-sized input is refused."""
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.export import export_policy
    from ppo_torchrl.rl.models import deterministic_action, make_actor_critic

    cfg = go1_cfg("policy.critic_obs=privileged")
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    stats = {"mean": np.full(48, 0.5), "var": np.full(48, 4.0), "count": 10.0,
             "layout": [dict(name="state", size=48, treatment="running", offset=0.0, scale=1.0, clip=None)]}
    path = export_policy(cfg, ac, stats, tmp_path / "policy.pt")
    policy = torch.jit.load(str(path))
    actor_weights = sum(p.numel() for p in ac.policy_net.parameters())
    critic_weights = sum(p.numel() for p in ac.critic.parameters())
    assert sum(p.numel() for p in policy.parameters()) == actor_weights and critic_weights > 0
    obs = torch.linspace(-3, 3, 48)
    expected = deterministic_action(ac, ac.policy_net(((obs.double() - 0.5) / 2.0).clamp(-10, 10).float())[0])
    assert torch.allclose(policy(obs), expected.detach(), atol=1e-6)
    with pytest.raises(RuntimeError):
        policy(torch.zeros(171))


@pytest.mark.parametrize("task", [GO1, "PandaRobotiqPushCube-v1"])  # the second's model has no camera
def test_a_frame_is_filmed_from_envpools_own_renderer(task):
    from ppo_torchrl.envs.playground import make_playground_env

    env = make_playground_env(compose_config(["env=playground", f"env.id={task}"]).env, "rgb_array", width=64, height=48)
    try:
        env.reset(seed=0)
        frame = env.render()
    finally:
        env.close()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8 and frame.std() > 0


@pytest.mark.parametrize("overrides, says", [
    (["env=playground", "env.id=Go1JoystickFlat-v1"], "is not one of EnvPool's MuJoCo Playground tasks: "),
    (["env=playground", f"env.id={GO1}", "+env.make_kwargs.foo=1"], "env.make_kwargs.foo is not a setting"),
    (["env=playground", f"env.id={GO1}", "env.locomotion.frame_skip=2"], "env.locomotion.frame_skip works on MJCF"),
    (["env=playground", f"env.id={GO1}", "collector.backend=fast"], "env=playground runs on its EnvPool's collector"),
    (["env=playground", "env.id=BarkourJoystick-v1", "policy.critic_obs=privileged"], "has no privileged_state"),
    (["env=playground", f"env.id={GO1}", "policy.critic_obs=privileged", "env.transforms.obs_norm=fixed"],
     "obs_norm=fixed fits the actor's observation only"),
    (["env=Hopper-v4", "policy.critic_obs=privileged"], "needs an env with a privileged observation"),
    (["env=playground", f"env.id={GO1}", "policy.critic_obs=critic"], "policy.critic_obs='critic' is not allowed"),
    (["env=gym", f"env.id={GO1}"], f"is a MuJoCo Playground task: env=playground env.id={GO1}"),
])
def test_bad_input_is_one_line(overrides, says):
    from ppo_torchrl.validation import validate_config

    with pytest.raises(ConfigError, match=None) as caught:
        validate_config(compose_config(overrides))
    assert says in str(caught.value) and "\n" not in str(caught.value)
    if "Go1JoystickFlat-v1" in overrides[1]:
        assert GO1 in str(caught.value) and "SpotFlatTerrainJoystick-v1" in str(caught.value)


def test_envpool_missing_says_how_to_install_it(monkeypatch):
    import sys

    from ppo_torchrl.envs.playground import _envpool

    monkeypatch.setitem(sys.modules, "envpool", None)  # `import envpool` raises ImportError, as without the extra
    with pytest.raises(ConfigError, match=r'env=playground needs EnvPool, which is not installed: pip install -e "\.\[envpool\]"'):
        _envpool()


def test_the_cli_trains_resumes_evaluates_and_exports_a_playground_task(tmp_path):
    """One command line each: a run with the asymmetric critic logs every reward term, resumes (saying its limit),
    evaluates (the terms per episode) and exports the actor (48 in); a bad id changes nothing on disk."""
    from ppo_torchrl.collectors.playground import RESUME_LIMIT

    run = tmp_path / "run"
    common = ["env=playground", f"env.id={GO1}", "policy.critic_obs=privileged", "collector.num_envs=4",
              "env.max_episode_steps=50"]
    result = run_cli(*common, *TINY, f"hydra.run.dir={run}")
    assert result.returncode == 0, result.stderr[-2000:]
    assert "PlaygroundCollector" in result.stderr
    header, *rows = (run / "metrics.csv").read_text().splitlines()
    assert "reward/tracking_lin_vel" in header.split(",") and "command/speed" in header.split(",")
    column = header.split(",").index("reward/pose")
    assert all(row.split(",")[column] for row in rows)  # every batch had ended episodes (50 steps at most)
    more = run_cli(f"resume={run}", "collector.total_frames=768")
    assert more.returncode == 0, more.stderr[-2000:]
    assert RESUME_LIMIT in more.stderr and json.loads((run / "summary.json").read_text())["frames"] == 768
    from ppo_torchrl import evaluate, export

    result = evaluate.main([f"run={run}", "checkpoint=last", "episodes=2"])  # the commands' mains, in this process
    assert result["length_mean"] <= 50 and "reward/tracking_lin_vel" in result["episode_metrics"]
    assert json.loads((run / "eval" / "eval.json").read_text())["episode_metrics"] == result["episode_metrics"]
    for args, says in ((["tracking=true"], "give env.max_episode_steps=417 or more"),  # 50-step episodes
                       (["tracking=true", "extremes=true"], "extremes=true fixes the corners")):
        with pytest.raises(ConfigError, match=says):
            evaluate.main([f"run={run}", "checkpoint=last", *args])
    assert not (run / "eval" / "tracking.json").exists()
    tracked = evaluate.main([f"run={run}", "checkpoint=last", "tracking=true", "episodes=1",
                             "env.max_episode_steps=1000"])["tracking"]["nominal"]
    record = json.loads((run / "eval" / "tracking.json").read_text())["worlds"]["nominal"]
    assert record["overall"] == tracked and record["leg_length"] == pytest.approx(0.426)  # read from the task's MJCF
    rows = {r["command"]: r for r in record["commands"]}
    assert len(rows) == 13 and (run / "eval" / "tracking.png").is_file()
    # a policy of 512 frames barely moves: the error of each command is about its size, in the robot's units
    assert rows["stand"]["v_xy_error"] < 0.05 and abs(rows["forward fast"]["v_xy_error"] - 0.5) < 0.1
    assert abs(rows["turn left"]["yaw_rate_error"] - 0.25) < 0.1
    export.main([f"run={run}", "checkpoint=last"])
    assert torch.jit.load(str(run / "policy.pt"))(torch.zeros(3, 48)).shape == (3, 12)
    bad = run_cli("env=playground", "env.id=Go1Joystick-v1", *TINY, f"hydra.run.dir={tmp_path / 'bad'}")
    assert bad.returncode == 2 and not (tmp_path / "bad").exists()
    assert bad.stderr.strip().splitlines()[-1].startswith("error: env.id=Go1Joystick-v1 is not one of"), bad.stderr


@pytest.mark.parametrize("task", ["Go1JoystickFlatTerrain-v1", "Go1JoystickRoughTerrain-v1"])
def test_tracking_finds_the_command_and_the_trunks_motion_where_its_layout_says(task):
    """playground_tracking.LAYOUTS, checked on the task's own observations (noise off): the command segment of the
    actor's observation is info["command"]; the privileged velocimeter and joint angles are the noise-free ones of
    the actor's observation (Playground's Go1 state: velocity 0-3, gyro 3-6, gravity 6-9, joint angles 9-21); the
    gyro is the rate the gravity vector turns at in the trunk frame (dg/dt = -w x g)."""
    from ppo_torchrl.tasks.playground_tracking import LAYOUTS

    layout = LAYOUTS[task]
    env = envpool.make(task, env_type="gymnasium", num_envs=1, num_threads=1, seed=5, noise_level=0.0)
    env.reset()
    rng = np.random.default_rng(1)
    states, privileged = [], []
    for _ in range(120):
        obs, _, terminated, truncated, info = env.step(rng.uniform(-0.5, 0.5, (1, 12)))
        if terminated[0] or truncated[0]:
            break
        s, p = obs["state"][0], obs["privileged_state"][0]
        assert np.allclose(s[layout.command:layout.command + 3], info["command"][0])
        assert np.allclose(p[layout.linvel:layout.linvel + 3], s[0:3])
        assert np.allclose(p[layout.joints:layout.joints + 12], s[9:21])
        states.append(s), privileged.append(p)
    env.close()
    assert len(states) > 50
    g, w = np.array(states)[:, 6:9], np.array(privileged)[:, layout.gyro:layout.gyro + 3]
    turned = -np.cross(0.5 * (w[1:] + w[:-1]), 0.5 * (g[1:] + g[:-1]))
    assert np.corrcoef(turned.ravel(), (np.diff(g, axis=0) / 0.02).ravel())[0, 1] > 0.95


@pytest.mark.parametrize("task", ["Go1JoystickFlatTerrain-v1", "Go1JoystickRoughTerrain-v1",
                                  "SpotFlatTerrainJoystick-v1"])
def test_the_layouts_velocities_are_the_ones_the_tasks_own_tracking_rewards_read(task):
    """Each LAYOUTS entry against the task itself: with its command segment, its privileged local velocity and its
    gyro's yaw rate, the task's own tracking terms come back (info: scale * exp(-error^2 / sigma), the task's config);
    and its joint angles are the noise-free ones of the actor's state (Go1's at 9-21, Spot's at 6-18)."""
    from ppo_torchrl.tasks.playground_tracking import LAYOUTS

    layout, joints = LAYOUTS[task], 9 if task.startswith("Go1") else 6
    config = envpool.make_spec(task).config
    env = envpool.make(task, env_type="gymnasium", num_envs=1, num_threads=1, seed=5, noise_level=0.0)
    env.reset()
    rng = np.random.default_rng(1)
    steps = 0
    for _ in range(100):
        obs, _, terminated, truncated, info = env.step(rng.uniform(-0.5, 0.5, (1, 12)))
        if terminated[0] or truncated[0]:
            break
        s, p = obs["state"][0], obs["privileged_state"][0]
        command = s[layout.command:layout.command + 3]
        assert np.allclose(command, info["command"][0])
        lin = np.square(command[:2] - p[layout.linvel:layout.linvel + 2]).sum()
        yaw = np.square(command[2] - p[layout.gyro + 2])
        assert info["reward_tracking_lin_vel"][0] == pytest.approx(
            config.tracking_lin_vel_scale * np.exp(-lin / config.tracking_sigma), rel=1e-4, abs=1e-7)
        assert info["reward_tracking_ang_vel"][0] == pytest.approx(
            config.tracking_ang_vel_scale * np.exp(-yaw / config.tracking_sigma), rel=1e-4, abs=1e-7)
        assert np.allclose(p[layout.joints:layout.joints + 12], s[joints:joints + 12])
        steps += 1
    env.close()
    assert steps > 50


def test_tracking_refuses_a_task_it_has_no_layout_for():
    from ppo_torchrl.tasks.playground_tracking import layout_of

    with pytest.raises(ConfigError, match="tracking=true on env=playground knows where .* not in BarkourJoystick-v1"):
        layout_of(compose_config(["env=playground", "env.id=BarkourJoystick-v1"]).env)


def test_torchrls_multisync_collector_runs_it_in_workers():
    """collector.workers=2: TorchRL's MultiSyncCollector builds PlaygroundCollector in each worker, each stepping a
    pool of its own; both statistics (the critic's too) are pooled over the workers."""
    cfg = go1_cfg("collector.workers=2", "collector.num_envs=2", "policy.critic_obs=privileged")
    ac, collection = collection_of(cfg)
    try:
        batches = [collection.collect() for _ in range(2)]
        state = collection.state_dict()
    finally:
        collection.close()
    assert tuple(batches[0].shape) == (4, 64) and tuple(batches[0][PRIVILEGED].shape) == (4, 64, 123)
    assert state["privileged"]["count"] == state["obs"]["count"] >= 2 * 256
    assert not torch.equal(batches[1]["observation"][0], batches[1]["observation"][2])  # the workers differ
