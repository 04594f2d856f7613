"""Bring your own robot: env=mjcf from a model file, the shipped quadruped, and init_from transfer."""

import json
from pathlib import Path

import gymnasium
import mujoco
import numpy as np
import pytest
import torch

from ppo_torchrl.run import checkpoint
from ppo_torchrl.envs.make import ASSETS_DIR, make_batch
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.trainer import Trainer
from conftest import compose_config, run_cli

GYM_ANT_XML = Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets" / "ant.xml"
NO_FREE_JOINT = """<mujoco><worldbody><body><joint name="hinge" type="hinge"/><geom size="0.1"/></body></worldbody>
<actuator><motor joint="hinge"/></actuator></mujoco>"""
# Quadruped runs sized for a test: one eval episode capped at 50 steps.
SHORT = ["env.max_episode_steps=50", "policy.hidden_sizes=[32,32]", "policy.critic_hidden_sizes=[32,32]"]


def test_mjcf_runs_a_model_it_was_not_tuned_for(tiny_cfg, tmp_path):
    """Gymnasium's own ant.xml through env=mjcf: the model file, not Ant-v5's built-in one, is loaded."""
    cfg = tiny_cfg("env=mjcf", f"env.xml_file={GYM_ANT_XML}", "env.locomotion.frame_skip=5",
                   "env.max_episode_steps=100")
    env = make_batch(cfg.env)
    assert Path(env.world.xml_file) == GYM_ANT_XML.resolve() and env.world.frame_skip == 5
    assert env.single_observation_space.shape == (27,) and env.single_action_space.shape == (8,)  # no contact forces
    summary = Trainer(cfg, tmp_path).train()
    assert summary["env"] == "mjcf:ant.xml" and summary["frames"] == 512
    assert "forward_velocity_mean" in summary


def test_mjcf_without_a_model_file_is_an_error():
    with pytest.raises(ConfigError, match="needs the robot's model file"):
        make_batch(compose_config(["env=mjcf"]).env)


@pytest.mark.parametrize("content, message", [
    (None, "no such file"),
    ("<mujoco><worldbody><body>", "not a valid MuJoCo model"),
    (NO_FREE_JOINT, "no free joint"),
])
def test_bad_model_files_are_one_line_errors(tmp_path, content, message):
    path = tmp_path / "robot.xml"
    if content is not None:
        path.write_text(content)
    with pytest.raises(ConfigError, match=message):
        make_batch(compose_config(["env=mjcf", f"env.xml_file={path}"]).env)


def test_bad_model_file_on_the_command_line_exits_2_with_one_line(tmp_path):
    path = tmp_path / "robot.xml"
    path.write_text(NO_FREE_JOINT)
    out = run_cli("env=mjcf", f"env.xml_file={path}", f"hydra.run.dir={tmp_path / 'run'}")
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "free joint" in lines[0], out.stderr


def test_quadruped_model_is_a_19kg_12dof_robot_that_stands():
    model = mujoco.MjModel.from_xml_path(str(ASSETS_DIR / "quadruped.xml"))
    assert 17.0 < model.body_subtreemass[1] < 21.0
    assert model.nu == 12 and (model.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE).all()  # position servos
    joints = [model.joint(i).name for i in range(1, model.njnt)]
    assert {j.split("_")[1] for j in joints} == {"HAA", "HFE", "KFE"}
    feet = [i for i in range(model.ngeom) if model.geom(i).name.endswith("_foot")]
    assert len(feet) == 4 and all(model.geom_type[i] == mujoco.mjtGeom.mjGEOM_SPHERE for i in feet)
    data = mujoco.MjData(model)
    for _ in range(400):  # 2 s holding the standing pose
        mujoco.mj_step(model, data)
    assert data.qpos[2] > 0.38


def test_step_model_has_a_15cm_step_ahead(tiny_cfg):
    """The model file's own step (what runs made before env.terrain see): 15 cm, 2 m ahead."""
    env = make_batch(tiny_cfg("env=mjcf", "env.xml_file=quadruped_step.xml", "env.locomotion.main_body=trunk").env)
    env.reset(seed=0)
    model, data = env.models[0], env.datas[0]
    step = model.geom("step")
    top = data.geom_xpos[step.id][2] + model.geom_size[step.id][2]
    edge = data.geom_xpos[step.id][0] - model.geom_size[step.id][0]
    assert top == pytest.approx(0.15) and edge == pytest.approx(2.0)
    assert model.geom_size[step.id][1] >= 40  # too wide to walk around in an episode
    assert model.body("trunk").id == 1  # the step body comes after the robot: its body ids are quadruped.xml's


def test_init_from_transfers_weights_stats_and_optimizer(tiny_cfg, tmp_path):
    source = Trainer(tiny_cfg("env=quadruped", *SHORT), tmp_path / "flat")
    source.train()
    saved = checkpoint.load(checkpoint.resolve_checkpoint(tmp_path / "flat", "best"))
    target = Trainer(tiny_cfg("env=quadruped_step", *SHORT, f"init_from={tmp_path / 'flat'}",
                              "init_from_optimizer=true"), tmp_path / "step")
    for name, value in saved["actor"].items():
        torch.testing.assert_close(target.ac.actor.state_dict()[name], value)
    np.testing.assert_allclose(target.collector.obs_stats()["mean"], saved["normalization"]["obs"]["mean"])
    assert target.optimizer.state_dict()["state"], "optimizer moments were not loaded"
    assert target.frames == 0  # a new run: counters start fresh
    summary = target.train()
    assert summary["env"] == "mjcf:quadruped_step.xml" and "success_rate" in summary
    # the last eval's per-foot gait figures, in the model's foot order
    assert summary["feet"] == ["LF_foot", "RF_foot", "LH_foot", "RH_foot"]
    assert len(summary["foot_contact_share"]) == len(summary["touchdown_frequency"]) == 4
    assert all(0 <= summary[key] <= 1 for key in ("diagonal_pairs_together", "same_side_pairs_together",
                                                  "same_end_pairs_together") if summary[key] is not None)


def test_init_from_refuses_what_does_not_fit(tiny_cfg, tmp_path):
    Trainer(tiny_cfg(), tmp_path / "pendulum").train()
    with pytest.raises(ConfigError, match="observations of size 4"):
        Trainer(tiny_cfg("env=quadruped", f"init_from={tmp_path / 'pendulum'}"), tmp_path / "a")
    with pytest.raises(ConfigError, match="networks do not fit"):
        Trainer(tiny_cfg("policy.hidden_sizes=[16,16]", f"init_from={tmp_path / 'pendulum'}"), tmp_path / "b")
    with pytest.raises(ConfigError, match="no such run dir"):
        Trainer(tiny_cfg(f"init_from={tmp_path / 'nowhere'}"), tmp_path / "c")


def test_eval_env_keeps_the_models_frame_skip_and_time_limit(tiny_cfg):
    """The TorchRL env used for eval must step the same MuJoCo env (GymEnv would eat frame_skip)."""
    from ppo_torchrl.envs.make import make_torchrl_env

    cfg = tiny_cfg("env=quadruped", "env.max_episode_steps=30", "env.locomotion.healthy_z_range=[0.0,5.0]")
    env = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99, obs_stats={"mean": np.zeros(35), "var": np.ones(35)},
                           train=False)
    from ppo_torchrl.envs.state import env_state_of

    assert env_state_of(env).rows.batch.world.frame_skip == 4  # a model file's robot: the batched env
    rollout = env.rollout(1000, break_when_any_done=True)
    assert rollout.shape[-1] == 30


@pytest.mark.parametrize("model", ["quadruped.xml", "quadruped_a1like.xml"])
def test_shipped_quadrupeds_joint_ranges_cover_their_actuators_targets(model):
    """A position actuator's targets must be reachable: each joint's range holds its ctrlrange (in
    radians). quadruped.xml once wrote radians under angle="degree" and its legs barely bent."""
    import mujoco

    from ppo_torchrl.envs.make import resolve_model_file

    m = mujoco.MjModel.from_xml_path(str(resolve_model_file(model)))
    for a in range(m.nu):
        joint = m.actuator_trnid[a, 0]
        low, high = m.jnt_range[joint]
        c_low, c_high = m.actuator_ctrlrange[a]
        assert low <= c_low and c_high <= high, (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, joint), m.jnt_range[joint])


def test_the_robots_table_puts_a_robots_runs_side_by_side_as_its_goal_table_counts_them(capsys):
    """benchmarks/robots_table.py --goals 59's last table (the README's): one row per robot, its runs a / b in the
    order given, each run's goals met the count of `met` in its column of the goal table."""
    import sys

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "benchmarks"))
    import robots_table

    shipped = root / "results" / "robots" / "legged_v2_2026-11-28"
    assert robots_table.main([str(shipped / "go1_seed12"), str(shipped / "anymal_b_seed12"), str(shipped / "go1_seed13"),
                              "--goals", "59"]) == 0
    text = capsys.readouterr().out
    last = text.strip().split("\n\n")[-1].splitlines()
    assert last[0].startswith("| robot (mass, l, step) | run |") and len(last) == 4  # head, rule, go1, anymal_b
    cells = lambda row: [c.strip() for c in row.strip().strip("|").split("|")]  # noqa: E731
    go1, anymal = (cells(row) for row in last[2:])
    assert go1[0].startswith("go1 (12.7 kg, 0.426 m") and go1[1] == "seed12 / seed13" and anymal[1] == "seed12"
    goal_table = next(t for t in text.split("\n\n") if t.startswith("| goal |")).splitlines()[2:]
    met = [sum(cells(row)[1 + i].startswith("met") for row in goal_table) for i in range(3)]
    assert go1[-1] == f"{met[0]} / {met[2]}" and anymal[-1] == str(met[1])
