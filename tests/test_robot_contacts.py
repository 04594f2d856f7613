"""Issue 59, item 4: env=legged steps only the contacts locomotion needs (env.legged.contacts=terrain, the default:
the robot's geoms touch the floor and the step only; robots/model.py, filter_contacts) and its physics step is
chosen by robots/recipe.py's rule (env.legged.physics_dt). Fast: a few Go1 envs, no training."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from conftest import run_app

ROBOTS_DIR = Path(__file__).resolve().parents[1] / "ppo_torchrl" / "assets" / "menagerie"
GO1 = ROBOTS_DIR / "unitree_go1" / "scene.xml"


def go1(*overrides):
    """A one-row batch of recipe v2's Go1, its curriculum off."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    cfg = compose(["experiment=legged_trot_v2", f"env.xml_file={GO1}", "env.terrain.curriculum=false", *overrides])
    return make_batch(cfg.env, 1, threads=1)


def step(batch, action) -> tuple:
    obs, reward, terminated, truncated, _ = batch.step(np.asarray(action)[None])
    return obs[0], float(reward[0]), bool(terminated[0]), bool(truncated[0])


def contacts_now(batch):
    """Row 0's contact readings afresh from its simulator (sensors.Contacts)."""
    fresh = type(batch.task.contacts)(1, batch.world)
    fresh.read(0, batch.datas[0])
    return fresh


def robot_robot(model, data) -> list:
    """The contacts between two geoms of bodies that are not welded to the world, as body-name pairs."""
    return [(model.body(model.geom_bodyid[a]).name, model.body(model.geom_bodyid[b]).name)
            for a, b in data.contact.geom[: data.ncon]
            if model.body_weldid[model.geom_bodyid[a]] and model.body_weldid[model.geom_bodyid[b]]]


def crossed_legs(model, data, seed=0, tries=500) -> np.ndarray:
    """A pose (trunk lifted, joints drawn within their ranges) where the model's own contacts put two Go1 legs
    against each other: Go1's joint ranges keep its thighs off its trunk, but not its legs off each other."""
    rng = np.random.default_rng(seed)
    for _ in range(tries):
        qpos = model.key("home").qpos.copy()
        qpos[2] = 0.6
        for joint in range(1, model.njnt):
            qpos[model.jnt_qposadr[joint]] = rng.uniform(*model.jnt_range[joint])
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
        if robot_robot(model, data):
            return qpos
    raise AssertionError("no self-colliding pose found")


def test_with_the_filter_the_robot_touches_the_terrain_and_never_itself():
    """Legs that the model's contacts let collide (the pose found with contacts=model) pass through each other
    with contacts=terrain; random steps make no robot-robot contact (and no trunk-thigh one) while the feet stand
    on the floor, and a trunk on the floor still counts as a body contact and ends the episode."""
    env = go1()
    plain = go1("env.legged.contacts=model")
    assert plain.world.contact_filter is None and env.world.contact_filter == (42, 0)  # every Go1 geom can touch the floor
    qpos = crossed_legs(plain.models[0], plain.datas[0])
    model, data = env.models[0], env.datas[0]
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    assert robot_robot(model, data) == []

    env.reset(seed=0)
    rng = np.random.default_rng(0)
    trunk = model.body("trunk").id
    thighs = {model.body(f"{leg}_thigh").id for leg in ("FL", "FR", "RL", "RR")}
    feet_down = 0
    for _ in range(200):
        _, _, terminated, truncated = step(env, np.clip(0.4 * rng.normal(size=12), -1, 1))
        assert robot_robot(model, data) == []
        bodies = {frozenset(model.geom_bodyid[g] for g in pair) for pair in data.contact.geom[: data.ncon]}
        assert not any(trunk in pair and pair & thighs for pair in bodies)
        feet_down += int(contacts_now(env).feet[0].sum())
        if terminated or truncated:
            env.reset_row(0)
    assert feet_down > 200  # the feet meet the floor (about 2 of 4 down on average)

    env.reset(seed=0)
    data.qpos[2], data.qpos[3:7] = 0.04, [0.0, 1.0, 0.0, 0.0]  # upside down, the trunk on the floor
    mujoco.mj_forward(model, data)
    assert contacts_now(env).body[0] > 0
    terminated = step(env, np.zeros(12))[2]
    assert terminated and env.task.termination(0) == "contact: trunk"


def test_the_filter_keeps_the_model_s_pairs_and_its_visual_geoms():
    """A robot-robot <pair> the model names still makes its contact; a visual geom (contype = conaffinity = 0) stays
    out of every contact; robot geoms still land on the floor."""
    from ppo_torchrl.robots.model import TERRAIN_BIT, filter_contacts

    spec = mujoco.MjSpec.from_string("""<mujoco><worldbody><geom name="floor" type="plane" size="5 5 .1"/>
      <body name="trunk" pos="0 0 0.05"><freejoint/><geom name="trunk" type="box" size=".2 .1 .05"/>
        <geom name="shell" type="sphere" size=".3" contype="0" conaffinity="0" group="2"/>
        <body name="hip" pos=".25 0 0"><joint type="hinge"/><geom name="hip" type="sphere" size=".06"/>
          <body name="knee" pos="-.1 0 0"><joint type="hinge"/><geom name="knee" type="sphere" size=".06"/>
            <body name="toe" pos="-.1 0 0"><joint type="hinge"/><geom name="toe" type="sphere" size=".06"/>
      </body></body></body></body></worldbody>
      <contact><pair geom1="trunk" geom2="toe"/></contact></mujoco>""")
    assert filter_contacts(spec) == (4, 0)
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pairs = {frozenset(model.geom(g).name for g in pair) for pair in data.contact.geom[: data.ncon]}
    assert frozenset({"trunk", "toe"}) in pairs  # the model's pair (the toe sits inside the trunk's box)
    assert frozenset({"trunk", "knee"}) not in pairs  # overlapping too, but no pair asks for it
    assert frozenset({"floor", "trunk"}) in pairs
    assert not any("shell" in pair for pair in pairs)
    assert model.geom("shell").contype == model.geom("shell").conaffinity == 0
    assert model.geom("trunk").contype == TERRAIN_BIT and model.geom("trunk").conaffinity == 0


def test_the_filter_changes_nothing_where_the_robot_never_touches_itself():
    """Flat ground, the same random actions: contacts=terrain steps the same floats as contacts=model (Go1 makes
    no self-contact there), foot contacts included; the standing pose holds the same."""
    runs = []
    for mode in ("model", "terrain"):
        env = go1(f"env.legged.contacts={mode}")
        env.reset(seed=3)
        rng = np.random.default_rng(3)
        trace = []
        for _ in range(50):
            observation, reward, terminated, truncated = step(env, np.clip(0.4 * rng.normal(size=12), -1, 1))
            trace.append(np.concatenate([observation, [reward], contacts_now(env).feet[0]]))
            if terminated or truncated:
                break
        runs.append(np.array(trace))
    assert np.array_equal(runs[0], runs[1])


def test_the_physics_step_is_the_rule_s_and_a_given_one_wins():
    """physics_dt null: the rule's step (robots/recipe.py), a whole number of which makes the 20 ms control step;
    a given physics_dt is set in the model and frame_skip follows it."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import physics_dt

    env = go1()
    legged = compose(["experiment=legged_trot_v2", f"env.xml_file={GO1}"]).env.legged
    assert env.models[0].opt.timestep == pytest.approx(physics_dt(read_robot(GO1), legged))
    assert env.models[0].opt.timestep * env.world.frame_skip == pytest.approx(0.02)
    given = go1("env.legged.physics_dt=0.004")
    assert given.models[0].opt.timestep == pytest.approx(0.004) and given.world.frame_skip == 5
    assert given.dt == pytest.approx(0.02)


def test_the_friction_cone_is_the_model_s_unless_one_is_given():
    """friction_cone model keeps Menagerie's elliptic cone; pyramidal and elliptic are set in every row's model (and
    named in the deploy manifest); another name is one failed check."""
    import mujoco

    from ppo_torchrl.compose import compose
    from ppo_torchrl.robots.recipe import legged_checks
    from ppo_torchrl.tasks.locomotion.deploy import manifest

    assert go1().models[0].opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    pyramidal = go1("env.legged.friction_cone=pyramidal")
    assert {int(m.opt.cone) for m in pyramidal.models} == {int(mujoco.mjtCone.mjCONE_PYRAMIDAL)}
    for cone in ("pyramidal", "model"):
        cfg = compose(["experiment=legged_trot_v2", f"env.xml_file={GO1}", f"env.legged.friction_cone={cone}"])
        assert manifest(cfg)["trained_friction_cone"] == ("pyramidal" if cone == "pyramidal" else "elliptic")
    legged = compose(["env=legged", f"env.xml_file={GO1}", "env.legged.friction_cone=soft"]).env.legged
    assert [message for ok, message in legged_checks(legged) if not ok] == [
        "env.legged.friction_cone=soft is not known; use model or pyramidal or elliptic"]


def test_bad_contacts_and_physics_steps_are_refused_by_the_legged_checks():
    """A step of 0, longer than the control step, or one that does not divide it (0.003 s: 6.67 steps of 20 ms) is
    one failed check; rule, model and a dividing step pass."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.robots.recipe import legged_checks

    def failed(value):
        legged = compose(["env=legged", f"env.xml_file={GO1}", f"env.legged.physics_dt={value}"]).env.legged
        return [message for ok, message in legged_checks(legged) if not ok]

    for bad in ("0", "0.5", "0.003"):
        assert failed(bad) == [f"env.legged.physics_dt={bad} must be rule, model or a step in seconds that divides "
                               "env.legged.control_dt=0.02 into whole steps"]
    for good in ("rule", "model", "0.004"):
        assert failed(good) == []


def test_the_rule_keeps_each_bound_and_a_saved_run_keeps_its_model_s_step():
    """rule_dt: Spot keeps its 2 ms (its feet's contacts have a 4 ms time constant: a longer step would soften them),
    Go1 gets 5 ms (its stiffest servo, sqrt(kp / I) ~ 80 rad/s, turns <= 0.5 rad a step); every robot's step divides
    the control step and meets each bound. A run saved before the key existed (no physics_dt) steps as it trained."""
    from omegaconf import OmegaConf

    from ppo_torchrl.compose import compose
    from ppo_torchrl.config import Config
    from ppo_torchrl.envs.make import make_batch
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import DAMPING_STEP, SERVO_PHASE, rule_dt

    for scene in sorted(ROBOTS_DIR.glob("*/scene.xml")):
        robot = read_robot(scene)
        dt = rule_dt(robot, 0.02)
        assert 0.02 / dt == pytest.approx(round(0.02 / dt)), scene
        assert dt <= robot.time_constant / 2 + 1e-12 or dt == robot.timestep, scene
        assert dt * robot.servo_rate <= SERVO_PHASE or dt == robot.timestep, scene
        assert robot.implicit_damping or dt * robot.damping_rate <= DAMPING_STEP or dt == robot.timestep, scene
    assert rule_dt(read_robot(ROBOTS_DIR / "boston_dynamics_spot" / "scene.xml"), 0.02) == pytest.approx(0.002)
    assert rule_dt(read_robot(GO1), 0.02) == pytest.approx(0.005)

    cfg = compose(["experiment=legged_trot_v2", f"env.xml_file={GO1}"])
    saved = OmegaConf.create(OmegaConf.to_container(cfg))  # as a run dir's config.yaml is read back
    del saved.env.legged["physics_dt"]
    old = OmegaConf.merge(OmegaConf.structured(Config), saved)  # config.run_config's merge
    assert make_batch(old.env).models[0].opt.timestep == pytest.approx(read_robot(GO1).timestep)


@pytest.mark.parametrize("override, expected", [
    ("env.legged.contacts=sideways", "env.legged.contacts=sideways is not known; use terrain or model"),
    ("env.legged.physics_dt=fast", "env.legged.physics_dt=fast must be rule, model or a step in seconds"),
])
def test_a_bad_contacts_or_physics_step_is_one_error_line_and_exit_2(override, expected, tmp_path):
    done = run_app(["env=legged", f"env.xml_file={GO1}", override, f"hydra.run.dir={tmp_path / 'run'}"], cwd=tmp_path,
                   env=dict(os.environ))
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and expected in lines[0], done.stderr
    assert not (tmp_path / "run").exists()


def weighted(batch, name: str, **given) -> float:
    """Row 0's weighted term `name` on the batch's own constants and the state given (rewards.py: a pure function)."""
    from ppo_torchrl.tasks.locomotion.rewards import TERMS, Step

    from test_joystick import crafted

    step = crafted(params=batch.task.params, **given)
    assert isinstance(step, Step)
    return float(TERMS[name].fn(step)[0] * batch.task.weights[batch.task.names.index(name)])


def test_a_swing_held_past_its_limit_costs_in_proportion_to_the_feet_held():
    """Recipe v2's gait lever: env.legged.long_swing_cost_weight x the share of feet in the air for longer than
    long_swing_limit x sqrt(l / g) (0.42 s for Go1); a foot down, or up for less, costs nothing."""
    import math

    env = go1("env.legged.long_swing_cost_weight=0.8")
    env.reset(seed=0)
    step(env, np.zeros(12))
    limit = env.task.params["long_swing_limit"]
    assert limit == pytest.approx(2.0 * math.sqrt(0.4260 / 9.81), rel=1e-3)
    up = np.array([[False, False, True, True]] * 2)  # LF and RF up
    air = np.array([[limit, 0.1, 0.0, 0.0]] * 2)  # LF up for the limit already, RF briefly
    assert weighted(env, "long_swing", feet=up, air_time=air) == pytest.approx(-0.8 * 1 / 4)
    assert "long_swing" not in go1("env.legged.long_swing_cost_weight=0").task.names  # the lever off (v2: 0.5)


def test_a_foot_against_the_steps_riser_is_a_stumble_and_a_foot_on_its_top_is_not():
    """Recipe v3's candidate C3: env.legged.stumble_cost_weight x the share of feet touching the ground or the step on a
    face more than 45 degrees from level. A Go1 pushed 5 mm into the step's riser pays for the fore feet that touch it;
    standing on the floor, or with a fore foot on the step's top, it pays nothing; the lever off, no such term."""
    from ppo_torchrl.tasks.locomotion.sensors import Contacts
    from ppo_torchrl.tasks.locomotion.world import FOOT

    env = go1("env.legged.stumble_cost_weight=2.0")
    env.reset(seed=0)
    w, model, data, terrain = env.world, env.models[0], env.datas[0], env.task.terrain
    fresh = Contacts(1, w, faces=True)
    terrain.place(0, 0.1, 1.0, model)
    for _ in range(10):  # settle onto the floor
        step(env, np.zeros(12))
    fresh.read(0, data)
    assert not fresh.on_face[0].any() and fresh.feet[0].sum() >= 2
    feet, radius = data.geom_xpos[w.feet], model.geom_size[w.feet, 0]
    data.qpos[0] += terrain.edge[0] - (feet[:, 0] + radius).max() + 0.005
    mujoco.mj_forward(model, data)
    fresh.read(0, data)
    stumbling = fresh.on_face[0].copy()
    assert stumbling.any() and {w.corners[i] for i in np.flatnonzero(stumbling)} <= {"LF", "RF"}
    assert weighted(env, "stumble", on_face=np.stack([stumbling] * 2)) == pytest.approx(
        -2.0 * np.count_nonzero(stumbling) / 4)

    env.reset(seed=0)
    mujoco.mj_forward(model, data)
    feet = data.geom_xpos[w.feet]
    fore = [i for i, corner in enumerate(w.corners) if corner.endswith("F")]
    terrain.place(0, (feet[fore, 2] - radius[fore]).min() + 0.004,
                  feet[fore, 0].min() - terrain._start_along - 0.05, model)
    mujoco.mj_forward(model, data)
    partners, _ = fresh.partners(data)
    on_top = [g for g in partners[w.kind[partners] == FOOT] if data.geom_xpos[g, 0] > terrain.edge[0]]
    fresh.read(0, data)
    assert on_top and not fresh.on_face[0].any()
    assert "stumble" not in go1().task.names  # recipe v2: the lever off


def test_the_eval_step_a_video_films_is_the_sweeps_step_to_the_micrometre():
    """Issue 59 item 7: evaluate's default step (what video=true films) and heights=0.25l's step are one number."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.tasks.locomotion.sweep import heights_in_metres, parse_heights
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import scaled_env

    for folder in ("unitree_go2", "anybotics_anymal_b"):
        cfg = compose(["experiment=legged_trot", f"env.xml_file={ROBOTS_DIR / folder / 'scene.xml'}"])
        robot = read_robot(cfg.env.xml_file)
        default = scaled_env(cfg.env, robot).terrain.eval_step_height
        swept = heights_in_metres(parse_heights("0.25l"), cfg.env)[0]
        assert default == swept and default != 0.25 * robot.leg_length  # the unrounded product differs
