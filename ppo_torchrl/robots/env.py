"""The locomotion env of MJCF robots (env=mjcf, env=legged, env=quadruped, env=quadruped_step).

`LocomotionEnv` is Gymnasium's Ant-v5 class (any model through `xml_file`) with, each off unless
configured (so a config without these keys steps exactly as Ant-v5 does):

- **A robot read from its model** (env=legged; robots/model.py): the standing pose from its keyframe,
  its feet, heading and drives; each action is a joint-angle offset from the standing pose
  (target = standing angle + scale x action, action in [-1, 1]; scale: env.legged.action_scale, or with
  env.legged.saturation_cap the servo's saturation angle, peak torque / kp, where smaller) sent to the servos
  as the model has them, torque motors being made PD servos first; the step added to the model at
  build time (robots/terrain.py); the robot's geoms made to touch the terrain only (env.legged.contacts)
  and the physics step set (env.legged.physics_dt), both at build time (robots/model.py).
- **Heading** (`env.locomotion.heading`): the forward reward and eval's forward velocity are the main
  body's velocity along this ground direction, not +x of the world.
- **Actuation** (`torque_limit`, `joint_speed_limit`, `kp`, `kd`, `armature`): the model's actuators
  are rewritten at build time. The speed limit is the drive's torque-speed line,
  torque <= torque_limit x (1 - speed / joint_speed_limit): a torque source behind a viscous loss of
  torque_limit / joint_speed_limit (a DC motor's back-EMF), so it is joint damping of that size added
  to each actuated joint, which MuJoCo integrates implicitly (`implicitfast`). Chosen over clipping
  the torque by the speed before each physics step: with these light legs a full-torque physics step
  (5 ms) can add several rad/s, so random actions drove joints well past the limit through that
  clip, while the damping holds them under it (tests/test_locomotion.py runs such a rollout; the
  model's own joint damping adds margin). Outside forces (a fall, an impact) can still push a joint
  past the limit, which eval's peak joint speed would show.
- **Reward terms** (robots/rewards.py), **terrain** (robots/terrain.py), **contacts** and termination
  on contact (robots/contacts.py), each a mixin of this class; `only_positive_rewards` floors each
  step's reward at 0, as legged_gym does, so that while the costs outweigh the rest an early fall
  does not pay. Why an episode ended is `termination` (also in `info`): 'contact: <body>', else
  is_healthy's 'fall' (under healthy_z_range), 'too high', 'non-finite state'; None while it runs or
  when only the time limit ends it.
- **Observation extras** (opt-in, the policy is blind by default): one 0/1 ground-contact flag per foot;
  terrain heights at points ahead of the main body, computed from the known step geometry
  (the step's top where the point lies beyond its edge, else 0: the floor is at z = 0); the trot
  clock's phase (sin, cos). How each is scaled is the env's to say (`observation_layout`, layout.py): with
  env.legged.obs_layout=segments the heights come relative to the trunk and are scaled by the leg length
  with a fixed clip, flags and clock pass as they are, and only the rest goes through running statistics.
- **Gait bookkeeping** for eval (`measure_gait = True`; robots/gait.py), sampled every physics step.
- **Tracking camera**: a rendered model without a camera named `track` gets one on its main body.
- **A robot to film**: MuJoCo draws geom groups 0-2 only, and models whose visual meshes were left out
  (Menagerie's keep collision geoms in group 3) would film an empty floor: a rendered env whose robot has
  no drawn geom draws its group-3 geoms (in the rendered copy only; a geom's group changes no physics).
"""

from __future__ import annotations

import math
from typing import Optional

import mujoco
import numpy as np
from gymnasium import utils
from gymnasium.envs.mujoco.ant_v5 import AntEnv
from gymnasium.spaces import Box

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.layout import ObservationLayout, Segment
from ppo_torchrl.robots.contacts import FootContacts
from ppo_torchrl.robots.gait import MOVING_SPEED, GaitMeter
from ppo_torchrl.robots.model import Robot, filter_contacts, read_robot
from ppo_torchrl.robots.rewards import LeggedRewards
from ppo_torchrl.robots.terrain import STEP_BODY, TERRAIN_STEP_KEYS, StepTerrain, add_step

LOCOMOTION_ID = "ppo_torchrl/Locomotion-v0"
HEADINGS = {"x": 0.0, "-x": 180.0, "y": 90.0, "-y": 270.0}
HEIGHT_CLIP = 1.0  # x l: terrain heights relative to the trunk read within +-1 leg length (observation_layout)

# Keys of env.locomotion that LocomotionEnv takes (the others are Ant-v5's own arguments).
LEGGED_KEYS = ("heading", "target_speed", "torque_limit", "joint_speed_limit", "kp", "kd", "armature",
               "torque_cost_weight", "joint_speed_cost_weight", "joint_speed_limit_cost_weight",
               "action_rate_cost_weight", "foot_slip_cost_weight", "base_height_cost_weight", "base_height_target",
               "orientation_cost_weight", "body_contact_cost_weight", "feet_air_time_weight", "feet_air_time_target",
               "foot_geoms", "only_positive_rewards", "terminate_on_contact", "healthy_z_above_terrain",
               "gait_period", "gait_clock_weight", "long_swing_cost_weight", "long_swing_limit", "contacts", "physics_dt",
               "friction_scale", "trunk_mass_scale", "stumble_cost_weight")


def register() -> None:
    import gymnasium as gym

    if LOCOMOTION_ID not in gym.registry:
        gym.register(id=LOCOMOTION_ID, entry_point="ppo_torchrl.robots.env:LocomotionEnv", max_episode_steps=1000)


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


DRAWN_GROUPS = 3  # MuJoCo's default visual options draw geom groups 0, 1 and 2
HIDDEN_GROUP = 3  # where MuJoCo Menagerie's models keep their collision geoms


def draw_hidden_robot(spec) -> bool:
    """Moves the robot's group-3 geoms into group 0 when none of its geoms (those of a body under a free
    joint) is drawn (groups 0-2, not transparent), as in a model whose visual meshes were left out; True
    if it did. Only for a rendered copy of the model: the group is a drawing choice, no contact or force
    reads it. (spec.bodies lists the bodies in the compiled model's order, the world first.)"""
    plain = spec.compile()
    free_roots = {plain.jnt_bodyid[j] for j in range(plain.njnt) if plain.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE}
    on_robot = np.isin(plain.body_rootid, list(free_roots))  # per body
    robot_geoms = on_robot[plain.geom_bodyid]
    drawn = robot_geoms & (plain.geom_group < DRAWN_GROUPS) & (plain.geom_rgba[:, 3] > 0)
    if drawn.any():
        return False
    hidden = [g for body, robot in zip(spec.bodies, on_robot) if robot for g in body.geoms if g.group == HIDDEN_GROUP]
    for geom in hidden:
        geom.group = 0
    return bool(hidden)


class LocomotionEnv(StepTerrain, FootContacts, LeggedRewards, AntEnv):
    """Ant-v5 over any MJCF model, plus a robot read from its model, heading, actuation limits, reward terms,
    terrain and gait (module doc)."""

    # Within step, read once after the control step: is_healthy (and the contacts: FootContacts._now).
    _healthy_now = None
    _moving = False  # the last control step went forward at MOVING_SPEED or more (gait bookkeeping)
    contact_filter = None  # env.legged.contacts=terrain: (robot geoms left colliding, robot geoms made non-colliding)

    def __init__(self, xml_file: str, legged: Optional[dict] = None, terrain: Optional[dict] = None,
                 evaluation: bool = False, robot: Optional[dict] = None, **ant_kwargs):
        """robot: env=legged's {'keyframe', 'action_scale', 'saturation_cap'}: the robot read from xml_file
        (robots/model.py) stands, acts and meets its step as the module doc says; None: the model as it is."""
        legged, terrain = dict(legged or {}), dict(terrain or {})
        self._legged, self._terrain_cfg, self._evaluation = legged, terrain, evaluation
        self._add_track_camera = False
        self._draw_collision_geoms = ant_kwargs.get("render_mode") is not None
        self._robot: Optional[Robot] = None if robot is None else read_robot(xml_file, robot.get("keyframe"))
        self._segments = robot is not None and robot.get("obs_layout") == "segments"  # observation_layout
        self._step_to_add = self._step_needed(xml_file, terrain) if self._robot is not None else None
        if ant_kwargs.get("render_mode") is not None and "camera_name" not in ant_kwargs and "camera_id" not in ant_kwargs:
            probe = mujoco.MjModel.from_xml_path(str(xml_file))
            names = [probe.camera(i).name for i in range(probe.ncam)]
            self._add_track_camera = "track" not in names
            ant_kwargs["camera_name"] = "track"
        super().__init__(xml_file=xml_file, **ant_kwargs)
        utils.EzPickle.__init__(self, xml_file, legged, terrain, evaluation, robot, **ant_kwargs)
        model, data = self.model, self.data
        self._body_id = data.body(self._main_body).id
        if self._robot is not None:
            self._drive_robot(float(robot["action_scale"]), bool(robot["saturation_cap"]))
            data.qpos[:] = self.init_qpos
        self._perturb(float(legged.get("friction_scale") or 1.0), float(legged.get("trunk_mass_scale") or 1.0))
        mujoco.mj_kinematics(model, data)  # the model's initial pose (reset computes it again)
        self._init_z = float(data.xpos[self._body_id][2])
        self._up0 = data.xmat[self._body_id].reshape(3, 3)[2].copy()  # world up in the body frame at the start
        angle = heading_angle(legged.get("heading", "x"))
        if angle is None:  # auto: the main body's +x axis, on the ground
            axis = data.xmat[self._body_id].reshape(3, 3)[:2, 0]
            if np.linalg.norm(axis) < 1e-6:
                raise ConfigError("env.locomotion.heading=auto: the main body's +x axis points straight up or down; "
                                  "give the heading as x, -x, y, -y or an angle")
            self.heading = axis / np.linalg.norm(axis)
        else:
            self.heading = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
        self._heading_is_x = angle == 0.0
        self._set_up_actuators(legged)
        self._set_up_contacts(legged.get("foot_geoms") or [], self._robot and list(self._robot.feet))
        self._set_up_contact_termination(legged.get("terminate_on_contact") or [])
        self._set_up_terrain(terrain, evaluation)
        self._w = {k: float(legged.get(k) or 0.0) for k in LEGGED_KEYS if k.endswith("_weight")}
        if self._w["joint_speed_limit_cost_weight"] and legged.get("joint_speed_limit") is None:
            raise ConfigError("env.locomotion.joint_speed_limit_cost_weight needs env.locomotion.joint_speed_limit")
        self._speed_limit = legged.get("joint_speed_limit")
        self._step_peak = np.zeros(len(self._act_dofs))  # each actuated joint's top |speed| in the last control step
        # a robot read from its model: each actuated joint's torque limit, the model's own (eval's torque figures)
        self._torque_limit = None if self._robot is None else \
            np.array([min(t, 1e30) for t in self._robot.peak_torque], np.float64)
        self._target_speed = legged.get("target_speed")
        self._positive_only = bool(legged.get("only_positive_rewards"))
        self._z_above_terrain = bool(legged.get("healthy_z_above_terrain"))
        self._air_target = float(legged.get("feet_air_time_target", 0.5))
        self._swing_limit = float(legged.get("long_swing_limit", 0.5))
        target = legged.get("base_height_target")
        self._height_target = self._init_z if target is None else float(target)
        self._set_up_clock(legged.get("gait_period"))
        self._needs_contacts = bool(self.observe_contacts or self._w["foot_slip_cost_weight"]
                                    or self._w["feet_air_time_weight"] or self._w["body_contact_cost_weight"]
                                    or self._w["gait_clock_weight"] or self._w["long_swing_cost_weight"])
        self._dt = self.dt  # the control step (s), read from the model once
        self.measure_gait = False  # evaluate sets it: gait figures sampled every physics step
        self.gait = GaitMeter(len(self.feet), self._speed_limit, self.foot_corners)
        self._reset_episode_memory()
        extra = len(self.feet) * self.observe_contacts + self.height_samples + 2 * (self._period is not None)
        if extra:
            size = self.observation_space.shape[0] + extra
            self.observation_space = Box(low=-np.inf, high=np.inf, shape=(size,), dtype=np.float64)

    # -- model set-up --------------------------------------------------------------------------------
    def _initialize_simulation(self):
        # env=legged's contacts and physics step (robots/model.py; recipe.py derives them): None for other envs
        only_terrain, physics_dt = self._legged.get("contacts") == "terrain", self._legged.get("physics_dt")
        if not (self._add_track_camera or self._step_to_add or self._draw_collision_geoms or only_terrain
                or physics_dt):
            return super()._initialize_simulation()
        spec = mujoco.MjSpec.from_file(self.fullpath)  # the model file is read, never written
        if self._step_to_add:
            add_step(spec, *self._step_to_add)
        if only_terrain:  # after the step is added: it is terrain
            self.contact_filter = filter_contacts(spec)
        if physics_dt:
            spec.option.timestep = float(physics_dt)
        if self._draw_collision_geoms:
            self._draw_collision_geoms = draw_hidden_robot(spec)
        if self._add_track_camera:
            self._add_track_camera = self._place_camera(spec)
        model = spec.compile()
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, self.width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, self.height)
        return model, mujoco.MjData(model)

    def _place_camera(self, spec) -> bool:
        """Adds the `track` camera on the main body, beside it and looking at it; False (no camera: render from
        the free camera) where the main body has no name."""
        plain = spec.compile()
        body = plain.body(self._main_body)
        data = mujoco.MjData(plain)
        mujoco.mj_kinematics(plain, data)
        sub = [g for g in range(plain.ngeom) if plain.body_rootid[plain.geom_bodyid[g]] == plain.body_rootid[body.id]]
        origin = data.xpos[body.id]
        extent = max([np.linalg.norm(data.geom_xpos[g] - origin) + plain.geom_rbound[g] for g in sub] or [0.5])
        heading = self._camera_heading(plain, data, body.id)
        left = np.array([-heading[1], heading[0], 0.0])
        forward = np.array([heading[0], heading[1], 0.0])
        distance = 4.0 * extent
        offset = -distance * left + 0.15 * distance * forward + np.array([0, 0, distance / 3])
        z_axis = offset / np.linalg.norm(offset)  # the camera looks along -z, at the body
        y_axis = np.cross(z_axis, forward)
        rotation = data.xmat[body.id].reshape(3, 3)  # world from body: the camera is given in the body's frame
        target = spec.body(plain.body(body.id).name) if plain.body(body.id).name else None
        if target is None:
            return False
        target.add_camera(name="track", mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM, pos=rotation.T @ offset,
                          xyaxes=np.concatenate([rotation.T @ forward, rotation.T @ y_axis]))
        return True

    def _step_needed(self, xml_file: str, terrain: dict) -> Optional[tuple]:
        """add_step's arguments where the terrain asks for a step and the model has none (else None): the
        step at its evaluation height and nearest distance, deep enough for the tallest height asked."""
        asked = [k for k in TERRAIN_STEP_KEYS + ("eval_step_height",) if terrain.get(k) is not None]
        probe = mujoco.MjModel.from_xml_path(str(xml_file))
        if not (asked or terrain.get("curriculum")) or mujoco.mj_name2id(probe, mujoco.mjtObj.mjOBJ_BODY, STEP_BODY) >= 0:
            return None
        heights = [terrain.get("step_height"), terrain.get("eval_step_height"), *(terrain.get("step_height_range") or ())]
        tallest = max([float(h) for h in heights if h is not None] or [0.0])
        distance = float((terrain.get("step_distance") or [2.0])[0])
        height = float(terrain.get("step_height") or terrain.get("eval_step_height") or 0.0)
        return height, distance, max(1.0, 2.0 * tallest), self._robot.heading

    def _camera_heading(self, model, data, body_id) -> np.ndarray:
        angle = heading_angle(self._legged.get("heading", "x"))
        if angle is None:
            axis = data.xmat[body_id].reshape(3, 3)[:2, 0]
            return axis / max(np.linalg.norm(axis), 1e-9)
        return np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])

    def _set_up_actuators(self, legged: dict) -> None:
        model = self.model
        limit, speed = legged.get("torque_limit"), legged.get("joint_speed_limit")
        kp, kd, armature = legged.get("kp"), legged.get("kd"), legged.get("armature")
        actuated = [model.actuator_trnid[i, 0] for i in range(model.nu)
                    if model.actuator_trntype[i] == mujoco.mjtTrn.mjTRN_JOINT]
        self._act_dofs = np.array([model.jnt_dofadr[j] for j in actuated], dtype=np.int64)
        first = int(self._act_dofs[0]) if len(actuated) else 0  # qvel[a:b], a view, where the dofs are contiguous
        contiguous = np.array_equal(self._act_dofs, np.arange(first, first + len(actuated)))
        self._act_qvel = slice(first, first + len(actuated)) if contiguous else self._act_dofs
        if any(v is not None for v in (limit, speed, kp, kd, armature)) and len(actuated) != model.nu:
            raise ConfigError("env.locomotion torque/speed limits and gains need every actuator to drive a joint "
                              "(transmission 'joint'); this model has other transmissions")
        gear = np.abs(model.actuator_gear[:, 0]) if model.nu else np.ones(0)
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
            model.dof_armature[self._act_dofs] = armature
        if speed is not None:  # the torque-speed line as damping: the net drive torque is 0 at the limit
            if not model.actuator_forcelimited.all():
                raise ConfigError("env.locomotion.joint_speed_limit needs a torque limit: set env.locomotion.torque_limit "
                                  "(or forcerange on every actuator)")
            peak = np.abs(model.actuator_forcerange).max(axis=1) * gear
            model.dof_damping[self._act_dofs] += peak / speed

    def _perturb(self, friction: float, trunk_mass: float) -> None:
        """Another world than the one trained on: every contact's friction (MuJoCo takes the larger of the two geoms':
        the feet's and the floor's are both scaled, so the grip scales by `friction`) and the main body's mass and
        inertia scaled (the model file is left as it is)."""
        model = self.model
        if friction != 1.0:
            model.geom_friction[:] *= friction
        if trunk_mass != 1.0:
            model.body_mass[self._body_id] *= trunk_mass
            model.body_inertia[self._body_id] *= trunk_mass

    def _drive_robot(self, action_scale: float, cap: bool) -> None:
        """env=legged: the standing pose as the start, torque motors made PD servos (robots/model.py gives
        the gains), and the action as joint-angle offsets from the standing pose (module doc)."""
        model, robot = self.model, self._robot
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
        self.init_qpos = np.array(robot.qpos)
        gear = np.array(robot.gear)
        self._home_ctrl = gear * np.array(robot.home_angle)
        self._ctrl_per_action = gear * np.array(robot.action_scales(action_scale, cap))
        limited = model.actuator_ctrllimited.astype(bool)
        self._ctrl_low = np.where(limited, model.actuator_ctrlrange[:, 0], -np.inf)
        self._ctrl_high = np.where(limited, model.actuator_ctrlrange[:, 1], np.inf)
        self.action_space = Box(low=-1.0, high=1.0, shape=(model.nu,), dtype=np.float32)

    def ctrl_of(self, action) -> np.ndarray:
        """The control the simulator gets for an action: as it is, or with a robot read from its model, each
        joint's target angle (standing angle + its scale x action, Robot.action_scales) within the actuator's
        range."""
        if self._robot is None:
            return action
        return np.clip(self._home_ctrl + self._ctrl_per_action * np.asarray(action, np.float64),
                       self._ctrl_low, self._ctrl_high)

    # -- episodes ------------------------------------------------------------------------------------
    def _reset_episode_memory(self) -> None:
        self._prev_action = np.zeros(self.model.nu)
        self._air_time = np.zeros(len(self.feet))
        self._prev_contact = np.zeros(len(self.feet), bool)
        self._prev_feet_xy = None
        self._clock_steps = 0  # control steps since the episode began: the trot clock's time
        self._stepped = self._moving = False
        self.termination = None  # why the episode ended (step): 'contact: <body>', 'fall', ...; None while it runs
        self.gait.reset()

    def reset(self, *, seed=None, options=None):
        # judge the episode before the reset wipes it (a flat_share episode says nothing of the level)
        if self.has_step and self._stepped and self._curriculum and not self._flat_episode:
            self._record_outcome(self.crossed())
        self._stepped = False
        return super().reset(seed=seed, options=options)

    def reset_model(self):
        if self.has_step and self._moves_step:
            self._draw_step()
        self._reset_episode_memory()
        observation = super().reset_model()
        self._prev_feet_xy = self.data.geom_xpos[self.feet, :2].copy()
        return observation

    @property
    def is_healthy(self) -> bool:
        """Ant-v5's test on the root's z; with healthy_z_above_terrain, that z less the terrain's height under main_body."""
        if self._healthy_now is not None:
            return self._healthy_now
        return self._unhealthy() is None

    def _unhealthy(self) -> Optional[str]:
        """Why is_healthy is False: 'non-finite state', 'fall' (the root's z under healthy_z_range, above the
        terrain with healthy_z_above_terrain), 'too high' (over it); None while healthy."""
        qpos = self.data.qpos  # Ant-v5's state_vector() is qpos and qvel, concatenated
        if not (np.isfinite(qpos).all() and np.isfinite(self.data.qvel).all()):
            return "non-finite state"
        low, high = self._healthy_z_range
        z = qpos[2] - self._ground_under_body() if self._z_above_terrain else qpos[2]
        return "fall" if z < low else "too high" if z > high else None

    # -- stepping ------------------------------------------------------------------------------------
    def _step_mujoco_simulation(self, ctrl, n_frames):
        if not (self.measure_gait or self._w["joint_speed_limit_cost_weight"]):
            return super()._step_mujoco_simulation(ctrl, n_frames)
        model, data = self.model, self.data
        data.ctrl[:] = ctrl
        peak, speeds = np.zeros(len(self._act_dofs)), np.empty(len(self._act_dofs))
        for _ in range(n_frames):  # joint speeds (and, in eval, the gait) sampled at every physics step
            mujoco.mj_step(model, data)
            np.abs(data.qvel[self._act_qvel], out=speeds)
            np.maximum(peak, speeds, out=peak)
            if self.measure_gait:
                feet, body = self._contacts()
                torque = None if self._torque_limit is None else \
                    float((np.abs(data.qfrc_actuator[self._act_dofs]) / self._torque_limit).max())
                self.gait.add(feet, float(speeds.max()) if len(speeds) else 0.0, body > 0, model.opt.timestep,
                              self._moving, torque)
        self._step_peak = peak
        mujoco.mj_rnePostConstraint(model, data)

    def step(self, action):
        self._now = self._healthy_now = None
        xy_before = self.data.xpos[self._body_id, :2].copy()
        self.do_simulation(self.ctrl_of(action), self.frame_skip)
        xy_after = self.data.xpos[self._body_id, :2].copy()
        if self._needs_contacts or self._ends_on_contact:  # read once for the observation, reward and end
            self._now = self._read_contacts()
        self._healthy_now = self.is_healthy
        xy_velocity = (xy_after - xy_before) / self._dt
        x_velocity, y_velocity = xy_velocity
        speed = x_velocity if self._heading_is_x else float(xy_velocity @ self.heading)
        self._stepped, self._moving = True, speed >= MOVING_SPEED

        reward, reward_info = self._get_rew(speed, action)
        extra_reward, extra_info = self._legged_terms(action)
        self._clock_steps += 1
        observation = self._get_obs()  # what the next action is taken on: the clock's next phase
        reward = reward + extra_reward if extra_info else reward
        if self._positive_only:  # legged_gym's only_positive_rewards: costs never make an early fall pay
            reward = max(reward, 0.0)
        # why the episode ends here: a terminate_on_contact body on the ground first, then is_healthy's reason
        contact = self._ending_contact()
        self.termination = (f"contact: {contact}" if contact is not None else
                            self._unhealthy() if self._terminate_when_unhealthy and not self.is_healthy else None)
        terminated = self.termination is not None
        xy = self.data.qpos[0:2]
        info = {"x_position": self.data.qpos[0], "y_position": self.data.qpos[1],
                "distance_from_origin": np.sqrt(xy.dot(xy)),  # np.linalg.norm's own sum for a vector
                "x_velocity": x_velocity, "y_velocity": y_velocity, "forward_velocity": speed,
                "termination": self.termination,
                **reward_info, **extra_info}
        self._now = self._healthy_now = None
        if self.render_mode == "human":
            self.render()
        return observation, reward, terminated, False, info

    def _get_obs(self):
        observation = super()._get_obs()
        extras = []
        if self.observe_contacts:
            extras.append(self._contacts()[0].astype(np.float64))
        if self.height_samples:
            body = self.data.xpos[self._body_id]
            ahead = self._along(body) + self._sample_offsets
            # obs_layout=segments: relative to the trunk (observation_layout scales it); whole: world z, as before
            extras.append(self.terrain_height(ahead) - body[2] if self._segments else self.terrain_height(ahead))
        if self._period is not None:
            angle = 2.0 * math.pi * self.clock_phase()
            extras.append(np.array([math.sin(angle), math.cos(angle)]))
        return np.concatenate([observation, *extras]) if extras else observation

    def observation_layout(self) -> ObservationLayout:
        """The observation's segments and how each is scaled (layout.py). env.legged.obs_layout=segments:
        proprioception (Ant-v5's: trunk height and attitude, joint angles, speeds) by the running statistics; the
        0/1 foot contacts and the clock's sin and cos as they are; the terrain heights, emitted as h - z (each
        sample's ground height less the trunk's z, m), as (h - z + H) / l clipped at +-HEIGHT_CLIP, with H the
        trunk's standing height and l the leg length, both read from the model: 0 on flat ground at standing
        height, 0.25 for a step of 0.25 l ahead, whatever the running statistics saw. whole (runs saved before
        issue 59, any env without a robot): one running segment over everything."""
        size = int(self.observation_space.shape[0])
        if not self._segments:
            return ObservationLayout.whole(size)
        feet, clock = len(self.feet) * self.observe_contacts, 2 * (self._period is not None)
        robot = self._robot
        parts = (Segment.running("proprioception", size - feet - self.height_samples - clock),
                 Segment.none("foot_contacts", feet),
                 Segment.fixed("terrain_heights", self.height_samples, -robot.height, robot.leg_length, HEIGHT_CLIP),
                 Segment.none("clock", clock))
        return ObservationLayout(tuple(p for p in parts if p.size))

    # -- what a resumed run needs beyond the simulator state -----------------------------------------
    def get_extra_state(self) -> dict:
        state = {"prev_action": self._prev_action.copy(), "air_time": self._air_time.copy(),
                 "prev_contact": self._prev_contact.copy(), "stepped": self._stepped, "clock_steps": self._clock_steps,
                 "prev_feet_xy": None if self._prev_feet_xy is None else self._prev_feet_xy.copy(),
                 # mj_step leaves body positions from the start of its last physics step, and the next step's
                 # velocity starts from them (Ant-v5's way); a restored state must start from the same ones.
                 "xpos": self.data.xpos.copy()}
        if self.has_step:
            state.update(step_height=self.step_height, step_edge=self.step_edge, level=self.level,
                         flat_episode=self._flat_episode, outcomes=list(self.outcomes), recent=list(self.recent))
        return state

    def set_extra_state(self, state: dict) -> None:
        """After the simulator state is set (envs.set_env_state): the step, the curriculum, the episode's memory."""
        self._prev_action, self._air_time = state["prev_action"].copy(), state["air_time"].copy()
        self._prev_contact, self._stepped = state["prev_contact"].copy(), state["stepped"]
        self._clock_steps = state.get("clock_steps", 0)
        self._prev_feet_xy = None if state["prev_feet_xy"] is None else state["prev_feet_xy"].copy()
        if self.has_step and "step_height" in state:
            self._place_step(state["step_height"], state["step_edge"] - self._start_along)
            self.level, self._flat_episode = state["level"], state.get("flat_episode", False)
            self.outcomes.clear()
            self.outcomes.extend(state["outcomes"])
            self.recent.clear()
            self.recent.extend(state.get("recent", state["outcomes"]))
            mujoco.mj_forward(self.model, self.data)  # contacts with the step where it now is
        if "xpos" in state:
            self.data.xpos[:] = state["xpos"]

    def gait_summary(self) -> dict:
        return self.gait.summary()

    @property
    def robot(self) -> Optional[Robot]:
        """The robot read from its model (robots/model.py: trunk, leg length, mass, feet); None for a model run as
        it is (env=mjcf)."""
        return self._robot


# ---------------------------------------------------------------- config checks (validation.py calls them)
MIN_JOINT_SPEED_LIMIT = 0.1  # rad/s; below it every joint is held still (1e-300 froze the robot)


def locomotion_checks(loco) -> list:
    """env.locomotion: limits > 0, gains and weights >= 0 (the reward terms subtract costs, add air time)."""
    def positive(key):
        value = loco.get(key)
        return value is None or value > 0, f"env.locomotion.{key}={value} must be > 0 (or null: as the model has it)"

    def non_negative(key):
        value = loco.get(key)
        return value is None or value >= 0, f"env.locomotion.{key}={value} must be >= 0"

    weights = [k for k in loco if str(k).endswith("_weight") and k not in ("forward_reward_weight", "healthy_reward")]
    speed_limit = loco.get("joint_speed_limit")
    return ([positive(k) for k in ("target_speed", "torque_limit", "base_height_target", "friction_scale",
                                   "trunk_mass_scale")]
            + [(speed_limit is None or speed_limit >= MIN_JOINT_SPEED_LIMIT,
                f"env.locomotion.joint_speed_limit={speed_limit} must be >= {MIN_JOINT_SPEED_LIMIT} rad/s "
                "(or null: as the model has it)")]
            + [(loco.get("gait_period") is None or loco.get("gait_period") > 0,
                f"env.locomotion.gait_period={loco.get('gait_period')} must be > 0 s (or null: no trot clock)")]
            + [non_negative(k) for k in ("kp", "kd", "armature", "feet_air_time_target", "long_swing_limit", *weights)])


