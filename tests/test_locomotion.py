"""Issue 18: the locomotion env (on the batched legged env, tasks/locomotion/, one row): actuation limits, reward terms, terrain and its
curriculum, observation extras, heading, tracking camera, and evaluation across step heights."""

import copy
import csv
import json
from pathlib import Path

import gymnasium
import mujoco
import numpy as np
import pytest
from omegaconf import OmegaConf

from ppo_torchrl import evaluate
from ppo_torchrl.tasks.locomotion import figures
from ppo_torchrl.envs.make import gym_make_kwargs, make_batch
from ppo_torchrl.trainer import Trainer

from conftest import TINY, compose_config
from test_bad_input import refused

GYM_ANT_XML = Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets" / "ant.xml"
WEIGHTS = ["torque_cost_weight", "joint_speed_cost_weight", "joint_speed_limit_cost_weight", "action_rate_cost_weight",
           "foot_slip_cost_weight", "base_height_cost_weight", "orientation_cost_weight", "body_contact_cost_weight",
           "feet_air_time_weight"]
# A base built facing -x (rotated half a turn about z), one leg with a motor.
FACING_MINUS_X = """<mujoco><worldbody><geom name="floor" type="plane" size="20 20 0.1"/>
<body name="base" pos="0 0 0.3" quat="0 0 0 1"><freejoint/><geom type="box" size="0.2 0.1 0.05"/>
<body name="leg"><joint name="hip" type="hinge" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0 0 -0.2" size="0.02"/>
</body></body></worldbody><actuator><motor joint="hip" ctrlrange="-1 1"/></actuator></mujoco>"""


def batch_of(*overrides, n: int = 1, evaluation: bool = False, **render):
    """A batch of n rows of the config (one row: the env a test used to build before the rebuild)."""
    return make_batch(compose_config(list(overrides)).env, n, evaluation, threads=1, **render)


def step(batch, action) -> tuple:
    """Row 0's step: (observation, reward, terminated, truncated, its reward terms as reward_<name>)."""
    obs, reward, term, trunc, _ = batch.step(np.asarray(action, np.float32)[None])
    terms = {f"reward_{name}": float(v) for name, v in zip(batch.task.names, batch.task.last_terms[0])}
    return obs[0], float(reward[0]), bool(term[0]), bool(trunc[0]), terms


def reset(batch, seed=None) -> np.ndarray:
    """Row 0's next episode (the one before it judged for the curriculum, as at any reset)."""
    return batch.reset_row(0, seed).copy()


def settle(batch) -> None:
    """Row 0's state set by hand: its kinematics and what the task reads of it, as after a step."""
    mujoco.mj_forward(batch.models[0], batch.datas[0])
    batch._gather(0)


def healthy(batch) -> bool:
    return bool(batch.task._unhealthy(batch.reading)[0] == 0)


def cross(batch) -> None:
    """Row 0's trunk put 1 m past its step's edge (a success when the episode is judged)."""
    terrain, d = batch.task.terrain, batch.datas[0]
    along = terrain.edge[0] + 1.0
    d.qpos[:2] = along * terrain.heading + (d.qpos[:2] - terrain.along(d.qpos[:2]) * terrain.heading)
    mujoco.mj_kinematics(batch.models[0], d)


def rollout(batch, steps, seed=0):
    reset(batch, seed)
    rng = np.random.default_rng(seed)
    infos = []
    for _ in range(steps):
        _, reward, terminated, _, terms = step(batch, rng.uniform(-1, 1, batch.world.model.nu))
        infos.append((reward, terms))
        if terminated:
            break
    return infos


def test_without_the_new_keys_an_mjcf_robot_steps_exactly_as_ant_v5():
    cfg = compose_config(["env=mjcf", f"env.xml_file={GYM_ANT_XML}"])
    kwargs = {k: v for k, v in gym_make_kwargs(cfg.env).items() if k not in ("legged", "terrain", "evaluation")}
    ant = gymnasium.make("Ant-v5", disable_env_checker=True, **kwargs)
    ours = batch_of("env=mjcf", f"env.xml_file={GYM_ANT_XML}")
    assert np.array_equal(reset(ours, 3), ant.reset(seed=3)[0])
    for action in np.random.default_rng(0).uniform(-1, 1, (60, 8)).astype(np.float32):
        a, b = step(ours, action), ant.step(action)
        assert np.array_equal(ours.datas[0].qpos, ant.unwrapped.data.qpos)
        # the control cost: float64 here, float32 there (NumPy 2's promotion of Ant-v5's float32 action), ~1e-7
        assert np.array_equal(a[0], b[0]) and a[1] == pytest.approx(b[1], abs=1e-6) and a[2] == b[2]


def test_reward_terms_follow_their_weights():
    base = ["env=quadruped", "env.locomotion.only_positive_rewards=false", "env.locomotion.target_speed=null"]
    off = rollout(batch_of(*base, *(f"env.locomotion.{w}=0" for w in WEIGHTS)), 40)
    one = rollout(batch_of(*base, *(f"env.locomotion.{w}=1" for w in WEIGHTS)), 40)
    two = rollout(batch_of(*base, *(f"env.locomotion.{w}=2" for w in WEIGHTS)), 40)
    seen = set()
    for (r0, i0), (r1, i1), (r2, i2) in zip(off, one, two):
        terms = {k: v for k, v in i1.items() if k not in i0}
        seen |= {k for k, v in terms.items() if v != 0}
        assert r1 == pytest.approx(r0 + sum(terms.values()))  # each weighted term is in the reward
        for key, value in terms.items():
            assert i2[key] == pytest.approx(2 * value)  # and scales with its weight
    assert {"reward_torque", "reward_joint_speed", "reward_action_rate", "reward_base_height", "reward_orientation",
            "reward_foot_slip", "reward_air_time"} <= seen


def test_target_speed_caps_the_forward_reward_and_only_positive_rewards_floors_it():
    batch = batch_of("env=quadruped", "env.locomotion.target_speed=0.01")
    for reward, terms in rollout(batch, 30):
        assert reward >= 0.0  # only_positive_rewards (on in env=quadruped)
        assert terms["reward_forward"] <= 2.0 * 0.01 + 1e-12


def test_joint_speed_and_torque_limits_hold_in_a_random_rollout():
    from ppo_torchrl.tasks.locomotion.evaluation import GaitBatch

    def peak(*overrides):
        batch = batch_of("env=quadruped", *overrides)
        batch.gait = GaitBatch(1, batch.world, None)  # sampled at every physics step
        top = 0.0
        for seed in (0, 1):
            batch.gait.reset(0)
            for _ in rollout(batch, 100, seed):
                assert np.abs(batch.datas[0].actuator_force).max() <= 40.0 + 1e-9
            top = max(top, batch.gait.meters[0].summary()["peak_joint_speed"])
        return top

    # env=quadruped: 40 N m, 8 rad/s. The drive's torque-speed line bounds what the motor can drive;
    # falls and impacts under random actions may push a joint a little past it (8.36 rad/s measured).
    assert peak() <= 8.0 * 1.1
    assert peak("env.locomotion.joint_speed_limit=null") > 8.0 * 2  # the same rollouts without the limit (39)


def test_the_joint_speed_limit_term_pays_for_the_fastest_physics_step_past_the_limit():
    def spun(weight):  # a joint spun to 20 rad/s, then one control step of 4 physics steps with no action
        batch = batch_of("env=quadruped", f"env.locomotion.joint_speed_limit_cost_weight={weight}")
        w, d = batch.world, batch.datas[0]
        reset(batch, 0)
        step(batch, np.zeros(12))
        quiet = step(batch, np.zeros(12))[4]["reward_joint_speed_limit"]
        d.qvel[w.act_dofs[2]] = 20.0
        mujoco.mj_forward(batch.models[0], d)
        speeds = []  # the same control step, stepped by hand from the same state
        data = copy.copy(d)
        data.ctrl[:] = w.ctrl_of(np.zeros((1, 12)))[0]
        for _ in range(w.frame_skip):
            mujoco.mj_step(batch.models[0], data)
            speeds.append(np.abs(data.qvel[w.act_dofs]))
        term = step(batch, np.zeros(12))[4]["reward_joint_speed_limit"]
        return quiet, term, np.max(speeds, axis=0)

    quiet, term, peak = spun(1.0)
    assert quiet == 0.0  # standing still: no joint near 8 rad/s
    assert peak.max() < 20.0 and peak[2] > 8.0  # the damping slows it within the step, not under the limit
    assert term == pytest.approx(-np.maximum(peak - 8.0, 0.0).sum())
    assert spun(2.0)[1] == pytest.approx(2 * term)


def test_step_height_is_drawn_in_range_and_the_curriculum_widens_on_success():
    batch = batch_of("env=quadruped_step", "env.terrain.step_height_range=[0.0,0.2]", "env.terrain.curriculum_window=2",
                     "env.terrain.curriculum_threshold=0.5", "env.terrain.curriculum_step=0.05")
    terrain, start = batch.task.terrain, None
    reset(batch, 0)
    start = terrain._start_along
    assert terrain.level[0] == 0.0 and terrain.height[0] == 0.0 and 1.5 <= terrain.edge[0] - start <= 2.5
    for episode in range(4):  # four successes in windows of two: the level rises twice
        step(batch, np.zeros(12))
        cross(batch)
        reset(batch)
        assert 0.0 <= terrain.height[0] <= terrain.level[0] and 1.5 <= terrain.edge[0] - start <= 2.5
    assert terrain.level[0] == pytest.approx(0.1)
    model, data = batch.models[0], batch.datas[0]
    geom = model.geom("step").id
    mujoco.mj_kinematics(model, data)
    assert data.geom_xpos[geom][2] + model.geom_size[geom][2] == pytest.approx(terrain.height[0])  # where it says
    step(batch, np.zeros(12))
    reset(batch)  # a failure (the trunk is back at the start) does not widen it
    assert terrain.level[0] == pytest.approx(0.1)
    # logged each iteration: the level, and the success share of the last window (2) of episodes
    assert terrain.metrics() == [{"env/terrain_level": pytest.approx(0.1), "env/terrain_success": 0.5}]

    heights = set()
    plain = batch_of("env=quadruped_step", "env.terrain.curriculum=false", n=20)
    plain.reset(seed=0)  # no curriculum: the whole range, each row its own draw
    for h in plain.task.terrain.height:
        heights.add(round(float(h), 3))
        assert 0.0 <= h <= 0.2
    assert max(heights) > 0.1


def test_the_curriculum_steps_down_when_success_falls_to_the_down_threshold():
    batch = batch_of("env=quadruped_step", "env.terrain.curriculum_window=2", "env.terrain.curriculum_threshold=1",
                     "env.terrain.curriculum_down_threshold=0", "env.terrain.curriculum_step=0.05")
    terrain = batch.task.terrain
    reset(batch, 0)

    def episode(crossed: bool):
        step(batch, np.zeros(12))
        if crossed:
            cross(batch)
        reset(batch)

    for outcome, level in [(True, 0.0), (True, 0.05), (True, 0.05), (True, 0.1), (False, 0.1), (True, 0.1),
                           (False, 0.1), (False, 0.05), (False, 0.05), (False, 0.0), (False, 0.0), (False, 0.0)]:
        episode(outcome)
        assert terrain.level[0] == pytest.approx(level)  # a full window of 2: both crossed -> up, none -> down
    assert terrain.level[0] >= 0.0 and 0.0 <= terrain.height[0] <= terrain.level[0] + 1e-12


def test_a_curriculum_band_draws_heights_just_under_the_level():
    batch = batch_of("env=quadruped_step", "env.terrain.curriculum_band=0.03")
    terrain = batch.task.terrain
    terrain.level[0] = 0.1
    heights = []
    for seed in range(30):
        reset(batch, seed)
        heights.append(float(terrain.height[0]))
    assert min(heights) >= 0.07 - 1e-12 and max(heights) <= 0.1 + 1e-12 and max(heights) - min(heights) > 0.01
    terrain.level[0] = 0.02  # the band stops at the range's min (0)
    reset(batch, 0)
    assert 0.0 <= terrain.height[0] <= 0.02
    mixed = batch_of("env=quadruped_step", "env.terrain.curriculum_band=0.03", "env.terrain.curriculum_band_share=0.5")
    mixed.task.terrain.level[0] = 0.1
    heights = []
    for seed in range(60):
        reset(mixed, seed)
        heights.append(float(mixed.task.terrain.height[0]))
    below = np.mean(np.array(heights) < 0.07)  # from [0, 0.1] outside the band: 0.5 * 0.7 of them, ~0.35
    assert 0.15 < below < 0.6 and max(heights) <= 0.1 + 1e-12


def test_flat_share_puts_episodes_on_flat_ground_that_the_curriculum_does_not_count():
    def episodes(*overrides, n=40):
        batch = batch_of("env=quadruped_step", "env.terrain.curriculum_band=0.03", *overrides)
        terrain = batch.task.terrain
        terrain.level[0] = 0.1
        heights = []
        for seed in range(n):
            reset(batch, seed)  # judges the episode before it (standing still: a failure) for the curriculum
            heights.append(float(terrain.height[0]))
            step(batch, np.zeros(12))
        reset(batch, n)
        return np.array(heights), len(terrain.recent[0])

    plain, judged = episodes(n=15)
    assert (plain >= 0.07 - 1e-12).all() and judged == 15
    flat, judged = episodes("env.terrain.flat_share=0.5", n=15)
    on_flat = flat == 0.0
    assert 0 < on_flat.sum() < 15 and (flat[~on_flat] >= 0.07 - 1e-12).all()
    assert judged == 15 - on_flat.sum()  # flat episodes say nothing of the level: the window skips them
    many, _ = episodes("env.terrain.flat_share=0.5", n=60)
    assert 0.3 < np.mean(many == 0.0) < 0.7


def test_the_step_lies_along_the_heading_of_a_robot_built_facing_minus_x():
    batch = batch_of("env=quadruped_a1like_step", "env.terrain.step_height=0.15", "env.terrain.step_distance=[2.0,2.0]",
                     "env.terrain.height_samples=30")
    terrain, model, data = batch.task.terrain, batch.models[0], batch.datas[0]
    obs = reset(batch, 0)
    mujoco.mj_forward(model, data)
    box = batch.world.step_geom
    near_x = data.geom_xpos[box][0] + model.geom_size[box][0]  # the box's face towards +x
    assert list(batch.world.heading) == pytest.approx([-1.0, 0.0])
    assert terrain.edge[0] - terrain._start_along == pytest.approx(2.0)
    assert near_x == pytest.approx(-2.0)  # 2 m ahead of the trunk's start (x = 0), along -x
    assert data.geom_xpos[box][2] + model.geom_size[box][2] == pytest.approx(0.15)
    heights = obs[-30:]  # 10 cm apart from under the trunk: 0 up to 2 m, then 15 cm
    assert (heights[:20] == 0).all() and heights[20:] == pytest.approx(0.15)
    trunk = lambda: data.xpos[batch.world.trunk, :2]  # noqa: E731
    assert not terrain.crossed(0, trunk())
    data.qpos[0] -= 2.6  # 60 cm past the edge, nose first
    mujoco.mj_kinematics(model, data)
    assert terrain.crossed(0, trunk())


def test_the_contacts_read_once_per_control_step_match_a_fresh_reading():
    # contact flags and height samples observed, trunk contact ends; a fall line at 42 cm ends episodes often
    batch = batch_of("experiment=quadruped_climb", "env.locomotion.healthy_z_range=[0.42,1.0]")
    fresh = type(batch.task.contacts)(1, batch.world)
    reset(batch, 3)
    rng = np.random.default_rng(3)
    ended = 0
    for _ in range(300):
        obs, _, terminated, _, _ = step(batch, rng.uniform(-1, 1, 12))
        fresh.read(0, batch.datas[0])  # outside the step: read afresh from the simulator
        assert (obs[-24:-20] == fresh.feet[0]).all()
        assert terminated == ((not healthy(batch)) or fresh.ending[0] >= 0)
        if terminated:
            ended += 1
            reset(batch, ended)
    assert 5 < ended < 300  # the end test was exercised both ways


def test_terminate_on_contact_ends_the_episode_when_the_trunk_touches_down():
    def trunk_on_the_ground(*overrides):
        batch = batch_of("env=quadruped", "env.locomotion.healthy_z_range=[0.0,2.0]", *overrides)
        reset(batch, 0)
        batch.datas[0].qpos[2:7] = [0.07, 0.0, 1.0, 0.0, 0.0]  # on its back, legs up: the trunk's box on the floor
        mujoco.mj_forward(batch.models[0], batch.datas[0])
        terminated = step(batch, np.zeros(12))[2]
        why = batch.task.termination(0)
        assert terminated == (why is not None)
        return why

    assert trunk_on_the_ground("env.locomotion.terminate_on_contact=[trunk]") == "contact: trunk"
    assert trunk_on_the_ground() is None  # off by default: only healthy_z_range ends an episode
    # the trunk on the floor is also under a 20 cm fall line: the contact is named first
    assert trunk_on_the_ground("env.locomotion.terminate_on_contact=[trunk]",
                               "env.locomotion.healthy_z_range=[0.2,2.0]") == "contact: trunk"
    assert trunk_on_the_ground("env.locomotion.healthy_z_range=[0.2,2.0]") == "fall"
    batch = batch_of("env=quadruped", "env.locomotion.terminate_on_contact=[trunk]")
    reset(batch, 0)
    assert not any(step(batch, np.zeros(12))[2] for _ in range(5))  # standing: the feet touch, not the trunk


def test_the_env_says_why_an_episode_ends():
    def first_step(*overrides):
        batch = batch_of("env=quadruped", *overrides)
        reset(batch, 0)
        terminated = step(batch, np.zeros(12))[2]
        return terminated, batch.task.termination(0)

    assert first_step() == (False, None)  # standing in its healthy range
    assert first_step("env.locomotion.healthy_z_range=[0.6,1.0]") == (True, "fall")  # the trunk stands at ~0.45 m
    assert first_step("env.locomotion.healthy_z_range=[0.0,0.3]") == (True, "too high")
    assert first_step("env.locomotion.healthy_z_range=[0.6,1.0]", "env.locomotion.terminate_when_unhealthy=false") == (
        False, None)


def test_healthy_z_above_terrain_reads_the_fall_line_from_the_step_top():
    def is_healthy(z_above_terrain, beyond_edge, height_above_ground):
        batch = batch_of("env=quadruped_step", "env.terrain.step_height=0.15",
                         "env.locomotion.healthy_z_range=[0.2,1.0]",
                         f"env.locomotion.healthy_z_above_terrain={z_above_terrain}")
        reset(batch, 0)
        terrain = batch.task.terrain
        along = terrain.edge[0] + (0.5 if beyond_edge else -0.5)
        ground = 0.15 if beyond_edge else 0.0
        batch.datas[0].qpos[:3] = [along * terrain.heading[0], along * terrain.heading[1], ground + height_above_ground]
        settle(batch)
        return healthy(batch)

    # 12 cm above the step's top is 27 cm above the floor: over the 20 cm line in world z, under it above the terrain
    assert is_healthy(False, True, 0.12) and not is_healthy(True, True, 0.12)
    assert is_healthy(True, True, 0.3)
    for on in (False, True):  # before the edge the terrain is the floor: the two readings agree
        assert is_healthy(on, False, 0.3) and not is_healthy(on, False, 0.12)


def test_the_climb_preset_composes_to_the_recipe_and_builds_its_env():
    cfg = compose_config(["experiment=quadruped_climb"])
    loco, terrain = cfg.env.locomotion, cfg.env.terrain
    assert (loco.target_speed, list(loco.terminate_on_contact), terrain.curriculum_band, terrain.curriculum_band_share,
            terrain.height_samples, cfg.optim.lr) == (0.6, ["trunk"], 0.04, 0.7, 20, 1e-4)
    assert (loco.joint_speed_limit_cost_weight, loco.feet_air_time_weight) == (1.0, 2.0)
    batch, blind = make_batch(cfg.env, 1, threads=1), batch_of("env=quadruped_step")
    reset(batch, 0)
    assert batch.task.obs_dim == blind.task.obs_dim + 4 + 20  # 4 feet, 20 heights
    assert 1.0 <= batch.task.terrain.edge[0] - batch.task.terrain._start_along <= 2.0


def test_the_trot_recipe_is_the_clock_preset_then_its_flat_ground_fine_tune():
    """The two stages of `make trot SEED=<k>` (issue 31's pre-registered recipe): the fine-tune is the trot preset
    with flat ground, the clock's weight doubled and a lower lr, for 2M frames, and nothing else."""
    trot = compose_config(["experiment=quadruped_trot"])
    fine = compose_config(["experiment=quadruped_trot_finetune"])
    assert (trot.env.locomotion.gait_period, trot.env.locomotion.gait_clock_weight, trot.collector.total_frames) == \
        (0.6, 0.5, 10_000_000)
    for key in ("env.locomotion.gait_clock_weight", "env.terrain.flat_share", "optim.lr", "collector.total_frames"):
        OmegaConf.update(trot, key, OmegaConf.select(fine, key))
    assert trot == fine
    assert (fine.env.locomotion.gait_clock_weight, fine.env.terrain.flat_share, fine.optim.lr,
            fine.collector.total_frames) == (1.0, 0.2, 3e-5, 2_000_000)


def test_the_curriculum_and_the_step_travel_with_the_row_position():
    config = ("env=quadruped_step", "env.terrain.curriculum_window=1", "env.terrain.curriculum_threshold=1")
    batch = batch_of(*config)
    reset(batch, 0)
    step(batch, np.zeros(12))
    batch.datas[0].qpos[0] = 9.0
    mujoco.mj_kinematics(batch.models[0], batch.datas[0])
    reset(batch)
    step(batch, np.ones(12) * 0.3)
    saved = batch.row_position(0)
    fresh = batch_of(*config)
    reset(fresh, 5)
    fresh.restore_row(0, saved)
    a, b = batch.task.terrain, fresh.task.terrain
    assert b.level[0] == a.level[0] == pytest.approx(0.02)
    assert (b.height[0], b.edge[0]) == (a.height[0], a.edge[0])
    np.testing.assert_array_equal(fresh.models[0].body_pos, batch.models[0].body_pos)
    action = np.full(12, -0.2)
    first, second = step(batch, action), step(fresh, action)
    assert np.array_equal(first[0], second[0]) and first[1] == second[1]


def test_eval_envs_use_the_eval_height_and_a_fixed_height_wins():
    evaluation = batch_of("env=quadruped_step", evaluation=True)
    reset(evaluation, 0)
    assert evaluation.task.terrain.height[0] == 0.15
    fixed = batch_of("env=quadruped_step", "env.terrain.step_height=0.07", evaluation=True)
    reset(fixed, 0)
    assert fixed.task.terrain.height[0] == 0.07
    old = batch_of("env=quadruped_step", "env.terrain.step_height_range=null", "env.terrain.curriculum=false",
                   "env.terrain.step_distance=null", "env.terrain.eval_step_height=null", evaluation=True)
    reset(old, 0)
    terrain = old.task.terrain
    assert terrain.height[0] == pytest.approx(0.15) and terrain.edge[0] - terrain._start_along == pytest.approx(2.0)


def test_contacts_and_height_samples_extend_the_observation():
    blind = batch_of("env=quadruped_step").task.obs_dim
    seeing = batch_of("env=quadruped_step", "env.terrain.observe_contacts=true", "env.terrain.height_samples=30",
                      "env.terrain.step_height=0.12", "env.terrain.step_distance=[1.0,1.0]")
    assert seeing.task.obs_dim == blind + 4 + 30
    obs = reset(seeing, 0)
    samples = obs[-30:]  # 0 to 2.9 m ahead of the trunk; the edge is 1 m ahead
    assert set(np.round(samples, 3)) == {0.0, 0.12} and samples[0] == 0.0 and samples[-1] == pytest.approx(0.12)
    for _ in range(25):
        obs = step(seeing, np.zeros(12))[0]
    assert obs[-34:-30].tolist() == [1.0] * 4  # standing: four feet down
    assert seeing.task.contacts.body[0] == 0  # and no non-foot body (the shanks carry the feet)


def test_the_trot_clock_is_observed_pays_the_diagonal_schedule_and_travels_with_the_row_position():
    clock = ("env.locomotion.gait_period=0.4", "env.locomotion.gait_clock_weight=0.5")
    plain = batch_of("env=quadruped").task.obs_dim
    batch = batch_of("env=quadruped", *clock)
    assert batch.task.obs_dim == plain + 2
    obs = reset(batch, 0)
    assert obs[-2:].tolist() == [0.0, 1.0]  # sin, cos of phase 0
    lf_rh = np.array([c in ("LF", "RH") for c in batch.world.corners])
    fresh = type(batch.task.contacts)(1, batch.world)
    for k in range(1, 31):  # 20 control steps of 0.02 s make one 0.4 s period
        obs, _, _, _, terms = step(batch, np.zeros(12))
        angle = 2 * np.pi * ((k * 0.02 / 0.4) % 1.0)
        np.testing.assert_allclose(obs[-2:], [np.sin(angle), np.cos(angle)], atol=1e-9)
        fresh.read(0, batch.datas[0])
        meant = lf_rh if ((k - 1) * 0.02 / 0.4) % 1.0 < 0.5 else ~lf_rh  # the phase the step was taken in
        assert terms["reward_gait_clock"] == pytest.approx(0.5 * (fresh.feet[0] == meant).mean())
    saved = batch.row_position(0)
    other = batch_of("env=quadruped", *clock)
    reset(other, 3)
    other.restore_row(0, saved)
    action = np.full(12, 0.1)
    first, second = step(batch, action), step(other, action)
    assert np.array_equal(first[0], second[0]) and first[1] == second[1]
    with pytest.raises(Exception, match="four feet"):
        batch_of("env=mjcf", f"env.xml_file={GYM_ANT_XML}", "env.locomotion.gait_period=0.4",
                 "env.locomotion.foot_geoms=[left_ankle_geom]")


def test_heading_auto_makes_a_minus_x_model_move_forward(tmp_path):
    path = tmp_path / "backwards.xml"
    path.write_text(FACING_MINUS_X)

    def forward_velocity(heading):
        batch = batch_of("env=mjcf", f"env.xml_file={path}", "env.locomotion.main_body=base",
                         f"env.locomotion.heading={heading}", "env.locomotion.healthy_z_range=[0.0,5.0]")
        reset(batch, 0)
        batch.datas[0].qvel[0] = -1.0  # along the base's own +x: world -x
        step(batch, np.zeros(1))
        return float(batch.task.progress[0])

    assert forward_velocity("auto") > 0.5
    assert forward_velocity("-x") > 0.5 and forward_velocity("180") > 0.5
    assert forward_velocity("x") < -0.5  # Gymnasium's world +x: the robot would learn to walk backwards


def test_a_model_without_a_track_camera_gets_one_when_rendered(tmp_path):
    path = tmp_path / "no_camera.xml"
    path.write_text(FACING_MINUS_X)
    assert mujoco.MjModel.from_xml_path(str(path)).ncam == 0
    batch = batch_of("env=mjcf", f"env.xml_file={path}", "env.locomotion.main_body=base", "env.locomotion.heading=auto",
                     render_mode="rgb_array", width=64, height=48)
    model = batch.models[0]
    camera = model.camera("track")
    assert model.cam_mode[camera.id] == mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM
    assert model.cam_bodyid[camera.id] == model.body("base").id
    reset(batch, 0)
    assert batch.render().shape == (48, 64, 3)  # filmed from it
    data = batch.datas[0]
    image_right = data.cam_xmat[camera.id].reshape(3, 3)[:, 0]  # the camera's x axis: right in the image
    assert image_right[:2] @ batch.world.heading > 0.99  # the robot walks to the right of the frame
    assert batch_of("env=mjcf", f"env.xml_file={path}", "env.locomotion.main_body=base"
                    ).models[0].ncam == 0  # not rendered: the model as written
    batch.close()


def test_the_a1like_quadruped_faces_minus_x_stands_and_gets_a_tracking_camera():
    """env=quadruped_a1like: a second quadruped (its own names, built facing -x, no camera) under the recipe."""
    batch = batch_of("env=quadruped_a1like")
    model, w = batch.models[0], batch.world
    assert 12.0 < model.body_subtreemass[model.body("trunk").id] < 13.0 and model.nu == 12 and model.ncam == 0
    assert np.allclose(w.heading, [-1.0, 0.0])  # heading=auto: the trunk's nose, world -x
    assert [model.geom(int(g)).name for g in w.feet] == ["FL_foot", "FR_foot", "RL_foot", "RR_foot"]
    assert np.allclose(np.abs(model.actuator_forcerange), 33.5)  # the A1's drives
    reset(batch, 0)
    fresh = type(batch.task.contacts)(1, w)
    for _ in range(100):  # 2 s under zero action: it stands, on its four feet and nothing else
        assert not step(batch, np.zeros(12))[2]
    fresh.read(0, batch.datas[0])
    assert batch.datas[0].qpos[2] > 0.22 and fresh.feet[0].all() and fresh.body[0] == 0
    batch.datas[0].qvel[0] = -0.5  # pushed along its nose
    step(batch, np.zeros(12))
    assert batch.task.progress[0] > 0.2
    rendered = batch_of("env=quadruped_a1like", render_mode="rgb_array", width=64, height=48)
    camera = rendered.models[0].camera("track")
    assert rendered.models[0].cam_bodyid[camera.id] == rendered.models[0].body("trunk").id
    rendered.close()


@pytest.mark.parametrize("args, expected", [
    (["env.terrain.step_height=-0.05"], "env.terrain.step_height=-0.05 must be >= 0"),
    (["env.terrain.step_height_range=[0.2,0.1]"], "must be [min, max] with 0 <= min <= max"),
    (["env.terrain.step_height_range=[-0.1,0.1]"], "must be [min, max] with 0 <= min <= max"),
    (["env.terrain.step_distance=[3,2]"], "env.terrain.step_distance=[3.0, 2.0] must be [min, max]"),
    (["env.terrain.curriculum_threshold=1.5"], "curriculum_threshold=1.5 must be in (0, 1]"),
    (["env.terrain.curriculum_down_threshold=0.9"], "curriculum_down_threshold=0.9 must be in [0, curriculum_threshold=0.8)"),
    (["env.terrain.height_samples=-1"], "height_samples=-1 must be >= 0"),
    (["env.terrain.step_height=2"], "taller than the model's step box is deep"),
    (["env.locomotion.heading=north"], "env.locomotion.heading=north is not known"),
    (["env.terrain.curriculum_band=0"], "curriculum_band=0.0 must be > 0"),
    (["env.terrain.curriculum_band_share=1.5"], "curriculum_band_share=1.5 must be in [0, 1]"),
    (["env.terrain.flat_share=-0.1"], "flat_share=-0.1 must be in [0, 1]"),
    (["env.locomotion.terminate_on_contact=[torso]"], "terminate_on_contact: torso is not a body of the model"),
    (["env.locomotion.joint_speed_limit=0"], "joint_speed_limit=0.0 must be >= 0.1 rad/s"),
    (["env.locomotion.joint_speed_limit=1e-300"], "joint_speed_limit=1e-300 must be >= 0.1 rad/s"),
    (["env.locomotion.torque_cost_weight=-1"], "torque_cost_weight=-1.0 must be >= 0"),
    (["env.locomotion.joint_speed_limit=null", "env.locomotion.joint_speed_limit_cost_weight=1"],
     "joint_speed_limit_cost_weight needs env.locomotion.joint_speed_limit"),
    (["env.locomotion.gait_period=0"], "gait_period=0.0 must be > 0 s"),
    (["env.locomotion.gait_clock_weight=0.5"], "gait_clock_weight needs env.locomotion.gait_period"),
])
def test_bad_terrain_and_locomotion_values_are_one_error_line(args, expected, capsys, tmp_path):
    code, lines = refused(["env=quadruped_step", *args, f"hydra.run.dir={tmp_path / 'new'}"], capsys)
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], lines
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("args, expected", [
    (["env=quadruped", "env.terrain.step_height=0.1"], "needs a model with a body named 'step'"),
    (["env=InvertedPendulum-v4", "env.terrain.step_height=0.1"], "works on MJCF robots"),
])
def test_terrain_needs_a_step_model(args, expected, capsys, tmp_path):
    code, lines = refused([*args, f"hydra.run.dir={tmp_path / 'new'}"], capsys)
    assert code == 2 and len(lines) == 1 and expected in lines[0], lines


@pytest.fixture(scope="module")
def step_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("step_run")
    cfg = compose_config(["env=quadruped_step", *TINY, "env.max_episode_steps=40", "policy.hidden_sizes=[16,16]",
                          "policy.critic_hidden_sizes=[16,16]"])
    Trainer(cfg, run).train()
    return run


def test_a_curriculum_run_logs_its_level_and_success(step_run):
    rows = list(csv.DictReader(open(step_run / "metrics.csv")))
    assert rows and all(float(r["env/terrain_level"]) == 0.0 and 0.0 <= float(r["env/terrain_success"]) <= 1.0
                        for r in rows)


def test_evaluate_at_a_step_height_reports_gait_figures(step_run, capsys):
    result = evaluate.main([f"run={step_run}", "episodes=2", "env.terrain.step_height=0.05"])
    saved = json.loads((step_run / "eval" / "eval.json").read_text())
    assert saved["step_height_mean"] == pytest.approx(0.05) and saved["overrides"] == ["env.terrain.step_height=0.05"]
    for key in ("success_rate", "crossed_at_end_rate", "terminated_share", "stride_frequency", "duty_factor",
                "peak_joint_speed", "over_speed_limit_share", "body_contact_share", *figures.GAIT_KEYS):
        assert key in result and key in saved
    assert saved["feet"] == ["LF_foot", "RF_foot", "LH_foot", "RH_foot"]  # the model's foot order
    assert len(saved["foot_contact_share"]) == len(saved["touchdown_frequency"]) == 4
    assert saved["duty_factor"] == pytest.approx(np.mean(saved["foot_contact_share"]))
    outcomes = saved["outcomes"]  # one record per episode
    assert [o["seed"] for o in outcomes] == [0, 1] and [o["length"] for o in outcomes] == saved["lengths"]
    assert saved["success_rate"] == np.mean([o["crossed"] and not o["terminated"] for o in outcomes])
    assert all(len(o[key]) == 4 for o in outcomes for key in figures.EPISODE_FOOT_KEYS)  # per foot, per episode
    printed = capsys.readouterr().out
    assert f"{saved['success_rate']:.0%} of episodes cross the line" in printed and "are not terminated" in printed
    assert f"LF_foot {saved['foot_contact_share'][0]:.2f}" in printed
    assert all(0 <= moving <= air for moving, air in zip(saved["longest_air_moving_s"], saved["longest_air_s"]))
    assert 0.0 <= result["duty_factor"] <= 1.0 and result["peak_joint_speed"] <= result["joint_speed_limit"]
    assert result["over_speed_limit_share"] == 0.0  # never over the limit, as the peak says


def test_the_gait_meter_counts_the_time_a_joint_is_over_the_speed_limit():
    from ppo_torchrl.tasks.locomotion.figures import gait_figures
    from ppo_torchrl.robots.gait import GaitMeter

    episodes = []
    for speeds in ([1.0, 9.0, 2.0, 8.0], [3.0] * 6):  # 8.0 is at the limit, not over it
        meter = GaitMeter(4, speed_limit=8.0)
        for speed in speeds:
            meter.add(np.ones(4, bool), speed, False, 0.005)
        episodes.append(meter.summary())
    figures = gait_figures(episodes, 8.0)
    assert figures["peak_joint_speed"] == 9.0 and figures["over_speed_limit_share"] == pytest.approx(1 / 10)
    assert "over_speed_limit_share" not in gait_figures(episodes, None)


def test_success_is_crossing_without_a_fall_or_a_forbidden_contact():
    from ppo_torchrl.robots.gait import GaitMeter

    gait = GaitMeter(4).summary()
    record = {"returns": [1.0, 2.0, 3.0, 4.0], "lengths": [500, 120, 500, 80], "dt": 0.02, "success_margin": 0.5,
              "distances": [(5.0, 5.0)] * 4, "gaits": [gait] * 4, "heights": [0.15] * 4, "seeds": [10, 11, 12, 13],
              "crossed": [True, True, False, False], "terminated": [False, True, False, True],
              "ends": [None, "contact: trunk", None, "fall"], "feet": ("a", "b", "c", "d"), "figures": "locomotion"}
    result = evaluate.summarize(compose_config(["env=quadruped_step"]), record)
    # beyond the line at the end: 2 of 4; of them one ended on its trunk: 1 of 4 succeeds
    assert (result["success_rate"], result["crossed_at_end_rate"], result["terminated_share"]) == (0.25, 0.5, 0.5)
    assert result["termination_shares"] == {"contact: trunk": 0.25, "fall": 0.25}
    assert [(o["seed"], o["crossed"], o["success"], o["termination"]) for o in result["outcomes"]] == [
        (10, True, True, None), (11, True, False, "contact: trunk"), (12, False, False, None),
        (13, False, False, "fall")]
    line = evaluate.result_lines(result)
    assert "25% of episodes cross the line 0.5 m beyond the step" in line and "50% are beyond it at the end" in line
    assert "50% end terminated (25% contact: trunk, 25% fall)" in line
    # an env without its own reason (not a locomotion env) still counts its terminated episodes
    record.update(ends=[None] * 4)
    result = evaluate.summarize(compose_config(["env=quadruped_step"]), record)
    assert result["termination_shares"] == {"terminated": 0.5}


def gait_of(pattern: str, corners=("LF", "RF", "LH", "RH"), repeats: int = 20):
    """Per-foot figures of a repeated contact pattern: each character a 0.05 s phase, the feet down in it
    ('a' LF+RH, 'b' RF+LH, 'l' LF+LH, 'r' RF+RH, 'f' LF+RF, 'h' LH+RH, '3' all but RH, '-' none)."""
    from ppo_torchrl.tasks.locomotion.figures import gait_figures
    from ppo_torchrl.robots.gait import GaitMeter

    down = {"a": "LF RH", "b": "RF LH", "l": "LF LH", "r": "RF RH", "f": "LF RF", "h": "LH RH", "3": "LF RF LH",
            "-": ""}
    meter = GaitMeter(4, corners=list(corners))
    for phase in pattern * repeats:
        feet = np.array([c in down[phase].split() for c in corners])
        for _ in range(10):
            meter.add(feet, 0.0, False, 0.005)
    return gait_figures([meter.summary()], None)


def test_per_foot_gait_figures_tell_a_trot_a_pace_a_bound_and_a_limp_apart():
    trot, pace, bound = gait_of("a-b-"), gait_of("l-r-"), gait_of("f-h-")
    for gait, together in ((trot, "diagonal"), (pace, "same_side"), (bound, "same_end")):
        assert gait["foot_contact_share"] == pytest.approx([0.25] * 4)
        assert gait["touchdown_frequency"] == pytest.approx([5.0] * 4, rel=0.05)  # one touchdown each 0.2 s cycle
        assert {k: gait[f"{k}_pairs_together"] for k in ("diagonal", "same_side", "same_end")} == {
            k: 1.0 if k == together else 0.0 for k in ("diagonal", "same_side", "same_end")}
    limp = gait_of("3-")  # RH never lands: a mean over feet (the duty factor) cannot see it, the per-foot share can
    assert limp["foot_contact_share"] == pytest.approx([0.5, 0.5, 0.5, 0.0]) and limp["touchdown_frequency"][3] == 0
    assert trot["longest_air_s"] == pytest.approx([0.15] * 4)  # up for three of the four 0.05 s phases
    assert limp["longest_air_s"] == pytest.approx([0.05, 0.05, 0.05, 2.0])  # RH up the whole 2 s
    assert limp["duty_factor"] == pytest.approx(0.375)
    # the figures follow the model's foot order, whatever it is
    assert gait_of("a-b-", corners=("RH", "LH", "RF", "LF"))["diagonal_pairs_together"] == 1.0
    from ppo_torchrl.robots.gait import GaitMeter

    assert "diagonal_pairs_together" not in figures.gait_figures([GaitMeter(3).summary()], None)  # no corners


def test_a_foot_held_up_at_a_standstill_is_not_counted_as_in_the_air_while_moving():
    from ppo_torchrl.robots.gait import GaitMeter

    meter, up, down = GaitMeter(1), np.array([False]), np.array([True])
    for feet, moving, seconds in ((up, True, 0.3), (up, False, 1.0), (up, True, 0.3), (down, True, 0.1),
                                  (up, True, 0.2), (down, False, 0.1)):
        for _ in range(round(seconds / 0.005)):
            meter.add(feet, 0.0, False, 0.005, moving)
    gait = meter.summary()
    assert gait["longest_air_s"] == pytest.approx([1.6])  # the whole spell, standstill included
    assert gait["longest_air_moving_s"] == pytest.approx([0.6])  # the same spell's moving part: 0.3 + 0.3


def test_each_foot_is_placed_at_its_corner_along_the_heading(tmp_path):
    corners = lambda *o: batch_of(*o).world.corners  # noqa: E731
    assert list(corners("env=quadruped")) == ["LF", "RF", "LH", "RH"]
    a1like = batch_of("env=quadruped_a1like").world  # built facing -x: its front is world -x
    assert list(a1like.foot_names) == ["FL_foot", "FR_foot", "RL_foot", "RR_foot"]
    assert list(a1like.corners) == ["LF", "RF", "LH", "RH"]
    # legs out at 45 degrees, in turn round
    assert list(corners("env=mjcf", f"env.xml_file={GYM_ANT_XML}")) == ["LF", "LH", "RH", "RF"]
    (tmp_path / "one_leg.xml").write_text(FACING_MINUS_X)
    one_leg = batch_of("env=mjcf", f"env.xml_file={tmp_path / 'one_leg.xml'}", "env.locomotion.main_body=base",
                       "env.locomotion.heading=-x").world
    assert len(one_leg.feet) == 1 and one_leg.corners is None  # no pair figures


def test_height_sweep_writes_a_csv_and_a_success_curve(step_run, tmp_path):
    evaluate.main([f"run={step_run}", "episodes=2", "heights=0,0.1,0.2", f"out={tmp_path}"])
    rows = list(csv.DictReader(open(tmp_path / "height_sweep.csv")))
    assert [float(r["step_height_m"]) for r in rows] == [0.0, 0.1, 0.2]
    assert all(0.0 <= float(r["success_rate"]) <= float(r["crossed_at_end_rate"]) for r in rows)
    assert all(float(r["foot_contact_share LF_foot"]) >= 0 and "diagonal_pairs_together" in r for r in rows)
    episodes = list(csv.DictReader(open(tmp_path / "height_sweep_episodes.csv")))  # a row per episode
    assert [(float(e["step_height_m"]), int(e["seed"])) for e in episodes] == [
        (h, s) for h in (0, 0.1, 0.2) for s in (0, 1)]
    for row in rows:
        mine = [e for e in episodes if e["step_height_m"] == row["step_height_m"]]
        assert float(row["success_rate"]) == np.mean([e["success"] == "True" for e in mine])
        assert float(row["terminated_share"]) == np.mean([e["terminated"] == "True" for e in mine])
        for foot in ("LF_foot", "RH_foot"):  # the height's worst case is one episode's, its mean the episodes'
            assert float(row[f"longest_air_moving_s {foot}"]) == max(
                float(e[f"longest_air_moving_s {foot}"]) for e in mine)
            assert float(row[f"touchdown_frequency {foot}"]) == pytest.approx(
                np.mean([float(e[f"touchdown_frequency {foot}"]) for e in mine]))
    saved = json.loads((tmp_path / "height_sweep.json").read_text())
    assert [h["step_height_m"] for h in saved["heights"]] == [0.0, 0.1, 0.2] and saved["seed"] == 0
    assert (tmp_path / "height_sweep.png").read_bytes()[:4] == b"\x89PNG"
