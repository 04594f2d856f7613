"""The joystick (issue 73) on the batched legged env: velocity commands drawn and drawn again from the row's own RNG,
the command as an observation segment, each new reward term on a crafted state, randomized worlds recorded and
replayed, and the tracking figures on a robot that stands still (whose error is the command itself)."""

import numpy as np
import pytest

from ppo_torchrl.envs.make import gym_make_kwargs
from ppo_torchrl.tasks.locomotion.batch import LeggedBatchEnv
from ppo_torchrl.tasks.locomotion.rewards import TERMS, Step

from conftest import compose_config

GO1 = "menagerie/unitree_go1/scene.xml"


def joystick(*overrides):
    return compose_config(["experiment=legged_joystick", f"env.xml_file={GO1}", *overrides])


def test_commands_are_drawn_in_the_robots_units_and_drawn_again_within_an_episode():
    cfg = joystick("env.legged.command.resample=[2.0,2.0]", "env.legged.command.stand_share=0.0")
    batch = LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=4, threads=1)
    batch.reset(seed=3)
    robot, command = batch.world.robot, batch.task.command
    first = command.value.copy()
    limits = np.array([0.5 * robot.speed_scale, 0.25 * robot.speed_scale, 0.25 / robot.time_scale])
    assert (np.abs(first) <= limits).all() and len({tuple(r) for r in first}) == 4  # each row its own draw
    # the command is the observation's segment before the clock, in the robot's units
    layout = batch.observation_layout()
    segment = layout.where("command")
    np.testing.assert_allclose(batch.last_obs[:, segment], first / [robot.speed_scale, robot.speed_scale,
                                                                    1 / robot.time_scale])
    steps = round(2.0 * robot.time_scale / batch.world.dt)
    for _ in range(steps - 1):
        batch.step(np.zeros((4, 12), np.float32))
    assert np.array_equal(command.value, first)  # held until its time is up
    batch.step(np.zeros((4, 12), np.float32))
    assert not np.any(np.all(command.value == first, axis=1))  # then every row draws again
    again = LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=4, threads=1)
    again.reset(seed=3)
    assert np.array_equal(again.task.command.value, first)  # from the row's seed
    standing = LeggedBatchEnv(gym_make_kwargs(joystick("env.legged.command.stand_share=1.0").env), num_envs=3)
    standing.reset(seed=1)
    assert not standing.task.command.value.any()


def crafted(**given):
    n = 2
    base = dict(action=np.zeros((n, 12)), prev_action=np.zeros((n, 12)), speed=np.zeros(n), healthy=np.ones(n, bool),
                cfrc_ext=None, actuator_force=np.zeros((n, 12)), joint_speed=np.zeros((n, 12)), step_peak=None,
                height=np.zeros(n), up=np.ones(n), feet=None, feet_xy=None, prev_feet_xy=None, air_time=None,
                body_contacts=None, on_face=None, meant_down=None, command=np.zeros((n, 3)),
                velocity=np.zeros((n, 2)), yaw_rate=np.zeros(n), vz=np.zeros(n), tilt_rate=np.zeros((n, 2)),
                joint_angle=np.zeros((n, 12)),
                params={"sigma_lin": 0.25, "sigma_yaw": 0.25, "speed": 2.0, "time": 0.2, "home_angle": np.zeros(12)})
    base.update(given)
    return Step(**base)


def test_each_joystick_term_on_a_crafted_state():
    on_target = crafted(command=np.array([[1.0, 0.5, 0.3], [1.0, 0.5, 0.3]]),
                        velocity=np.array([[1.0, 0.5], [0.5, 0.5]]), yaw_rate=np.array([0.3, 0.8]))
    lin = TERMS["tracking_lin_vel"].fn(on_target)
    assert lin[0] == 1.0 and lin[1] == pytest.approx(np.exp(-0.25 / 0.25))
    yaw = TERMS["tracking_ang_vel"].fn(on_target)
    assert yaw[0] == 1.0 and yaw[1] == pytest.approx(np.exp(-0.25 / 0.25))
    assert TERMS["lin_vel_z"].fn(crafted(vz=np.array([0.0, 1.0])))[1] == pytest.approx(-(1.0 / 2.0) ** 2)
    assert TERMS["ang_vel_xy"].fn(crafted(tilt_rate=np.array([[0, 0], [3.0, 4.0]])))[1] == pytest.approx(-25 * 0.04)
    still = crafted(command=np.array([[0.0, 0, 0], [0.2, 0, 0]]), joint_angle=np.full((2, 12), 0.1))
    assert TERMS["stand_still"].fn(still).tolist() == pytest.approx([-1.2, 0.0])  # only while told to stand
    assert all(TERMS[name].weight_key is None for name in ("tracking_lin_vel", "tracking_ang_vel", "stand_still"))


def test_an_unknown_reward_name_is_one_line():
    from ppo_torchrl.errors import ConfigError

    with pytest.raises(ConfigError, match="env.legged.rewards.tracking_speed: no such reward term"):
        LeggedBatchEnv(gym_make_kwargs(joystick("+env.legged.rewards.tracking_speed=1.0").env))


def test_randomized_worlds_are_drawn_per_row_recorded_and_replayed():
    cfg = joystick()
    batch = LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=3, threads=1)
    batch.reset(seed=11)
    rand, models = batch.task.randomize, batch.models
    draws = [dict(d) for d in rand.draws]
    import mujoco  # the recipe's pyramidal cone is on every row's randomized model, not only on the base one

    assert {int(m.opt.cone) for m in models} == {int(mujoco.mjtCone.mjCONE_PYRAMIDAL)}
    assert len({d["friction"] for d in draws}) == 3 and all(0.4 <= d["friction"] <= 1.25 for d in draws)
    trunk = batch.world.trunk
    base = batch.world.model
    for model, d in zip(models, draws):  # each row's own model carries its draw
        assert model.body_mass[trunk] == pytest.approx(base.body_mass[trunk] * d["trunk_mass"])
        assert model.geom_friction[0, 0] == pytest.approx(base.geom_friction[0, 0] * d["friction"])
    # a position saved and restored brings the world back with the episode
    position = batch.row_position(1)
    batch.reset_row(1)
    assert rand.draws[1] != draws[1]
    batch.restore_row(1, position)
    assert rand.draws[1] == draws[1] and models[1].body_mass[trunk] == pytest.approx(base.body_mass[trunk] *
                                                                                     draws[1]["trunk_mass"])
    # an evaluation env is the nominal world unless a draw is fixed, which it replays
    evaluation = LeggedBatchEnv(gym_make_kwargs(cfg.env, evaluation=True) | {}, num_envs=1, evaluation=True)
    evaluation.reset(seed=11)
    assert evaluation.models[0].body_mass[trunk] == base.body_mass[trunk]
    evaluation.task.randomize.fix(0, draws[2])
    evaluation.reset_row(0, 5)
    assert evaluation.task.randomize.draws[0] == draws[2]
    assert evaluation.models[0].body_mass[trunk] == pytest.approx(base.body_mass[trunk] * draws[2]["trunk_mass"])


def test_the_tracking_error_of_a_robot_that_stands_is_its_command():
    """Zero actions hold the standing pose: the measured velocity is ~0, so each command's error is its size."""
    import torch

    from ppo_torchrl.envs.make import env_spec, make_batch
    from ppo_torchrl.rl.models import make_actor_critic
    from ppo_torchrl.tasks.locomotion import tracking

    cfg = joystick("policy.log_std_init=-5")
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    with torch.no_grad():
        for p in ac.actor.parameters():
            p.zero_()  # the mean action 0: each joint's target its standing angle
    commands = (("stand", 0.0, 0.0, 0.0), ("forward", 0.3, 0.0, 0.0), ("turn left", 0.0, 0.0, 0.25))
    result = tracking.track(make_batch, cfg, ac, None, episodes=1, seed=0, commands=commands, settle_time=5.0,
                            measure_time=5.0)
    rows = {r["command"]: r for r in result["commands"]}
    assert rows["stand"]["v_xy_error"] < 0.01 and rows["stand"]["joint_motion_rms"] < 0.01
    assert rows["forward"]["v_xy_error"] == pytest.approx(0.3, abs=0.01)
    assert rows["turn left"]["yaw_rate_error"] == pytest.approx(0.25, abs=0.01)
    assert rows["forward"]["falls"] == 0.0 and result["overall"]["episodes"] == 3


def _stepped_without_noise(cfg):
    """One Go1 row of the batched env, without its training noise, seven random steps on: (env, command, clock)."""
    batch = LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=1, threads=1)
    batch.task.randomize.obs_noise = 0.0
    batch.task.randomize.noise_scale[:] = 0.0
    batch.reset(seed=4)
    for _ in range(7):
        batch.step(np.random.default_rng(0).uniform(-0.3, 0.3, (1, 12)).astype(np.float32))
    return batch, batch.task.command.observe()[0], batch.task.memory.clock_steps[0] * batch.world.dt


def test_policy_json_is_the_observation_the_env_gives_and_the_deploy_script_drives_the_export(tmp_path):
    """The layout export writes down is the env's own observation, element for element (from the same state), and
    the standalone script (torch and mujoco only) drives policy.pt and policy.onnx alike in plain MuJoCo."""
    import json
    import subprocess
    import sys

    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.export import export_deploy, export_policy
    from ppo_torchrl.rl.models import make_actor_critic
    from ppo_torchrl.tasks.locomotion import deploy_mujoco

    cfg = joystick()
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    export_policy(cfg, ac, None, tmp_path / "policy.pt")
    written = export_deploy(cfg, ac, None, tmp_path / "policy.pt", None)
    assert [p.name for p in written] == ["policy.onnx", "policy.json", "deploy_mujoco.py"]
    manifest = json.loads((tmp_path / "policy.json").read_text())
    assert sum(p["size"] for p in manifest["observation"]) == manifest["obs_dim"]
    batch, command, t = _stepped_without_noise(cfg)
    mine = deploy_mujoco.observation(batch.models[0], batch.datas[0], manifest, command, t)
    np.testing.assert_allclose(mine, batch.last_obs[0], rtol=0, atol=1e-12)
    outputs = []
    for policy in ("policy.pt", "policy.onnx"):
        result = subprocess.run([sys.executable, "deploy_mujoco.py", "policy.json", "--policy", policy, "--commands",
                                 "forward:0.3,0,0:0.2;stop:0,0,0:0.1", "--noise", "1"], cwd=tmp_path,
                                capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr[-1500:]
        lines = [json.loads(line) for line in result.stdout.splitlines()]
        assert [line["segment"] for line in lines] == ["forward", "stop"] and not any(line["fell"] for line in lines)
        outputs.append(lines)
    assert outputs[0] == outputs[1]  # TorchScript and ONNX act alike


def test_a_drive_script_is_parsed_or_refused_in_one_line():
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.tasks.locomotion.drive import DEFAULT, parse

    segments = parse(DEFAULT)
    assert [s[0] for s in segments] == ["forward", "turn", "left", "stop"] and segments[1][1] == [0.0, 0.0, 0.25]
    for bad in ("forward:0.3,0:4", "forward:0.3,0,0:-1", "forward:0.3,0,0", "x:nan,0,0:1"):
        with pytest.raises(ConfigError, match="expected name:vx,vy,yaw:seconds"):
            parse(bad)


def test_a_drive_segment_shorter_than_a_control_step_is_one_line(tmp_path):
    """A segment of 0.001 s rounds to no control step: its measured velocity was the mean of nothing (NaN)."""
    from ppo_torchrl.envs.make import env_spec, make_batch
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.rl.models import make_actor_critic
    from ppo_torchrl.tasks.locomotion.drive import drive

    cfg = joystick()
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    with pytest.raises(ConfigError, match="shorter than a control step"):
        drive(make_batch, cfg, ac, None, [("go", [0.3, 0.0, 0.0], 1.0), ("blink", [0.0, 0.0, 0.0], 0.001)],
              tmp_path / "drive.mp4", 0, owner=None)
    assert not (tmp_path / "drive.mp4").exists()


def test_a_joystick_runs_start_line_names_its_commands_not_a_step_and_a_target_speed():
    """The start line of experiment=legged_joystick said "step 10.7 cm (0.25 l), speed up to 0.71 m/s": a climb
    recipe's task, which a joystick run has not. It now says the commands' ranges in SI and how often they change;
    the climb recipes' line is as before."""
    from ppo_torchrl.envs.make import resolve_model_file
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import describe

    robot = read_robot(resolve_model_file(GO1))
    line = describe(robot, joystick().env.legged)
    assert "step " not in line and "speed up to" not in line, line
    vx = 0.5 * robot.speed_scale
    assert f"commands vx {-vx:+.2f} to {vx:+.2f} m/s" in line and "standing, drawn again every" in line, line
    climb = describe(robot, compose_config(["experiment=legged_trot_v2", f"env.xml_file={GO1}"]).env.legged)
    assert "recipe: step 10.7 cm (0.25 l), speed up to" in climb, climb


def test_the_privileged_observation_is_the_noiseless_observation_then_what_the_simulator_knows():
    """policy.critic_obs=privileged on env=legged: the critic's input is the observation before the randomization's
    noise, the feet's contacts, their air times, the trunk's height and ground velocity, and the episode's world
    draw, in the robot's units; the layout covers it; the actor's observation stays the noisy one."""
    cfg = joystick("env.legged.randomize.push_speed=0.0")
    batch = LeggedBatchEnv(gym_make_kwargs(cfg.env), num_envs=3, threads=1, privileged=True)
    batch.reset(seed=11)
    task, robot = batch.task, batch.world.robot
    rng = np.random.default_rng(0)
    for _ in range(15):
        batch.step((0.3 * rng.standard_normal((3, 12))).clip(-1, 1).astype(np.float32))
    p = batch.privileged()
    assert p.shape == (3, task.privileged_dim) == (3, batch.privileged_layout().size)
    clean = task.observe(batch.reading)
    np.testing.assert_array_equal(p[:, :task.obs_dim], clean)
    assert np.abs(batch.last_obs - clean).max() > 0  # the actor sees the noisy one (obs_noise 1.0 in the recipe)
    feet = len(batch.world.feet)
    rest = p[:, task.obs_dim:]
    np.testing.assert_array_equal(rest[:, :feet], task.contacts.feet)
    np.testing.assert_allclose(rest[:, feet:2 * feet], task.memory.air_time / robot.time_scale)
    z = batch.reading.xpos[:, batch.world.trunk, 2]
    np.testing.assert_allclose(rest[:, 2 * feet], z / robot.leg_length, rtol=1e-9)  # flat ground at 0
    for i in range(3):
        d = task.randomize.draws[i]
        np.testing.assert_allclose(rest[i, -7:], [d["friction"], d["trunk_mass"], *np.array(d["com"]) / robot.leg_length,
                                                  d["strength"], float(d["delayed"])])
    assert len({tuple(r) for r in rest[:, -7:]}) == 3  # each row's own world
    segments = [(s.name, s.treatment) for s in batch.privileged_layout().segments]
    assert segments[-2:] == [("privileged_feet_down", "none"), ("privileged_state", "running")]
    assert np.array_equal(batch.privileged(slice(1, 2)), p[1:2])
    batch.close()


def test_the_asymmetric_critic_on_a_legged_run_reads_the_privileged_observation_and_torchrls_path_is_refused():
    import torch

    from ppo_torchrl.collectors import make_collector
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.envs.layout import PRIVILEGED
    from ppo_torchrl.rl.models import make_actor_critic

    tiny = ["collector.num_envs=2", "collector.frames_per_batch=64", "collector.physics_threads=1",
            "policy.critic_obs=privileged"]
    cfg = joystick(*tiny)
    spec = env_spec(cfg.env)
    ac = make_actor_critic(cfg.policy, spec)
    assert ac.critic.in_keys == [PRIVILEGED] and spec.privileged_dim > spec.obs_dim
    collector = make_collector(cfg, ac, 3, torch.device("cpu"))
    try:
        batch = collector.collect()
        assert batch[PRIVILEGED].shape == (2, 32, spec.privileged_dim)
        # the step's next privileged observation is the next step's, where no episode ended
        same = ~batch["next", "done"][:, :-1, 0]
        assert torch.equal(batch["next", PRIVILEGED][:, :-1][same], batch[PRIVILEGED][:, 1:][same])
    finally:
        collector.close()
    with pytest.raises(ConfigError, match="collector.backend=torchrl writes no privileged"):
        make_collector(joystick(*tiny, "collector.backend=torchrl"), ac, 3, torch.device("cpu"))


def test_the_tuning_table_keeps_a_lever_only_by_the_plans_rule(tmp_path):
    """benchmarks/joystick_table.py on crafted tracking sets: a lever that lowers every row's v_xy error beyond base's
    standard error is kept; one as good on v_xy but with a row falling more than base's worst is rejected; a row
    without its tracking set waits and decides nothing."""
    import json
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    import joystick_table

    def row(setting, name, v_xy, falls=0.0):
        d = tmp_path / setting / name
        (d / "eval").mkdir(parents=True)
        commands = [{"command": "stand", "v_xy_error": v_xy / 2, "joint_motion_rms": 0.02},
                    {"command": "forward", "v_xy_error": v_xy * 1.5, "joint_motion_rms": None}]
        overall = {"episodes": 10, "falls": falls, "v_xy_error": v_xy, "yaw_rate_error": 0.04}
        worlds = {"nominal": {"commands": commands, "overall": overall},
                  "extreme 1": {"commands": commands, "overall": {**overall, "falls": falls}}}
        (d / "eval" / "tracking.json").write_text(json.dumps({"worlds": worlds}))
        (d / "summary.json").write_text(json.dumps({"frames": 20_000_000}))

    for name, v in (("go1_seed6", 0.20), ("go1_seed7", 0.22), ("anymal_b_seed6", 0.18), ("anymal_b_seed7", 0.21)):
        row("base", name, v)
        row("better", name, v - 0.05)
        row("falls", name, v - 0.05, falls=0.2 if name == "go1_seed7" else 0.0)
    (tmp_path / "better" / "go1_seed8").mkdir()
    row("single", "go1_seed6", 0.15)  # one row has no sample std: said, not "+- nan"
    (tmp_path / "waits" / "go1_seed6").mkdir(parents=True)
    text = joystick_table.table([(label, tmp_path / label) for label in ("base", "better", "falls", "single", "waits")])
    verdicts = {line.split("**")[1]: line for line in text.splitlines() if line.startswith("- **")}
    assert "baseline" in verdicts["base"]
    assert "kept (v_xy -0.050" in verdicts["better"] and "on 4 rows" in verdicts["better"]
    assert "rejected" in verdicts["falls"] and "falls beyond base's worst" in verdicts["falls"]
    assert "| better | go1 seed 8 | waiting" in text
    assert "v_xy 0.150 (one row)" in verdicts["single"] and "nan" not in text and "no row yet" in verdicts["waits"]
    assert "| base | go1 seed 7 | 20,000,000 | 0.220 | 0.040 | 0% | 0% | forward 0.330 | 0.020 | - | - |" in text
    # a report (no base): each of issue 73's goals with the rows that meet it; the row's wall time and frames/s
    row("report", "go1_seed16", 0.04)
    row("report", "a1_seed16", 0.08, falls=0.3)
    (tmp_path / "report" / "a1_seed16" / "summary.json").write_text(json.dumps(
        {"frames": 20_000_000, "wall_s": 9750.0, "sps": 2066.7}))
    report = joystick_table.table([("report", tmp_path / "report")])
    assert "| report | a1 seed 16 | 20,000,000 | 0.080 | 0.040 | 30% | 30% | forward 0.120 | 0.020 | 2:42 | 2,067 |" \
        in report
    assert ("goals: v_xy <= 0.05 in 1 of 2 rows; missed by a1 seed 16, yaw <= 0.05 in 2 of 2 rows, falls <= 1% in 1 "
            "of 2 rows; missed by a1 seed 16") in report


def test_the_rounds_curves_read_every_row_with_metrics_and_smooth_over_frames(tmp_path):
    """benchmarks/joystick_curves.py: every <robot>_seed<s> dir with a metrics record (plain or .xz) is a curve, one
    without is left out, and so is one still training (unless running=True); a value is the mean over the last
    WINDOW frames, so logs thinned to different strides agree."""
    import lzma
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    import joystick_curves

    header = "frames,train/return_last100,reward/tracking_lin_vel,reward/tracking_ang_vel\n"
    def log(stride):
        return header + "".join(f"{f},{f / 1e5},{2 * f / 1e5},\n" for f in range(stride, 2_000_001, stride))
    (tmp_path / "go1_seed16").mkdir()
    (tmp_path / "go1_seed16" / "metrics.csv").write_text(log(100_000))
    (tmp_path / "a1_seed16").mkdir()
    (tmp_path / "a1_seed16" / "metrics.csv.xz").write_bytes(lzma.compress(log(250_000).encode()))
    (tmp_path / "spot_seed16").mkdir()  # still waiting: no metrics
    (tmp_path / "go2_seed16").mkdir()  # still training: left out unless running=True
    (tmp_path / "go2_seed16" / "metrics.csv").write_text(log(100_000))
    (tmp_path / "go2_seed16" / "summary.json").write_text('{"status": "running"}')
    (tmp_path / "a1_seed16" / "summary.json").write_text('{"status": "finished"}')
    found = joystick_curves.curves(tmp_path)
    assert sorted(found) == [("a1", 16), ("go1", 16)]
    assert sorted(joystick_curves.curves(tmp_path, running=True)) == [("a1", 16), ("go1", 16), ("go2", 16)]
    fine, coarse = found[("go1", 16)], found[("a1", 16)]
    y = joystick_curves.smooth(fine["frames"], fine["train/return_last100"])
    assert y[-1] == pytest.approx(np.mean([16, 17, 18, 19, 20]))  # 1.6M (exclusive) .. 2.0M
    assert np.isnan(joystick_curves.smooth(fine["frames"], fine["reward/tracking_ang_vel"])).all()  # an empty column
    z = joystick_curves.smooth(coarse["frames"], coarse["train/return_last100"])
    assert z[-1] == pytest.approx(np.mean([17.5, 20]))  # 1.75M, 2.0M: the same window, fewer points
    out = joystick_curves.plot(tmp_path, tmp_path / "curves.png")
    from PIL import Image

    assert Image.open(out).mode == "P"


def _qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def test_the_heading_frame_takes_the_trunks_yaw_out_of_its_attitude_and_velocity_whichever_way_it_faces():
    """env.legged.obs_frame=heading: one tilted, moving trunk turned to five headings reads the same observation
    (its roll-and-pitch quaternion, its velocity in its heading frame); the world frame's reading changes with it."""
    from ppo_torchrl.tasks.locomotion.task import heading_frame

    rng = np.random.default_rng(0)
    # pitch then roll: the trunk's x axis stays in the world's xz plane (no yaw of its own)
    tilt = _qmul([np.cos(0.12), 0, np.sin(0.12), 0], [np.cos(-0.09), np.sin(-0.09), 0, 0])
    v_heading = np.array([0.7, -0.2, 0.05])
    rows_q, rows_v = [], []
    for yaw in (0.0, 0.5, 2.0, -2.9, 3.1):
        q = _qmul([np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)], tilt) * (-1 if yaw == 2.0 else 1)  # either sign
        c, s = np.cos(yaw), np.sin(yaw)
        v = np.array([c * v_heading[0] - s * v_heading[1], s * v_heading[0] + c * v_heading[1], v_heading[2]])
        rows_q.append(np.concatenate([[0.3], q, rng.normal(size=12)]))
        rows_v.append(np.concatenate([v, rng.normal(size=15)]))
    qpos, qvel = np.array(rows_q), np.array(rows_v)
    hq, hv = heading_frame(qpos, qvel)
    yaw0 = np.arctan2(2 * (tilt[0] * tilt[3] + tilt[1] * tilt[2]), 1 - 2 * (tilt[2] ** 2 + tilt[3] ** 2))
    assert abs(yaw0) < 1e-12  # the tilt has no yaw: it is what every row should read
    np.testing.assert_allclose(hq[:, 1:5], np.tile(tilt, (5, 1)), atol=1e-12)
    np.testing.assert_allclose(hv[:, :3], np.tile(v_heading, (5, 1)), atol=1e-12)
    np.testing.assert_array_equal(hq[:, [0, *range(5, 17)]], qpos[:, [0, *range(5, 17)]])  # the rest as it is
    np.testing.assert_array_equal(hv[:, 3:], qvel[:, 3:])
    assert not np.allclose(qvel[1:, :2], v_heading[:2])  # the world frame's velocity turned with the trunk


def test_policy_json_and_the_deploy_script_read_the_heading_frame_as_the_env_does():
    """With obs_frame=heading policy.json names the tilt quaternion and the heading-frame velocity, and the standalone
    script's observation equals the env's, element for element, after the trunk has turned."""
    import mujoco

    from ppo_torchrl.tasks.locomotion import deploy_mujoco
    from ppo_torchrl.tasks.locomotion.deploy import manifest as make_manifest

    cfg = joystick("env.legged.obs_frame=heading")
    manifest = make_manifest(cfg)
    names = [p["name"] for p in manifest["observation"]]
    assert "trunk_tilt_quat_wxyz" in names and "trunk_linvel_heading" in names and "trunk_quat_wxyz" not in names
    batch, command, t = _stepped_without_noise(cfg)
    data = batch.datas[0]
    mine = deploy_mujoco.observation(batch.models[0], data, manifest, command, t)
    np.testing.assert_allclose(mine, batch.last_obs[0], rtol=0, atol=1e-12)
    # turned by 1.3 rad about the world's z, the same state reads the same observation
    turned = mujoco.MjData(batch.models[0])
    turned.qpos[:], turned.qvel[:] = data.qpos, data.qvel
    q = _qmul([np.cos(0.65), 0, 0, np.sin(0.65)], data.qpos[3:7])
    turned.qpos[3:7] = q
    c, s = np.cos(1.3), np.sin(1.3)
    turned.qvel[0], turned.qvel[1] = c * data.qvel[0] - s * data.qvel[1], s * data.qvel[0] + c * data.qvel[1]
    mujoco.mj_forward(batch.models[0], turned)
    again = deploy_mujoco.observation(batch.models[0], turned, manifest, command, t)
    skip = [p["name"] for p in manifest["observation"]].index("foot_contacts") if "foot_contacts" in names else None
    size = sum(p["size"] for p in manifest["observation"][:skip]) if skip is not None else len(mine)
    np.testing.assert_allclose(again[:size], mine[:size], atol=1e-9)
