"""What a robot must feed an exported legged policy and do with its action (issue 73 item 5): `manifest(cfg)` writes
it down, the exact observation layout and action mapping, as `policy.json` beside `policy.pt` (export.py); the
standalone `deploy_mujoco.py` beside them drives the policy in plain MuJoCo from that file alone (torch or onnxruntime,
and mujoco: no ppo_torchrl), which is the deploy check.

The observation, in order (sizes for a 12-joint quadruped): the trunk's height (1, m above the world's z = 0), its
attitude quaternion (4, w x y z, world frame), the joint angles (nq - 7, the model's qpos order), the trunk's linear
velocity (3, world frame, m/s) and angular velocity (3, the trunk's own frame, rad/s: a free joint's qvel), the joint
speeds (nv - 6) (a run with env.legged.obs_frame=heading has, in the same places, the quaternion with the trunk's
yaw taken out, `trunk_tilt_quat_wxyz`, and the linear velocity in the trunk's heading frame, `trunk_linvel_heading`),
then, where the run had them, a 0/1 ground contact per foot, terrain heights ahead (flat ground: 0 -
the trunk's height), the command (vx, vy in the trunk's heading frame over sqrt(g l), the yaw rate over sqrt(g / l)),
and the trot clock (sin, cos of 2 pi x the phase, the phase = time since the episode began / period, mod 1). The
normalization is inside policy.pt. The action, in [-1, 1] per actuator: each joint's target angle = its standing
angle + scale x action, within its range, held by a PD servo with the run's kp, kd and torque limit (for a model whose
actuators are already position servos with these gains, the target is their control), at the control step.
"""

from __future__ import annotations

import math

SCHEMA = 1


def manifest(cfg) -> dict:
    """policy.json's content for a legged run's config (the robot read from its model as the run trained)."""
    from ppo_torchrl.envs.make import make_batch

    batch = make_batch(cfg.env, 1, evaluation=True)
    try:
        world, task = batch.world, batch.task
        robot, model = world.robot, world.model
        segments = [{"name": s.name, "size": s.size} for s in task.layout().segments] if task.segments else []
        nq, nv = model.nq, model.nv
        tilt = task.heading_frame  # env.legged.obs_frame=heading: the trunk's yaw taken out of both
        parts = [["trunk_height", 1], ["trunk_tilt_quat_wxyz" if tilt else "trunk_quat_wxyz", 4],
                 ["joint_angles", nq - 7], ["trunk_linvel_heading" if tilt else "trunk_linvel_world", 3],
                 ["trunk_angvel_local", 3], ["joint_speeds", nv - 6]]
        if task.observe_contacts:
            parts.append(["foot_contacts", len(world.feet)])
        if task.height_samples:
            parts.append(["terrain_heights_minus_trunk_z" if task.segments else "terrain_heights", task.height_samples])
        if task.command.size:
            parts.append(["command_vx_vy_yaw_robot_units", task.command.size])
        if task.period is not None:
            parts.append(["clock_sin_cos", 2])
        joints = [model.joint(model.actuator_trnid[a, 0]).name for a in range(model.nu)]
        return {
            "schema": SCHEMA, "robot": robot.name if robot else None, "model_file": world.xml_file,
            "observation": [{"name": n, "size": int(k)} for n, k in parts], "obs_dim": int(task.obs_dim),
            "normalization_segments": segments,
            "control_dt": world.dt, "trained_physics_dt": float(model.opt.timestep),
            "trained_friction_cone": ("pyramidal", "elliptic")[int(model.opt.cone)],  # mjtCone's order
            "feet_geoms": [int(g) for g in world.feet], "foot_names": list(world.foot_names),
            "trunk_body": int(world.trunk), "standing_qpos": [float(q) for q in world.init_qpos],
            "fall_height": float(task.healthy_z[0]),
            "ground_bodies_welded_to_world": True,
            "heading": [float(h) for h in world.heading], "height_sample_spacing": float(task._offsets[1])
            if task.height_samples > 1 else 0.0,
            "gait_period": task.period,
            "command_scale": task.command.scale.tolist() if task.command.size else None,
            "speed_scale": world.units[0], "time_scale": world.units[1],
            "action": {"joints": joints, "home_angle": [float(x) for x in world.home_ctrl / _gears(world)],
                       "scale": [float(x) for x in world.ctrl_per_action / _gears(world)],
                       "low": [_finite(x) for x in world.ctrl_low / _gears(world)],
                       "high": [_finite(x) for x in world.ctrl_high / _gears(world)],
                       "kp": list(robot.kp) if robot else None, "kd": list(robot.kd) if robot else None,
                       "torque_limit": [_finite(t) for t in robot.peak_torque] if robot else None,
                       "drive": list(robot.drive) if robot else None},
        }
    finally:
        batch.close()


def _gears(world):
    import numpy as np

    return np.array(world.robot.gear) if world.robot is not None else np.ones(world.model.nu)


def _finite(x: float):
    return float(x) if math.isfinite(x) else None
