"""The world a legged batch steps: the robot's model compiled once, with everything the recipe changes in it, and
the facts read from it that every part of the task shares (ids, the drives' control mapping, the feet).

`build_world` takes the env's keyword arguments (envs.gym_make_kwargs: the recipe already scaled to the robot) and
makes the model exactly as the locomotion env before the rebuild did (robots/env.py, gone;
tests/legged_reference.py): the step added and the robot's contacts filtered at build time (MjSpec; no model file is
written), the physics step set, torque motors made PD servos around the standing pose, the robustness world's
friction and trunk mass, and the step box turned to face the heading. Each row of the batch steps its own copy of
this model (`row_model`): the terrain moves its row's step in it, a randomized world changes it without touching the
others."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Optional

import mujoco
import numpy as np

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.robots.model import Robot, filter_contacts, read_robot
from ppo_torchrl.tasks.locomotion.terrain import STEP_BODY, TERRAIN_STEP_KEYS, add_step

HEADINGS = {"x": 0.0, "-x": 180.0, "y": 90.0, "-y": 270.0}
GROUND, FOOT, OTHER, NON_FOOT = 1, 2, 0, 3  # a geom's kind (Contacts): the terrain, a foot, a foot body's other geom, a non-foot body's


def heading_angle(heading) -> Optional[float]:
    """Degrees from +x for x, -x, y, -y or a number; None for auto. ConfigError otherwise."""
    text = str(heading).strip()
    if text == "auto":
        return None
    if text in HEADINGS:
        return HEADINGS[text]
    try:
        angle = float(text)
    except ValueError:
        raise ConfigError(f"env.locomotion.heading={heading} is not known; use x, -x, y, -y, auto (the main body's "
                          "own +x axis) or an angle in degrees from +x") from None
    if not math.isfinite(angle):
        raise ConfigError(f"env.locomotion.heading={heading} must be a finite angle in degrees")
    return angle


@dataclass
class World:
    """The compiled model (the template every row copies) and what the task reads of it."""

    model: mujoco.MjModel
    robot: Optional[Robot]  # env=legged's robot read from its model; None: the model as it is (env=mjcf)
    xml_file: str
    trunk: int  # body id of the main body
    frame_skip: int
    dt: float  # the control step (s)
    init_qpos: np.ndarray
    init_qvel: np.ndarray
    heading: np.ndarray  # unit ground direction [2]
    heading_is_x: bool
    init_z: float  # the trunk's height at the standing pose
    up0: np.ndarray  # world up in the trunk's frame at the standing pose
    act_dofs: np.ndarray  # the actuated joints' dofs
    act_qpos: np.ndarray  # their qpos addresses
    home_ctrl: np.ndarray  # per actuator: the control at the standing pose
    ctrl_per_action: np.ndarray  # per actuator: the control a full action adds
    ctrl_low: np.ndarray
    ctrl_high: np.ndarray
    torque_limit: Optional[np.ndarray]  # per actuated joint: the model's own peak torque (the gait figures)
    feet: np.ndarray  # geom ids, in the robot's corner order (LF, RF, LH, RH)
    foot_names: tuple
    corners: Optional[tuple]
    kind: np.ndarray  # per geom: GROUND, FOOT, OTHER, NON_FOOT
    foot_index: np.ndarray  # per geom: its place in `feet`, -1 for the rest
    ending_geom: np.ndarray  # per geom: touching the terrain ends the episode (terminate_on_contact)
    step_body: int  # the step's body id, -1 without one
    step_geom: int
    contact_filter: Optional[tuple]  # env.legged.contacts=terrain: (robot geoms kept, dropped); None otherwise

    @property
    def units(self) -> tuple:
        """(speed, time): the robot's units, sqrt(g l) in m/s and sqrt(l / g) in s (a yaw rate's is 1 / time); (1, 1),
        SI itself, for a model without a robot read from it (env=mjcf)."""
        return (self.robot.speed_scale, self.robot.time_scale) if self.robot else (1.0, 1.0)

    def row_model(self) -> mujoco.MjModel:
        """A row's own copy of the model."""
        return copy.copy(self.model)

    def ctrl_of(self, actions: np.ndarray) -> np.ndarray:
        """Each joint's target (standing angle + its scale x action) within the actuator's range, [N, nu]; without
        a robot read from its model, the action as it is."""
        if self.robot is None:
            return actions
        return np.clip(self.home_ctrl + self.ctrl_per_action * actions, self.ctrl_low, self.ctrl_high)

    def action_bounds(self) -> tuple:
        """(low, high) of one action: [-1, 1] for a robot read from its model, else the actuators' control ranges."""
        if self.robot is not None:
            return -np.ones(self.model.nu, np.float32), np.ones(self.model.nu, np.float32)
        bounds = self.model.actuator_ctrlrange.astype(np.float32)
        return bounds[:, 0].copy(), bounds[:, 1].copy()


def _step_needed(xml_file: str, terrain: dict, robot: Robot) -> Optional[tuple]:
    """add_step's arguments where the terrain asks for a step and the model has none (else None)."""
    asked = [k for k in TERRAIN_STEP_KEYS + ("eval_step_height",) if terrain.get(k) is not None]
    probe = mujoco.MjModel.from_xml_path(str(xml_file))
    if not (asked or terrain.get("curriculum")) or mujoco.mj_name2id(probe, mujoco.mjtObj.mjOBJ_BODY, STEP_BODY) >= 0:
        return None
    heights = [terrain.get("step_height"), terrain.get("eval_step_height"), *(terrain.get("step_height_range") or ())]
    tallest = max([float(h) for h in heights if h is not None] or [0.0])
    distance = float((terrain.get("step_distance") or [2.0])[0])
    height = float(terrain.get("step_height") or terrain.get("eval_step_height") or 0.0)
    return height, distance, max(1.0, 2.0 * tallest), robot.heading


def _compile(kwargs: dict, robot: Robot, render: bool) -> tuple:
    """The model with the step and the contact filter added and the physics step set (MjSpec), as compiled."""
    from ppo_torchrl.tasks.locomotion.filming import add_track_camera, draw_hidden_robot

    legged, terrain = kwargs.get("legged") or {}, kwargs.get("terrain") or {}
    spec = mujoco.MjSpec.from_file(str(kwargs["xml_file"]))  # the model file is read, never written
    step = _step_needed(kwargs["xml_file"], terrain, robot)
    if step:
        add_step(spec, *step)
    contact_filter = filter_contacts(spec) if legged.get("contacts") == "terrain" else None
    if legged.get("physics_dt"):
        spec.option.timestep = float(legged["physics_dt"])
    cone = legged.get("friction_cone") or "model"
    if cone != "model":  # pyramidal or elliptic (robots/recipe.py FRICTION_CONES)
        spec.option.cone = getattr(mujoco.mjtCone, f"mjCONE_{cone.upper()}")
    if render:
        draw_hidden_robot(spec)
        add_track_camera(spec, kwargs["main_body"], heading_angle(legged.get("heading", "x")))
    return spec.compile(), contact_filter


def build_world(kwargs: dict, render: bool = False) -> World:
    """The world of a locomotion env from its keyword arguments (envs.gym_make_kwargs; module doc): env=legged's robot
    read from its model, or (env=mjcf, the in-house quadruped presets) the model as it is, the action its controls."""
    robot_args, legged = kwargs.get("robot"), dict(kwargs.get("legged") or {})
    robot = None if robot_args is None else read_robot(kwargs["xml_file"], robot_args.get("keyframe"))
    if robot is not None:
        model, contact_filter = _compile(kwargs, robot, render)
    else:
        model, contact_filter = _plain_model(kwargs, render), None
    trunk = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, str(kwargs["main_body"])) \
        if not isinstance(kwargs["main_body"], int) else int(kwargs["main_body"])
    if robot is not None:
        home_ctrl, per_action, low, high = _drive(model, robot, float(robot_args["action_scale"]),
                                                  bool(robot_args["saturation_cap"]))
        init_qpos = np.array(robot.qpos)
    else:  # the action is the control, within the actuators' ranges (MuJoCo clamps limited controls)
        home_ctrl, per_action = np.zeros(model.nu), np.ones(model.nu)
        low, high = np.full(model.nu, -np.inf), np.full(model.nu, np.inf)
        init_qpos = model.qpos0.copy()
    friction, trunk_mass = float(legged.get("friction_scale") or 1.0), float(legged.get("trunk_mass_scale") or 1.0)
    if friction != 1.0:  # another world than the one trained on: every contact's grip, the trunk's mass and inertia
        model.geom_friction[:] *= friction
    if trunk_mass != 1.0:
        model.body_mass[trunk] *= trunk_mass
        model.body_inertia[trunk] *= trunk_mass
    data = mujoco.MjData(model)
    data.qpos[:] = init_qpos
    mujoco.mj_kinematics(model, data)
    angle = heading_angle(legged.get("heading", "x"))
    if angle is None:
        axis = data.xmat[trunk].reshape(3, 3)[:2, 0]
        if np.linalg.norm(axis) < 1e-6:
            raise ConfigError("env.locomotion.heading=auto: the main body's +x axis points straight up or down; "
                              "give the heading as x, -x, y, -y or an angle")
        heading = axis / np.linalg.norm(axis)
    else:
        heading = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    act_dofs = _actuators(model, legged)
    act_qpos = np.array([model.jnt_qposadr[model.actuator_trnid[a, 0]] for a in range(model.nu)
                         if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT], np.int64)
    feet = _feet(model, trunk, legged.get("foot_geoms") or [], robot and list(robot.feet))
    kind = _kinds(model, trunk, feet)
    corners = _corners(data.geom_xpos[feet, :2], heading) if robot is None else \
        (tuple(robot.corners) if len(feet) == 4 else None)
    foot_index = np.full(model.ngeom, -1, np.int64)
    foot_index[feet] = np.arange(len(feet))
    ending = np.zeros(model.ngeom, bool)
    for name in legged.get("terminate_on_contact") or []:
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) < 0:
            raise ConfigError(f"env.locomotion.terminate_on_contact: {name} is not a body of the model")
        ending[model.geom_bodyid == model.body(name).id] = True
    ending &= kind != GROUND
    step_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, STEP_BODY)
    step_geom = -1
    if step_body > 0:
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == step_body]
        if len(geoms) != 1 or model.geom_type[geoms[0]] != mujoco.mjtGeom.mjGEOM_BOX:
            raise ConfigError(f"the model's body '{STEP_BODY}' must hold one box geom (the step)")
        step_geom = geoms[0]
        half_angle = 0.5 * math.atan2(heading[1], heading[0])  # the box's own x along the heading
        model.body_quat[step_body] = [math.cos(half_angle), 0.0, 0.0, math.sin(half_angle)]
    frame_skip = int(kwargs["frame_skip"])
    names = tuple(model.geom(g).name or (corners[i] if corners else f"foot {i}") for i, g in enumerate(feet))
    return World(model=model, robot=robot, xml_file=str(kwargs["xml_file"]), trunk=trunk, frame_skip=frame_skip,
                 dt=float(model.opt.timestep) * frame_skip, init_qpos=init_qpos,
                 init_qvel=np.zeros(model.nv), heading=heading, heading_is_x=angle == 0.0,
                 init_z=float(data.xpos[trunk][2]), up0=data.xmat[trunk].reshape(3, 3)[2].copy(), act_dofs=act_dofs,
                 act_qpos=act_qpos,
                 home_ctrl=home_ctrl, ctrl_per_action=per_action, ctrl_low=low, ctrl_high=high,
                 torque_limit=None if robot is None else np.array([min(t, 1e30) for t in robot.peak_torque]),
                 feet=feet, foot_names=names, corners=corners, kind=kind,
                 foot_index=foot_index, ending_geom=ending, step_body=step_body, step_geom=step_geom,
                 contact_filter=contact_filter)


def _plain_model(kwargs: dict, render: bool):
    """env=mjcf's model: compiled from its file as Gymnasium's MuJoCo envs do (with a camera and drawn geoms only for
    a rendered copy), actuators without a ctrlrange given their force range / gear (mjcf.check_mjcf)."""
    from ppo_torchrl.envs.mjcf import check_mjcf
    from ppo_torchrl.tasks.locomotion.filming import add_track_camera, draw_hidden_robot

    path = str(kwargs["xml_file"])
    if render:
        spec = mujoco.MjSpec.from_file(path)
        draw_hidden_robot(spec)
        add_track_camera(spec, kwargs["main_body"], heading_angle((kwargs.get("legged") or {}).get("heading", "x")))
        model = spec.compile()
    else:
        model = mujoco.MjModel.from_xml_path(path)
    from pathlib import Path

    for i, low, high in check_mjcf(Path(path)).ctrl_from_force:
        model.actuator_ctrllimited[i] = 1
        model.actuator_ctrlrange[i] = (low, high)
    return model


def _feet(model, trunk: int, names, derived) -> np.ndarray:
    """The geoms named in env.locomotion.foot_geoms, else `derived` (a robot read from its model), else the geoms
    whose name holds 'foot', else those of the robot's bodies without child bodies."""
    root = model.body_rootid[trunk]
    robot = [g for g in range(model.ngeom) if model.body_rootid[model.geom_bodyid[g]] == root]
    if names:
        missing = [n for n in names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) < 0]
        if missing:
            raise ConfigError(f"env.locomotion.foot_geoms: {', '.join(missing)} is not a geom of the model")
        return np.array([model.geom(n).id for n in names], np.int64)
    if derived:
        return np.array(derived, np.int64)
    feet = [g for g in robot if "foot" in model.geom(g).name.lower()]
    if not feet:
        parents = set(model.body_parentid[1:].tolist())
        feet = [g for g in robot if model.geom_bodyid[g] not in parents]
    return np.array(feet, np.int64)


def _corners(feet_xy: np.ndarray, heading: np.ndarray) -> Optional[tuple]:
    """Each foot's corner (left or right of the feet's centre, ahead or behind along the heading) for four feet, one
    at each corner; else None."""
    from ppo_torchrl.robots.gait import CORNERS

    if len(feet_xy) != 4:
        return None
    xy = feet_xy - feet_xy.mean(axis=0)
    ahead, left = xy @ heading, xy @ np.array([-heading[1], heading[0]])
    corners = tuple(("L" if y > 0 else "R") + ("F" if x > 0 else "H") for x, y in zip(ahead, left))
    return corners if sorted(corners) == sorted(CORNERS) else None


def _drive(model, robot: Robot, action_scale: float, cap: bool) -> tuple:
    """Torque motors made PD servos (robots/model.py gives the gains); the action's control mapping."""
    for a, drive in enumerate(robot.drive):
        if drive != "motor":
            continue
        gear, joint = robot.gear[a], model.actuator_trnid[a, 0]
        # a MuJoCo position actuator on length gear x q: torque = kp (target - q) - kd qdot for ctrl = gear x target
        model.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
        model.actuator_gainprm[a, 0] = robot.kp[a] / gear ** 2
        model.actuator_biasprm[a, :3] = [0.0, -robot.kp[a] / gear ** 2, -robot.kd[a] / gear ** 2]
        model.actuator_forcelimited[a] = 1
        model.actuator_forcerange[a] = [-robot.peak_torque[a] / abs(gear), robot.peak_torque[a] / abs(gear)]
        model.actuator_ctrllimited[a] = model.jnt_limited[joint]
        model.actuator_ctrlrange[a] = np.sort(gear * model.jnt_range[joint])
    gear = np.array(robot.gear)
    limited = model.actuator_ctrllimited.astype(bool)
    return (gear * np.array(robot.home_angle), gear * np.array(robot.action_scales(action_scale, cap)),
            np.where(limited, model.actuator_ctrlrange[:, 0], -np.inf),
            np.where(limited, model.actuator_ctrlrange[:, 1], np.inf))


def _actuators(model, legged: dict) -> np.ndarray:
    """The actuated joints' dofs, with env.locomotion's torque and speed limits, gains and armature applied."""
    limit, speed = legged.get("torque_limit"), legged.get("joint_speed_limit")
    kp, kd, armature = legged.get("kp"), legged.get("kd"), legged.get("armature")
    actuated = [model.actuator_trnid[i, 0] for i in range(model.nu)
                if model.actuator_trntype[i] == mujoco.mjtTrn.mjTRN_JOINT]
    act_dofs = np.array([model.jnt_dofadr[j] for j in actuated], dtype=np.int64)
    gear = np.abs(model.actuator_gear[:, 0])
    gear[gear == 0] = 1.0
    if limit is not None:
        model.actuator_forcelimited[:] = 1
        model.actuator_forcerange[:] = np.stack([-limit / gear, limit / gear], axis=1)
    if kp is not None or kd is not None:
        servo = (model.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE) & np.isclose(
            model.actuator_biasprm[:, 1], -model.actuator_gainprm[:, 0])
        if not servo.all():
            raise ConfigError("env.locomotion.kp / kd set position-servo gains, but this model has actuators that "
                              "are not position actuators")
        if kp is not None:
            model.actuator_gainprm[:, 0] = kp
            model.actuator_biasprm[:, 1] = -kp
        if kd is not None:
            model.actuator_biasprm[:, 2] = -kd
    if armature is not None:
        model.dof_armature[act_dofs] = armature
    if speed is not None:  # the torque-speed line as damping: the net drive torque is 0 at the limit
        if not model.actuator_forcelimited.all():
            raise ConfigError("env.locomotion.joint_speed_limit needs a torque limit: set env.locomotion.torque_limit "
                              "(or forcerange on every actuator)")
        peak = np.abs(model.actuator_forcerange).max(axis=1) * gear
        model.dof_damping[act_dofs] += peak / speed
    return act_dofs


def _kinds(model, trunk: int, feet: np.ndarray) -> np.ndarray:
    """Each geom's kind: GROUND (of a body welded to the world: the floor, the step), FOOT, NON_FOOT (a geom of a
    robot body that holds no foot: the trunk, a thigh), OTHER (the rest, such as the shank that carries a foot)."""
    root = model.body_rootid[trunk]
    robot = [g for g in range(model.ngeom) if model.body_rootid[model.geom_bodyid[g]] == root]
    kind = np.full(model.ngeom, OTHER, np.int8)
    kind[model.body_weldid[model.geom_bodyid] == 0] = GROUND
    foot_bodies = set(model.geom_bodyid[feet].tolist())
    kind[[g for g in robot if model.geom_bodyid[g] not in foot_bodies]] = NON_FOOT
    kind[feet] = FOOT
    return kind
