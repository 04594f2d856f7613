"""Drive an exported legged policy in plain MuJoCo: the deploy check (issue 73 item 5). Needs mujoco and torch (or
onnxruntime for policy.onnx), not ppo_torchrl: export writes this file beside policy.pt, policy.onnx and policy.json.

    python deploy_mujoco.py policy.json [--policy policy.pt|policy.onnx] [--model <scene.xml>] [--noise 1.0]
        [--commands "forward:0.3,0,0:4;turn:0,0,0.25:4;left:0,0.25,0:4;stop:0,0,0:3"] [--seed 0]

It builds each observation from the simulator as policy.json lists it (the layout the robot must feed the policy),
runs the policy at the control step, and holds each joint's target with the robot's own servos (position actuators
as the model has them) or a PD loop at every physics step (torque motors: kp, kd and the torque limit of the run),
on the model file as it is (all its contacts, its own physics step). Commands: name:vx,vy,yaw:seconds, in the robot's
units (speeds in sqrt(g l), the yaw rate in sqrt(g / l)). --noise: uniform observation noise at that level (the
training's scales). Prints one JSON line per command segment: the measured mean velocity against the command, and
whether the trunk fell below its fall line.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import mujoco
import numpy as np

NOISE = {"height_attitude": 0.02, "joint_angle": 0.03, "linear": 0.05, "angular": 0.04, "joint_speed": 0.3}


def observation(model, data, manifest: dict, command, time_s: float) -> np.ndarray:
    """The observation policy.json describes, for the state in `data` and `command` (robot units)."""
    qpos, qvel = data.qpos[2:].copy(), data.qvel.copy()
    names = [p["name"] for p in manifest["observation"]]
    if "trunk_tilt_quat_wxyz" in names:  # the trunk's yaw taken out of its attitude and its linear velocity
        w, x, y, z = qpos[1:5]
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        c, s = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
        tilt = np.array([c * w + s * z, c * x + s * y, c * y - s * x, c * z - s * w])
        qpos[1:5] = -tilt if tilt[0] < 0 else tilt
        cy, sy = math.cos(yaw), math.sin(yaw)
        qvel[0], qvel[1] = cy * data.qvel[0] + sy * data.qvel[1], -sy * data.qvel[0] + cy * data.qvel[1]
    parts = [qpos, qvel]
    if "foot_contacts" in names:
        feet = manifest["feet_geoms"]
        flags = np.zeros(len(feet))
        ground = {g for g in range(model.ngeom) if model.body_weldid[model.geom_bodyid[g]] == 0}
        for a, b in data.contact.geom:
            for foot, other in ((a, b), (b, a)):
                if foot in feet and other in ground:
                    flags[feet.index(foot)] = 1.0
        parts.append(flags)
    for name in ("terrain_heights_minus_trunk_z", "terrain_heights"):
        if name in names:
            size = next(p["size"] for p in manifest["observation"] if p["name"] == name)
            ground = np.zeros(size)  # flat ground at z = 0
            parts.append(ground - data.xpos[manifest["trunk_body"], 2] if name.endswith("minus_trunk_z") else ground)
    if "command_vx_vy_yaw_robot_units" in names:
        parts.append(np.asarray(command, np.float64))
    if "clock_sin_cos" in names:
        angle = 2.0 * math.pi * ((time_s / manifest["gait_period"]) % 1.0)
        parts.append(np.array([math.sin(angle), math.cos(angle)]))
    return np.concatenate(parts)


def noise_scale(model, manifest: dict) -> np.ndarray:
    nq, nv = model.nq, model.nv
    speed, rate = manifest["speed_scale"], 1.0 / manifest["time_scale"]
    scale = np.zeros(nq - 2 + nv)
    scale[:5] = NOISE["height_attitude"]
    scale[5:nq - 2] = NOISE["joint_angle"]
    scale[nq - 2:nq + 1] = NOISE["linear"] * speed
    scale[nq + 1:nq + 4] = NOISE["angular"] * rate
    scale[nq + 4:] = NOISE["joint_speed"] * rate
    return scale


def load_policy(path: str):
    if path.endswith(".onnx"):
        import onnxruntime

        session = onnxruntime.InferenceSession(path)
        name = session.get_inputs()[0].name
        return lambda obs: session.run(None, {name: obs[None].astype(np.float64)})[0][0]
    import torch

    module = torch.jit.load(path)
    return lambda obs: module(torch.as_tensor(obs[None], dtype=torch.float64)).detach().numpy()[0]


class Drives:
    """Each joint's target held: by the model's own position servos, or a PD loop on its torque motors."""

    def __init__(self, model, manifest: dict):
        a = manifest["action"]
        self.home, self.scale = np.array(a["home_angle"]), np.array(a["scale"])
        self.low = np.array([-np.inf if x is None else x for x in a["low"]])
        self.high = np.array([np.inf if x is None else x for x in a["high"]])
        self.kp, self.kd = np.array(a["kp"]), np.array(a["kd"])
        self.limit = np.array([np.inf if x is None else x for x in a["torque_limit"]])
        self.position = np.array([d == "position" for d in a["drive"]])
        self.gear = model.actuator_gear[:, 0].copy()
        self.gear[self.gear == 0] = 1.0
        self.gain = model.actuator_gainprm[:, 0].copy()
        joints = model.actuator_trnid[:, 0]
        self.qadr, self.vadr = model.jnt_qposadr[joints], model.jnt_dofadr[joints]
        self.target = self.home.copy()

    def act(self, action) -> None:
        self.target = np.clip(self.home + self.scale * np.asarray(action, np.float64), self.low, self.high)

    def apply(self, data) -> None:
        """Before each physics step."""
        q, qd = data.qpos[self.qadr], data.qvel[self.vadr]
        torque = np.clip(self.kp * (self.target - q) - self.kd * qd, -self.limit, self.limit)
        data.ctrl[:] = np.where(self.position, self.gear * self.target, torque / (self.gain * self.gear))


def run(manifest: dict, policy, model_file: str, segments: list, noise: float = 0.0, seed: int = 0) -> list:
    model = mujoco.MjModel.from_xml_path(model_file)
    data = mujoco.MjData(model)
    data.qpos[:] = manifest["standing_qpos"]
    mujoco.mj_forward(model, data)
    drives = Drives(model, manifest)
    rng = np.random.default_rng(seed)
    scale = noise_scale(model, manifest) * noise
    per_control = max(1, round(manifest["control_dt"] / model.opt.timestep))
    speed, rate = manifest["speed_scale"], 1.0 / manifest["time_scale"]
    out, t = [], 0.0
    for name, command, seconds in segments:
        velocities, fell = [], False
        for _ in range(max(1, round(seconds / manifest["control_dt"]))):
            obs = observation(model, data, manifest, command, t)
            obs[:len(scale)] += rng.uniform(-1.0, 1.0, len(scale)) * scale
            drives.act(policy(obs))
            for _ in range(per_control):
                drives.apply(data)
                mujoco.mj_step(model, data)
            t += manifest["control_dt"]
            xmat = data.xmat[manifest["trunk_body"]]
            yaw = math.atan2(xmat[3], xmat[0])
            c, s = math.cos(yaw), math.sin(yaw)
            vx, vy = data.qvel[0], data.qvel[1]
            omega_z = xmat.reshape(3, 3)[2] @ data.qvel[3:6]
            velocities.append([(c * vx + s * vy) / speed, (-s * vx + c * vy) / speed, omega_z / rate])
            fell = fell or data.qpos[2] < manifest["fall_height"]
        mean = np.mean(velocities[len(velocities) // 2:], axis=0)  # the second half: after the robot settles
        out.append({"segment": name, "command": list(command), "measured": [round(float(x), 4) for x in mean],
                    "fell": bool(fell)})
    return out


def parse_commands(text: str) -> list:
    segments = []
    for part in text.split(";"):
        name, values, seconds = part.split(":")
        segments.append((name, [float(v) for v in values.split(",")], float(seconds)))
    return segments


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("manifest")
    p.add_argument("--policy", help="the .pt or .onnx (default: the .pt the manifest names, beside it)")
    p.add_argument("--model", help="the model file (default: the one the run trained on)")
    p.add_argument("--commands", default="forward:0.3,0,0:4;turn:0,0,0.25:4;left:0,0.25,0:4;stop:0,0,0:3")
    p.add_argument("--noise", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    with open(args.manifest) as f:
        manifest = json.load(f)
    from pathlib import Path

    policy_path = args.policy or str(Path(args.manifest).with_name(manifest.get("policy", "policy.pt")))
    try:
        segments = parse_commands(args.commands)
    except ValueError:
        print("error: --commands takes name:vx,vy,yaw:seconds;... e.g. forward:0.3,0,0:4;stop:0,0,0:2", file=sys.stderr)
        return 2
    for line in run(manifest, load_policy(policy_path), args.model or manifest["model_file"], segments, args.noise,
                    args.seed):
        print(json.dumps(line))
    return 0


if __name__ == "__main__":
    sys.exit(main())
