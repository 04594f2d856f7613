"""Issue 46: a robot read from its model (env=legged, ppo_torchrl/robots/). The six MuJoCo Menagerie
quadrupeds in ppo_torchrl/assets/menagerie (their README gives the figures checked here), real file layouts, bad
robots as one line, the step added to any model. No training."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from conftest import run_app as launched
from ppo_torchrl.errors import ConfigError

ROBOTS_DIR = Path(__file__).resolve().parents[1] / "ppo_torchrl" / "assets" / "menagerie"

# ppo_torchrl/assets/menagerie/README.md: name, mass kg, home trunk z m, leg (thigh + shank) m, drive, heading, each corner's
# foot (a geom name, or the body of an unnamed foot sphere)
FACTS = {
    "unitree_go1": ("go1", 12.743, 0.27, 0.426, "position", (1, 0), {"LF": "FL", "RF": "FR", "LH": "RL", "RH": "RR"}),
    "unitree_go2": ("go2", 15.206, 0.27, 0.426, "motor", (1, 0), {"LF": "FL", "RF": "FR", "LH": "RL", "RH": "RR"}),
    "unitree_a1": ("a1", 12.453, 0.27, 0.400, "position", (1, 0),
                   {"LF": "FL_calf", "RF": "FR_calf", "LH": "RL_calf", "RH": "RR_calf"}),
    "anybotics_anymal_b": ("anymal_b", 33.331, 0.58, 0.5877, "position", (-1, 0),
                           {"LF": "LF_SHANK", "RF": "RF_SHANK", "LH": "LH_SHANK", "RH": "RH_SHANK"}),
    "boston_dynamics_spot": ("spot", 50.34, 0.46, 0.6575, "position", (1, 0),
                             {"LF": "FL", "RF": "FR", "LH": "HL", "RH": "HR"}),
    "google_barkour_vb": ("barkour_vb", 14.496, 0.28, 0.4304, "position", (1, 0),
                          {"LF": "foot_front_left", "RF": "foot_front_right", "LH": "foot_hind_left",
                           "RH": "foot_hind_right"}),
}


def scene(folder: str) -> Path:
    return ROBOTS_DIR / folder / "scene.xml"


@pytest.mark.parametrize("folder", sorted(FACTS))
def test_each_menagerie_robot_is_read_from_its_model_as_its_readme_gives_it(folder):
    from ppo_torchrl.robots.model import read_robot

    name, mass, height, leg, drive, heading, feet = FACTS[folder]
    robot = read_robot(scene(folder))
    model = mujoco.MjModel.from_xml_path(str(scene(folder)))
    assert robot.name == name
    assert robot.mass == pytest.approx(mass, abs=1e-3)
    assert robot.height == pytest.approx(height, abs=1e-3)
    assert robot.leg_length == pytest.approx(leg, abs=1e-3)
    assert set(robot.drive) == {drive}
    assert robot.heading == pytest.approx(heading, abs=1e-6)
    by_corner = {}
    for corner, geom in zip(robot.corners, robot.feet):
        assert model.geom_type[geom] == mujoco.mjtGeom.mjGEOM_SPHERE  # every foot here is a sphere
        by_corner[corner] = model.geom(geom).name or model.body(model.geom_bodyid[geom]).name
    assert by_corner == feet
    assert robot.keyframe == (None if folder == "anybotics_anymal_b" else "home")


@pytest.mark.parametrize("folder", sorted(FACTS))
def test_each_robot_stands_for_two_seconds_at_its_derived_pose_under_its_derived_drives(folder):
    """The env's own start (no reset noise) and drives (action 0 holds the standing pose): the trunk stays
    within 20% of its standing height and tilts under 30 degrees, with only its feet (and A1's calves,
    Menagerie's geometry) on the floor."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    cfg = compose(["env=legged", f"env.xml_file={scene(folder)}", "env.locomotion.reset_noise_scale=0"])
    batch = make_batch(cfg.env, 1, threads=1)
    batch.reset(seed=0)
    data, w = batch.datas[0], batch.world
    start = float(data.qpos[2])
    heights, tilts = [], []
    for _ in range(int(round(2.0 / batch.dt))):
        _, _, terminated, _, _ = batch.step(np.zeros((1, w.model.nu)))
        assert not terminated[0]
        heights.append(data.qpos[2])
        tilts.append(math.degrees(math.acos(min(1.0, data.xmat[w.trunk][8]))))
    assert start == pytest.approx(FACTS[folder][2], abs=1e-3)
    assert max(abs(h - start) for h in heights) <= 0.2 * start
    assert max(tilts) < 30.0
    feet = type(batch.task.contacts)(1, w)
    feet.read(0, data)
    assert feet.feet[0].all()
    batch.close()


def test_a_full_action_moves_a_joint_no_further_than_its_servo_saturates():
    """env.legged.action_scale (0.5 rad) is the most; a servo that reaches its peak torque sooner (peak / kp, from
    the model) gets that angle: Go1 23.7 / 100 (hips) and 35.55 / 100 (knees), ANYmal B 40 / 100, Go2's torque
    motors their derived PD's 0.3 rad."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    expected = {"unitree_go1": [0.237, 0.237, 0.3555] * 4, "anybotics_anymal_b": [0.4] * 12, "unitree_go2": [0.3] * 12}
    for folder, scales in expected.items():
        world = make_batch(compose(["env=legged", f"env.xml_file={scene(folder)}"]).env).world
        assert world.ctrl_per_action == pytest.approx(scales), folder
        assert (world.ctrl_of(np.ones(12)) - world.ctrl_of(np.zeros(12)) <= np.array(scales) + 1e-9).all()
    world = make_batch(compose(["env=legged", f"env.xml_file={scene('unitree_go1')}",
                                "env.legged.action_scale=0.1"]).env).world
    assert world.ctrl_per_action == pytest.approx([0.1] * 12)  # the most, where the servos saturate later


def test_the_legged_recipe_moves_every_joint_by_the_action_scale_and_explores_gently():
    """experiment=legged_trot turns the saturation cap off (under it a Go1 foot could rise only 0.24 l, under the
    step of 0.25 l) and starts its policy at std 0.4; its start line says so. A saved run without the key keeps the
    cap it trained with."""
    from omegaconf import OmegaConf

    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import describe

    cfg = compose(["experiment=legged_trot", f"env.xml_file={scene('unitree_go1')}"])
    world = make_batch(cfg.env).world
    assert world.ctrl_per_action == pytest.approx([0.5] * 12)
    assert "actions move joints up to 0.50 rad" in describe(read_robot(scene("unitree_go1")), cfg.env.legged)
    assert world.ctrl_of(np.ones(12))[2] - world.ctrl_of(np.zeros(12))[2] == pytest.approx(0.5)
    saved = OmegaConf.create(OmegaConf.to_container(cfg))  # as a run dir's config.yaml is read back
    del saved.env.legged["saturation_cap"]  # saved before the key existed: the cap it trained under
    assert make_batch(saved.env).world.ctrl_per_action == pytest.approx([0.237, 0.237, 0.3555] * 4)
    assert math.exp(cfg.policy.log_std_init) + cfg.policy.std_min == pytest.approx(0.4, abs=0.002)
    assert OmegaConf.select(cfg, "env.terrain.flat_share") == 0.2


def test_eval_measures_joint_torque_against_the_models_own_limits():
    """Standing (action 0) a Go1's servos hold well under their force range; driven to the ends of the action
    range they saturate: the peak share reaches 1.0 (the model's limit, not more) and the time at it shows."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch
    from ppo_torchrl.tasks.locomotion.evaluation import GaitBatch

    cfg = compose(["env=legged", f"env.xml_file={scene('unitree_go1')}", "env.locomotion.reset_noise_scale=0"])
    batch = make_batch(cfg.env, 1, evaluation=True, threads=1)
    batch.gait = GaitBatch(1, batch.world, None)  # the gait figures, sampled at every physics step
    figures = {}
    for name, action in (("standing", np.zeros(12)), ("driven", np.tile([1.0, -1.0, 1.0], 4))):
        batch.reset(seed=0)
        for _ in range(int(round(0.5 / batch.dt))):
            batch.step(action[None])
        figures[name] = batch.gait.meters[0].summary()
    assert 0.0 < figures["standing"]["peak_torque_share"] < 0.9
    assert figures["standing"]["torque_at_limit_share"] == 0.0
    assert figures["driven"]["peak_torque_share"] == pytest.approx(1.0, abs=1e-6)
    assert figures["driven"]["torque_at_limit_share"] > 0.0


def test_the_robustness_worlds_halve_every_contacts_grip_and_weigh_the_trunk_down():
    """env.legged.friction_scale=0.5: every geom's friction halved (a contact takes the larger of its pair's, so the
    grip halves: halving the floor alone would leave a Go1's feet at 0.6 of 1.0); trunk_mass_scale=1.1: the trunk
    10% heavier, inertia too; a heavier trunk settles lower standing. The model file is not touched."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    text = scene("unitree_go1").parent.joinpath("go1.xml").read_text()
    envs = {}
    for name, extra in (("plain", []), ("world", ["env.legged.friction_scale=0.5", "env.legged.trunk_mass_scale=1.1"])):
        cfg = compose(["env=legged", f"env.xml_file={scene('unitree_go1')}", "env.locomotion.reset_noise_scale=0", *extra])
        envs[name] = make_batch(cfg.env, 1, threads=1)
    plain, world = envs["plain"].models[0], envs["world"].models[0]
    assert np.allclose(world.geom_friction, 0.5 * plain.geom_friction)
    trunk = envs["plain"].world.trunk
    assert world.body_mass[trunk] == pytest.approx(1.1 * plain.body_mass[trunk])
    assert np.allclose(world.body_inertia[trunk], 1.1 * plain.body_inertia[trunk])
    heights = {}
    for name, batch in envs.items():
        batch.reset(seed=0)
        for _ in range(int(round(1.0 / batch.dt))):
            batch.step(np.zeros((1, 12)))
        heights[name] = float(batch.datas[0].xpos[trunk][2])
    assert heights["world"] < heights["plain"]
    assert scene("unitree_go1").parent.joinpath("go1.xml").read_text() == text
    with pytest.raises(ConfigError, match="friction_scale=0.0 must be > 0"):
        from ppo_torchrl.validation import validate_config

        validate_config(compose(["env=legged", f"env.xml_file={scene('unitree_go1')}", "env.legged.friction_scale=0"]))


def test_torque_motors_become_pd_servos_around_the_standing_pose_with_gains_from_the_model():
    """Go2's torque motors: kp = peak torque / 0.3 rad, kd = 2 sqrt(kp I); used as Menagerie ships them (its
    keyframe's ctrl, angles, sent as torques) the robot collapses to 0.077 m (the robots' README)."""
    from ppo_torchrl.robots.model import PD_SATURATION_RAD, read_robot

    robot = read_robot(scene("unitree_go2"))
    assert robot.kp[2] == pytest.approx(45.43 / PD_SATURATION_RAD)
    assert all(kd > 0 for kd in robot.kd)
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    batch = make_batch(compose(["env=legged", f"env.xml_file={scene('unitree_go2')}"]).env)
    batch.reset(seed=0)
    model, world = batch.models[0], batch.world
    a = 2  # a knee: a position actuator around its standing angle, limited to the motor's torque
    assert model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE
    assert model.actuator_forcerange[a].tolist() == pytest.approx([-45.43, 45.43])
    assert world.ctrl_of(np.zeros(12))[a] == pytest.approx(-1.8)
    assert world.ctrl_of(np.ones(12))[a] == pytest.approx(-1.8 + PD_SATURATION_RAD)  # a full action: where it saturates


def test_the_step_is_added_to_a_model_that_has_none_at_a_quarter_leg_length_and_faces_the_heading():
    """ANYmal B faces -x: its step (0.25 l = 14.7 cm in evaluation) lies ahead of it, made by MjSpec at build
    time; the model file is not touched."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    before = scene("anybotics_anymal_b").read_bytes(), (ROBOTS_DIR / "anybotics_anymal_b" / "anymal_b.xml").read_bytes()
    cfg = compose(["env=legged", f"env.xml_file={scene('anybotics_anymal_b')}"])
    batch = make_batch(cfg.env, 1, evaluation=True, threads=1)
    batch.reset(seed=3)
    terrain, data, model = batch.task.terrain, batch.datas[0], batch.models[0]
    assert terrain.has_step and terrain.height[0] == pytest.approx(0.25 * 0.5877, abs=1e-3)
    edge = terrain.edge[0]
    points = np.array([[[(edge - 0.01) * terrain.heading[0], (edge - 0.01) * terrain.heading[1]],
                        [(edge + 0.01) * terrain.heading[0], (edge + 0.01) * terrain.heading[1]]]])
    assert terrain.height_at(slice(0, 1), points)[0].tolist() == pytest.approx([0.0, terrain.height[0]])
    mujoco.mj_kinematics(model, data)
    box = data.geom_xpos[model.geom("step").id]
    assert box[0] < data.qpos[0] - 1.0  # the box lies towards world -x
    assert terrain.crossed(0, data.xpos[batch.world.trunk, :2]) is False
    after = scene("anybotics_anymal_b").read_bytes(), (ROBOTS_DIR / "anybotics_anymal_b" / "anymal_b.xml").read_bytes()
    assert before == after


def tiny_stl() -> bytes:
    """A binary STL of two triangles (MuJoCo reads binary STL only)."""
    import struct

    triangles = [((0, 0, 1), (0, 0, 0), (0.05, 0, 0), (0, 0.05, 0)), ((-1, 0, 0), (0, 0, 0), (0, 0.05, 0), (0, 0, 0.05))]
    body = b"".join(struct.pack("<12fH", *[c for v in t for c in v], 0) for t in triangles)
    return b"tiny".ljust(80, b" ") + struct.pack("<I", len(triangles)) + body


def write_robot(folder: Path, *, free=True, feet=4, keyframe_in_scene=True, site_actuator=False) -> Path:
    """A small four-legged robot in the Menagerie layout: robot.xml (a visual mesh from meshdir assets/) and
    scene.xml that includes it and holds the floor and the 'home' keyframe."""
    (folder / "assets").mkdir(parents=True, exist_ok=True)
    (folder / "assets" / "shell.stl").write_bytes(tiny_stl())
    legs = ""
    for i, (name, x, y) in enumerate([("LF", 0.2, 0.1), ("RF", 0.2, -0.1), ("LH", -0.2, 0.1), ("RH", -0.2, -0.1)]):
        if i >= feet:
            break
        legs += f"""
      <body name="{name}_thigh" pos="{x} {y} 0">
        <joint name="{name}_hip" axis="0 1 0" range="-1.5 1.5"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.15" size="0.02" mass="0.3"/>
        <body name="{name}_shank" pos="0 0 -0.15">
          <joint name="{name}_knee" axis="0 1 0" range="-2.5 0"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.15" size="0.015" mass="0.2"/>
          <geom type="sphere" pos="0 0 -0.15" size="0.02" mass="0.05"/>
        </body>
      </body>"""
    actuators = "".join(f'<position joint="{n}_{j}" kp="30" forcerange="-8 8" ctrlrange="-3 3"/>'
                        for n in ("LF", "RF", "LH", "RH")[:feet] for j in ("hip", "knee"))
    if site_actuator:
        actuators += '<motor site="imu" gear="0 0 0 0 0 1" ctrlrange="-1 1"/>'
    (folder / "robot.xml").write_text(f"""<mujoco model="tiny">
  <compiler meshdir="assets"/>
  <asset><mesh name="shell" file="shell.stl"/></asset>
  <worldbody>
    <body name="trunk" pos="0 0 0.32">
      {'<freejoint/>' if free else ''}
      <site name="imu"/>
      <geom type="box" size="0.25 0.12 0.05" mass="4"/>
      <geom type="mesh" mesh="shell" contype="0" conaffinity="0" group="2"/>{legs}
    </body>
  </worldbody>
  <actuator>{actuators}</actuator>
</mujoco>""")
    nq = 7 * free + 2 * feet
    home = "0 0 0.3 1 0 0 0 " + " ".join(["0.3 -0.6"] * feet) if free else " ".join(["0.3 -0.6"] * feet)
    key = f'<keyframe><key name="home" qpos="{home}"/></keyframe>' if keyframe_in_scene and nq else ""
    (folder / "scene.xml").write_text(f"""<mujoco model="tiny scene">
  <include file="robot.xml"/>
  <worldbody><geom name="floor" type="plane" size="0 0 0.05"/></worldbody>
  {key}
</mujoco>""")
    return folder / "scene.xml"


def test_a_scene_that_includes_its_robot_with_a_mesh_dir_and_its_keyframe_in_the_scene_loads(tmp_path):
    from ppo_torchrl.robots.model import read_robot

    robot = read_robot(write_robot(tmp_path / "tiny_robot"))
    assert robot.name == "tiny" and robot.keyframe == "home"
    assert robot.height == pytest.approx(0.3)
    assert robot.corners == ("LF", "RF", "LH", "RH") and robot.heading == (1.0, 0.0)
    thigh_plus_shank = 0.15 + 0.15
    assert robot.leg_length == pytest.approx(thigh_plus_shank)


def run_app(*args, cwd: Path) -> subprocess.CompletedProcess:
    return launched(args, cwd=cwd, timeout=600, env={**os.environ, "MUJOCO_GL": "egl"})


@pytest.mark.parametrize("bad, expected", [
    (dict(free=False), "has no free joint"),
    (dict(feet=3), "env=legged needs four feet"),
    (dict(site_actuator=True), "drives no joint"),
])
def test_a_bad_robot_is_one_error_line_and_exit_2_with_nothing_written(bad, expected, tmp_path):
    model = write_robot(tmp_path / "bad", **bad)
    before = sorted(p.name for p in tmp_path.rglob("*"))
    done = run_app("env=legged", f"env.xml_file={model}", f"hydra.run.dir={tmp_path / 'run'}", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and expected in lines[0], done.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


def test_an_unknown_keyframe_names_the_ones_the_model_has(tmp_path):
    from ppo_torchrl.robots.model import read_robot

    with pytest.raises(ConfigError, match=r"has no keyframe 'crouch' \(its keyframes: home\)"):
        read_robot(write_robot(tmp_path / "r"), "crouch")


def test_a_legged_run_is_named_by_its_model_and_says_what_was_read(tmp_path):
    """One training batch of the recipe on the tiny robot: the run dir and the start line carry the model's name
    (not scene.xml), the start line what was read; the env file derives the size-dependent values, and a
    user's value for one of them is refused in one line."""
    model = write_robot(tmp_path / "tiny_robot")
    done = run_app("experiment=legged_trot", f"env.xml_file={model}", "collector.total_frames=256",
                   "collector.frames_per_batch=256", "eval.every_frames=0", "eval.final_episodes=1", "logger=none",
                   cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    runs = list((tmp_path / "outputs" / "runs").glob("*/*"))
    assert len(runs) == 1 and runs[0].name.endswith("_legged_trot_tiny_seed1"), runs
    assert "start: legged:tiny" in done.stderr and "robot tiny: " in done.stderr
    assert "step 7.5 cm (0.25 l)" in done.stderr  # l = 0.3 m
    evaluate = [sys.executable, "-m", "ppo_torchrl.evaluate", f"run={runs[0]}", "checkpoint=last", "episodes=1"]
    plain = subprocess.run(evaluate, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert plain.returncode == 0, plain.stderr
    result = json.loads((runs[0] / "eval" / "eval.json").read_text())
    assert result["step_height_mean"] == pytest.approx(0.075)  # no argument: the step of 0.25 l
    assert 0.0 < result["peak_torque_share"] <= 1.0 + 1e-9 and 0.0 <= result["torque_at_limit_share"] <= 1.0
    assert all(0.0 < o["peak_torque_share"] <= 1.0 + 1e-9 for o in result["outcomes"])  # each episode's own
    sweep = subprocess.run(evaluate + ["heights=0,0.25l,0.3l"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert sweep.returncode == 0, sweep.stderr
    rows = list(csv.DictReader(open(runs[0] / "eval" / "height_sweep.csv")))
    assert [float(r["step_height_m"]) for r in rows] == pytest.approx([0.0, 0.075, 0.09])
    refused = run_app("env=legged", f"env.xml_file={model}", "env.locomotion.target_speed=1.0", cwd=tmp_path)
    assert refused.returncode == 2 and "env.legged.target_speed" in refused.stderr, refused.stderr
    # evaluate's env.<key>=<value> checks as training does: a step in m on a run whose curriculum range the
    # recipe derives (it was refused, 'curriculum=true needs step_height_range'); a bad target is one line
    from ppo_torchrl import evaluate
    from ppo_torchrl.errors import guarded

    fixed = evaluate.main([f"run={runs[0]}", "checkpoint=last", "episodes=1", "env.terrain.step_height=0.05",
                           f"out={tmp_path / 'at_5cm'}"])
    assert fixed["step_height_mean"] == pytest.approx(0.05)
    with pytest.raises(SystemExit) as exit_:
        guarded(evaluate.main, [f"run={runs[0]}", "env.legged.step_height=-1", f"out={tmp_path / 'bad'}"])
    assert exit_.value.code == 2 and not (tmp_path / "bad").exists()


def test_a_filmed_robot_whose_visual_meshes_were_left_out_is_drawn():
    """The Menagerie robots keep their collision geoms in group 3, which MuJoCo does not draw: a video of
    one showed an empty floor. A rendered env draws them (in its own copy: a training env keeps the model's
    groups), and the frame has the robot in it: grey pixels that are not there when its geoms stay hidden."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    cfg = compose(["env=legged", f"env.xml_file={scene('unitree_go1')}", "env.locomotion.reset_noise_scale=0"])
    plain = make_batch(cfg.env).models[0]
    robot_geoms = plain.body_rootid[plain.geom_bodyid] == plain.body("trunk").id
    assert (plain.geom_group[robot_geoms] == 3).all()  # as written: nothing of the robot drawn
    filmed = make_batch(cfg.env, 1, render_mode="rgb_array", width=96, height=72)
    model = filmed.models[0]
    assert (model.geom_group[robot_geoms] == 0).all() and model.ngeom == plain.ngeom
    assert (model.geom_contype == plain.geom_contype).all() and (model.geom_size == plain.geom_size).all()
    filmed.reset(seed=0)
    frame = filmed.render().astype(int)
    grey = (np.abs(frame - frame.mean(axis=2, keepdims=True)).max(axis=2) < 12) & (frame.mean(axis=2) > 90)
    model.geom_group[robot_geoms] = 3  # hidden again: the same frame without the robot
    hidden = filmed.render().astype(int)
    grey_hidden = (np.abs(hidden - hidden.mean(axis=2, keepdims=True)).max(axis=2) < 12) & (hidden.mean(axis=2) > 90)
    assert grey.sum() > 100 and grey_hidden.sum() < grey.sum() / 10, (grey.sum(), grey_hidden.sum())


def test_a_step_of_height_zero_is_not_drawn():
    """Flat ground is the step at height 0, its top in the floor's plane: filmed, the two flickered as dark
    patches. Such a step is transparent (MuJoCo does not draw it) and the same box, raised, is drawn again;
    the frame at height 0 is the frame of a model whose step is far away."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    cfg = compose(["experiment=legged_trot", f"env.xml_file={scene('unitree_go2')}", "env.terrain.step_height=0",
                   "env.locomotion.reset_noise_scale=0"])
    env = make_batch(cfg.env, 1, render_mode="rgb_array", width=96, height=72)
    env.reset(seed=0)
    model, terrain = env.models[0], env.task.terrain
    step = model.geom("step").id
    assert model.geom_rgba[step, 3] == 0.0

    def frame(height, distance):
        terrain.place(0, height, distance, model)
        mujoco.mj_forward(model, env.datas[0])
        env.render()  # (the first frame after a change can differ from the next ones)
        return env.render().astype(int)

    flat = frame(0.0, terrain.model_step[1])
    assert np.abs(frame(0.0, 1000.0) - flat).max() <= 8  # the same step, out of the camera's view
    assert np.abs(frame(0.1, terrain.model_step[1]) - flat).max() > 8 and model.geom_rgba[step, 3] == 1.0


def test_unnamed_feet_go_by_their_corner_in_evals():
    """ANYmal B's and A1's foot spheres have no name: the gait line and the sweep's columns call them by their
    corner (they said 'foot 0'..'foot 3'); named feet keep their names."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    for folder, names in (("anybotics_anymal_b", None), ("unitree_a1", None), ("unitree_go1", ["FL", "FR", "RL", "RR"])):
        world = make_batch(compose(["env=legged", f"env.xml_file={scene(folder)}"]).env).world
        assert list(world.foot_names) == (names or list(world.corners)), folder
        assert sorted(world.corners) == ["LF", "LH", "RF", "RH"]
