"""The locomotion env of MJCF robots (env=mjcf, env=quadruped, env=quadruped_step).

`LocomotionEnv` is Gymnasium's Ant-v5 class (any model through `xml_file`) with, each off unless
configured (so a config without these keys steps exactly as Ant-v5 does):

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
- **Reward terms** of legged-locomotion practice (legged_gym's set, weights per control step):
  joint torque, joint speed, joint speed past the limit (the largest excess of each joint over the
  control step's physics steps, so the impacts that eval's peak joint speed sees are paid for), action
  rate, foot slip, base height and orientation, feet air time, non-foot contacts; `target_speed` caps
  the rewarded forward speed; `only_positive_rewards` floors each step's reward at 0, as legged_gym
  does, so that while the costs outweigh the rest an early fall does not pay.
- **Terrain** (`env.terrain.*`, models with a body named `step` holding one box geom): the step's
  height and distance drawn per episode, from a range that a success-driven curriculum widens (or,
  with `curriculum_band`, a band just under the curriculum's level that it raises, for a
  `curriculum_band_share` of the episodes); `flat_share` of the training episodes on flat ground.
  The step is moved by `model.body_pos` at reset (no recompile; moving a geom of the world body
  instead leaves MuJoCo's collision bounding volumes stale). Its box reaches below the floor, so any
  height from 0 to the box's depth is a solid step. Distances (the edge, the success line, the height
  samples) run along the heading, and the box is turned to face it, so a robot built facing -x or +y
  meets the step ahead of it.
- **Termination on contact** (`terminate_on_contact`, legged_gym's): the episode also ends when a
  listed body (e.g. the trunk) touches the ground or the step. Why an episode ended is `termination`
  (also in `info`): 'contact: <body>', else is_healthy's 'fall' (under healthy_z_range), 'too high',
  'non-finite state'; None while it runs or when only the time limit ends it.
- **Observation extras** (opt-in, the policy is blind by default): one 0/1 ground-contact flag per foot;
  terrain heights at points ahead of the main body, computed from the known step geometry
  (the step's top where the point lies beyond its edge, else 0: the floor is at z = 0).
- **Gait bookkeeping** for eval (`measure_gait = True`): stride frequency, duty factor, each foot's
  share of time on the ground, touchdowns per second and longest time in the air (also counting only
  the time the robot moved forward, its previous control step at 0.1 m/s or more), for four feet at
  four corners (`foot_corners`) the share of time both feet of a pair are down (diagonal, same side,
  same end: a trot, a pace, a bound), peak joint speed and the share of time a non-foot body touches
  the ground, sampled at every physics step. A non-foot body is a robot body that holds no foot geom:
  the trunk, a thigh; not the shank that carries the foot (its capsule ends inside the foot sphere and
  touches whenever the foot sinks a millimetre into the ground).
- **Tracking camera**: a rendered model without a camera named `track` gets one on its main body.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Optional

import mujoco
import numpy as np
from gymnasium import utils
from gymnasium.envs.mujoco.ant_v5 import AntEnv
from gymnasium.spaces import Box

from ppo_torchrl.errors import ConfigError

LOCOMOTION_ID = "ppo_torchrl/Locomotion-v0"
STEP_BODY = "step"  # terrain models: the static body that holds the step's box geom
HEADINGS = {"x": 0.0, "-x": 180.0, "y": 90.0, "-y": 270.0}
MIN_AIR_S = 0.02  # gait: a touchdown counts after at least this long in the air (contact chatter is not a stride)
MOVING_SPEED = 0.1  # m/s, gait: the robot moves when its last control step went forward at least this fast
CORNERS = ("LF", "RF", "LH", "RH")  # a four-footed robot's feet: left/right, fore/hind
# gait: the foot pairs whose time down together tells the gaits apart (a trot, a pace, a bound)
FOOT_PAIRS = {"diagonal": (("LF", "RH"), ("RF", "LH")), "same_side": (("LF", "LH"), ("RF", "RH")),
              "same_end": (("LF", "RF"), ("LH", "RH"))}

# Keys of env.locomotion that LocomotionEnv takes (the others are Ant-v5's own arguments).
LEGGED_KEYS = ("heading", "target_speed", "torque_limit", "joint_speed_limit", "kp", "kd", "armature",
               "torque_cost_weight", "joint_speed_cost_weight", "joint_speed_limit_cost_weight",
               "action_rate_cost_weight", "foot_slip_cost_weight", "base_height_cost_weight", "base_height_target",
               "orientation_cost_weight", "body_contact_cost_weight", "feet_air_time_weight", "feet_air_time_target",
               "foot_geoms", "only_positive_rewards", "terminate_on_contact", "healthy_z_above_terrain",
               "gait_period", "gait_clock_weight")
TERRAIN_STEP_KEYS = ("step_height", "step_height_range", "step_distance")


def register() -> None:
    import gymnasium as gym

    if LOCOMOTION_ID not in gym.registry:
        gym.register(id=LOCOMOTION_ID, entry_point="ppo_torchrl.locomotion:LocomotionEnv", max_episode_steps=1000)


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


class GaitMeter:
    """Per episode: foot contacts and touchdowns (each foot), the time the feet of each pair of FOOT_PAIRS are down
    together, peak joint speed and time over the speed limit, non-foot ground contact, sampled each physics step.

    corners: each foot's corner (CORNERS, in the feet's order) where the robot has one foot at each; None: no
    pair figures."""

    def __init__(self, n_feet: int, speed_limit: Optional[float] = None, corners: Optional[list] = None):
        self.n_feet, self.speed_limit = n_feet, speed_limit
        self.pair_kinds = list(FOOT_PAIRS) if corners else []
        pairs = [pair for kind in self.pair_kinds for pair in FOOT_PAIRS[kind]]  # two pairs of each kind
        self._first = np.array([corners.index(a) for a, _ in pairs], np.int64)
        self._second = np.array([corners.index(b) for _, b in pairs], np.int64)
        self.reset()

    def reset(self) -> None:
        self.time = 0.0
        self.contact_time = np.zeros(self.n_feet)
        self.air_time = np.zeros(self.n_feet)
        self.longest_air = np.zeros(self.n_feet)
        self.air_moving = np.zeros(self.n_feet)  # of this time in the air, the time the robot moved
        self.longest_air_moving = np.zeros(self.n_feet)
        self.touchdowns = np.zeros(self.n_feet, np.int64)
        self.previous = None
        self.peak_joint_speed = 0.0
        self.over_limit_time = 0.0
        self.body_contact_time = 0.0
        self.pair_together_time = np.zeros(len(self._first))  # both feet of the pair down
        self.pair_down_time = np.zeros(len(self._first))  # at least one of them down

    def add(self, feet: np.ndarray, joint_speed: float, body_contact: bool, dt: float, moving: bool = True) -> None:
        if self.previous is not None:
            self.touchdowns += feet & ~self.previous & (self.air_time >= MIN_AIR_S)
        self.air_time = np.where(feet, 0.0, self.air_time + dt)
        self.longest_air = np.maximum(self.longest_air, self.air_time)
        self.air_moving = np.where(feet, 0.0, self.air_moving + dt * moving)
        self.longest_air_moving = np.maximum(self.longest_air_moving, self.air_moving)
        self.previous = feet
        self.time += dt
        self.contact_time += dt * feet
        if len(self._first):
            first, second = feet[self._first], feet[self._second]
            self.pair_together_time += dt * (first & second)
            self.pair_down_time += dt * (first | second)
        self.peak_joint_speed = max(self.peak_joint_speed, joint_speed)
        if self.speed_limit is not None and joint_speed > self.speed_limit:
            self.over_limit_time += dt
        self.body_contact_time += dt * body_contact

    def summary(self) -> dict:
        t = max(self.time, 1e-9)
        return {
            "stride_frequency": float(self.touchdowns.mean() / t) if self.n_feet else 0.0,  # Hz, per foot
            "duty_factor": float(self.contact_time.mean() / t) if self.n_feet else 0.0,  # share of time a foot is down
            "foot_contact_share": (self.contact_time / t).tolist(),  # each foot's share of time on the ground
            "touchdown_frequency": (self.touchdowns / t).tolist(),  # each foot's touchdowns per second (Hz)
            "longest_air_s": self.longest_air.tolist(),  # each foot's longest time off the ground (s)
            # the same, counting only the time the robot moved (MOVING_SPEED): a foot held up at a standstill
            # (hanging at the step's edge) does not count, a foot held up while walking does
            "longest_air_moving_s": self.longest_air_moving.tolist(),
            # each kind of pair (its two pairs pooled): the time both feet of a pair are down, and one or both
            "pair_together_time_s": {k: float(self.pair_together_time[2 * i:2 * i + 2].sum())
                                     for i, k in enumerate(self.pair_kinds)},
            "pair_down_time_s": {k: float(self.pair_down_time[2 * i:2 * i + 2].sum())
                                 for i, k in enumerate(self.pair_kinds)},
            "peak_joint_speed": float(self.peak_joint_speed),  # rad/s, actuated joints
            "time_s": float(self.time),
            "over_speed_limit_time_s": float(self.over_limit_time),  # an actuated joint over joint_speed_limit
            "body_contact_share": float(self.body_contact_time / t),  # share of time a non-foot body touches ground
        }


class LocomotionEnv(AntEnv):
    """Ant-v5 over any MJCF model, plus heading, actuation limits, reward terms, terrain and gait (module doc)."""

    # Within step, read once after the control step: the contacts (_read_contacts) and is_healthy.
    _now = None
    _healthy_now = None
    _moving = False  # the last control step went forward at MOVING_SPEED or more (gait bookkeeping)

    def __init__(self, xml_file: str, legged: Optional[dict] = None, terrain: Optional[dict] = None,
                 evaluation: bool = False, **ant_kwargs):
        legged, terrain = dict(legged or {}), dict(terrain or {})
        self._legged, self._terrain_cfg, self._evaluation = legged, terrain, evaluation
        self._add_track_camera = False
        if ant_kwargs.get("render_mode") is not None and "camera_name" not in ant_kwargs and "camera_id" not in ant_kwargs:
            probe = mujoco.MjModel.from_xml_path(str(xml_file))
            names = [probe.camera(i).name for i in range(probe.ncam)]
            self._add_track_camera = "track" not in names
            ant_kwargs["camera_name"] = "track"
        super().__init__(xml_file=xml_file, **ant_kwargs)
        utils.EzPickle.__init__(self, xml_file, legged, terrain, evaluation, **ant_kwargs)
        model, data = self.model, self.data
        self._body_id = data.body(self._main_body).id
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
        self._set_up_contacts(legged.get("foot_geoms") or [])
        self._set_up_contact_termination(legged.get("terminate_on_contact") or [])
        self._set_up_terrain(terrain, evaluation)
        self._w = {k: float(legged.get(k) or 0.0) for k in LEGGED_KEYS if k.endswith("_weight")}
        if self._w["joint_speed_limit_cost_weight"] and legged.get("joint_speed_limit") is None:
            raise ConfigError("env.locomotion.joint_speed_limit_cost_weight needs env.locomotion.joint_speed_limit")
        self._speed_limit = legged.get("joint_speed_limit")
        self._step_peak = np.zeros(len(self._act_dofs))  # each actuated joint's top |speed| in the last control step
        self._target_speed = legged.get("target_speed")
        self._positive_only = bool(legged.get("only_positive_rewards"))
        self._z_above_terrain = bool(legged.get("healthy_z_above_terrain"))
        self._air_target = float(legged.get("feet_air_time_target", 0.5))
        target = legged.get("base_height_target")
        self._height_target = self._init_z if target is None else float(target)
        self._set_up_clock(legged.get("gait_period"))
        self._needs_contacts = bool(self.observe_contacts or self._w["foot_slip_cost_weight"]
                                    or self._w["feet_air_time_weight"] or self._w["body_contact_cost_weight"]
                                    or self._w["gait_clock_weight"])
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
        if not self._add_track_camera:
            return super()._initialize_simulation()
        spec = mujoco.MjSpec.from_file(self.fullpath)
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
        if target is None:  # an unnamed main body: no camera to add; render from the free camera
            self._add_track_camera = False
            return super()._initialize_simulation()
        target.add_camera(name="track", mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM, pos=rotation.T @ offset,
                          xyaxes=np.concatenate([rotation.T @ forward, rotation.T @ y_axis]))
        model = spec.compile()
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, self.width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, self.height)
        return model, mujoco.MjData(model)

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

    def _set_up_contacts(self, names) -> None:
        model = self.model
        root = model.body_rootid[self._body_id]
        robot = [g for g in range(model.ngeom) if model.body_rootid[model.geom_bodyid[g]] == root]
        if names:
            missing = [n for n in names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) < 0]
            if missing:
                raise ConfigError(f"env.locomotion.foot_geoms: {', '.join(missing)} is not a geom of the model")
            feet = [model.geom(n).id for n in names]
        else:
            feet = [g for g in robot if "foot" in model.geom(g).name.lower()]
            if not feet:  # the geoms of the bodies that have no child body
                parents = set(model.body_parentid[1:].tolist())
                feet = [g for g in robot if model.geom_bodyid[g] not in parents]
        self.feet = np.array(feet, dtype=np.int64)
        # 1 ground (static), 2 foot, 3 a geom of a robot body that holds no foot (a "non-foot body":
        # the trunk, a thigh); 0 the rest, such as the shank capsule that ends inside the foot sphere.
        self._kind = np.zeros(model.ngeom, np.int8)
        self._kind[model.body_weldid[model.geom_bodyid] == 0] = 1
        foot_bodies = set(model.geom_bodyid[self.feet].tolist())
        self._kind[[g for g in robot if model.geom_bodyid[g] not in foot_bodies]] = 3
        self._kind[self.feet] = 2
        self._kinds = self._kind.tolist()  # the per-step lookups, without arrays
        self._foot_of = {geom: i for i, geom in enumerate(self.feet.tolist())}  # a foot geom's place in self.feet
        self._forces = np.empty_like(self.data.cfrc_ext)  # contact_cost's buffer
        self.foot_names = [model.geom(g).name or f"foot {i}" for i, g in enumerate(self.feet)]
        self.foot_corners = self._corners()

    def _corners(self) -> Optional[list]:
        """Each foot's corner (CORNERS: left or right of the feet's centre, ahead of it along the heading or
        behind) in the model's initial pose, for a robot with four feet, one at each corner; else None."""
        if len(self.feet) != 4:
            return None
        xy = self.data.geom_xpos[self.feet, :2] - self.data.geom_xpos[self.feet, :2].mean(axis=0)
        ahead, left = xy @ self.heading, xy @ np.array([-self.heading[1], self.heading[0]])
        corners = [("L" if y > 0 else "R") + ("F" if x > 0 else "H") for x, y in zip(ahead, left)]
        return corners if sorted(corners) == sorted(CORNERS) else None

    def _set_up_clock(self, period: Optional[float]) -> None:
        """The trot clock: which feet are meant to be down in each half of the period (the diagonal pairs)."""
        self._period = None if period is None else float(period)
        if self._period is None:
            if self._w["gait_clock_weight"]:
                raise ConfigError("env.locomotion.gait_clock_weight needs env.locomotion.gait_period (s)")
            return
        if self.foot_corners is None:
            raise ConfigError("env.locomotion.gait_period needs a robot with four feet, one at each corner "
                              f"(this model's feet: {', '.join(self.foot_names) or 'none'})")
        first = set(FOOT_PAIRS["diagonal"][0])
        self._first_half = np.array([c in first for c in self.foot_corners])  # down in the first half: LF, RH

    def clock_phase(self) -> Optional[float]:
        """The trot clock's phase in [0, 1) for the next step (None without a clock)."""
        return None if self._period is None else (self._clock_steps * self._dt / self._period) % 1.0

    def feet_meant_down(self) -> Optional[np.ndarray]:
        """The trot clock's schedule for the next step: a flag per foot meant to be on the ground (LF and RH in the
        first half of the period, RF and LH in the second); None without a clock."""
        phase = self.clock_phase()
        return None if phase is None else self._first_half if phase < 0.5 else ~self._first_half

    def feet_on_ground(self) -> np.ndarray:
        """A ground-contact flag per foot (in `foot_names` order), as the simulator stands now."""
        return self._contacts()[0]

    def _set_up_contact_termination(self, names) -> None:
        model = self.model
        missing = [n for n in names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) < 0]
        if missing:
            raise ConfigError(f"env.locomotion.terminate_on_contact: {', '.join(missing)} is not a body of the model")
        self._ending_geom = np.zeros(model.ngeom, bool)  # geoms whose touching the ground or the step ends an episode
        for name in names:
            self._ending_geom[model.geom_bodyid == model.body(name).id] = True
        self._ending_geom &= self._kind != 1
        self._ends_on_contact = bool(self._ending_geom.any())

    def touches_ground(self) -> bool:
        """A geom of a terminate_on_contact body touches the ground or the step."""
        return self._ending_contact() is not None

    def _ending_contact(self) -> Optional[str]:
        """The terminate_on_contact body that touches the ground or the step (the first geom's), or None."""
        if not self._ends_on_contact:
            return None
        partners = self._now[0] if self._now is not None else self._ground_partners()
        ending = partners[self._ending_geom[partners]]
        return self.model.body(self.model.geom_bodyid[ending[0]]).name if len(ending) else None

    def _set_up_terrain(self, terrain: dict, evaluation: bool) -> None:
        model = self.model
        self.observe_contacts = bool(terrain.get("observe_contacts", False))
        self.height_samples = int(terrain.get("height_samples") or 0)
        self._sample_spacing = float(terrain.get("height_sample_spacing") or 0.1)
        self._sample_offsets = self._sample_spacing * np.arange(self.height_samples)  # from main_body, along the heading
        self._step_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, STEP_BODY)
        asked = [k for k in TERRAIN_STEP_KEYS + ("eval_step_height",) if terrain.get(k) is not None]
        if terrain.get("curriculum"):
            asked.append("curriculum")
        self.has_step = self._step_id > 0
        if asked and not self.has_step:
            raise ConfigError(f"env.terrain.{asked[0]} needs a model with a body named '{STEP_BODY}' holding the step's "
                              "box: env=quadruped_step, or env.xml_file=quadruped_step.xml to put the quadruped on it")
        self.success_margin = float(terrain.get("success_margin", 0.5))
        if not self.has_step:
            return
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == self._step_id]
        if len(geoms) != 1 or model.geom_type[geoms[0]] != mujoco.mjtGeom.mjGEOM_BOX:
            raise ConfigError(f"the model's body '{STEP_BODY}' must hold one box geom (the step)")
        g = geoms[0]
        self._half = model.geom_size[g].copy()  # the box's half sizes
        self._box_offset = model.geom_pos[g].copy()
        # Distances run along the heading: the step's edge, the success line and the height samples
        # are coordinates on that ground axis (world x for heading x).
        self._start_along = self._along(self.data.xpos[self._body_id])
        self._step_pos0 = model.body_pos[self._step_id].copy()
        self.step_height, self.step_edge = self._read_step()
        self.model_step = (self.step_height, self.step_edge - self._start_along)  # as the model file has it
        # The step box turned so that its own x runs along the heading (its extent to the side stays
        # what the file gives, 100 m in quadruped_step.xml), and moved along the heading from then on.
        half_angle = 0.5 * math.atan2(self.heading[1], self.heading[0])
        model.body_quat[self._step_id] = [math.cos(half_angle), 0.0, 0.0, math.sin(half_angle)]
        self._side = np.array([-self.heading[1], self.heading[0]])
        fixed = terrain.get("step_height")
        if evaluation and fixed is None:
            fixed = terrain.get("eval_step_height")
        self._fixed_height = None if fixed is None else float(fixed)
        span = terrain.get("step_height_range")
        self._height_range = None if span is None else (float(span[0]), float(span[1]))
        self._curriculum = bool(terrain.get("curriculum")) and self._fixed_height is None and not evaluation
        if self._curriculum and self._height_range is None:
            raise ConfigError("env.terrain.curriculum=true needs env.terrain.step_height_range=[min, max]")
        distance = terrain.get("step_distance")
        self._distance_range = None if distance is None else (float(distance[0]), float(distance[1]))
        # Without any of these the step stays exactly where the model file puts it.
        self._moves_step = (self._fixed_height is not None or self._height_range is not None
                            or self._distance_range is not None)
        self.level = self._height_range[0] if self._height_range else self.step_height  # curriculum: the range's top now
        self._level_step = float(terrain.get("curriculum_step") or 0.02)
        self._threshold = float(terrain.get("curriculum_threshold") or 0.8)
        band = terrain.get("curriculum_band")
        self._band = None if band is None else float(band)
        share = terrain.get("curriculum_band_share")
        self._band_share = 1.0 if share is None else float(share)
        self._flat_share = 0.0 if evaluation else float(terrain.get("flat_share") or 0.0)
        self._flat_episode = False  # this episode's step was put at 0 by flat_share (not a curriculum outcome)
        down = terrain.get("curriculum_down_threshold")
        self._down_threshold = None if down is None else float(down)
        self.outcomes = deque(maxlen=int(terrain.get("curriculum_window") or 20))
        self.recent = deque(maxlen=self.outcomes.maxlen)  # the same outcomes, kept across level changes (logged)
        depth = 2 * self._half[2]
        top = max([self._fixed_height or 0.0, *(self._height_range or ())])
        if top > depth:
            raise ConfigError(f"env.terrain: a step of {top} m is taller than the model's step box is deep ({depth} m)")

    def _along(self, xyz) -> float:
        """A world position's coordinate along the heading (x for heading x)."""
        return float(xyz[0] * self.heading[0] + xyz[1] * self.heading[1])

    def _read_step(self) -> tuple:
        """The model file's step (a box with its axes along the world's): its top and near edge along the heading."""
        pos = self.model.body_pos[self._step_id] + self._box_offset
        reach = abs(self.heading[0]) * self._half[0] + abs(self.heading[1]) * self._half[1]
        return float(pos[2] + self._half[2]), self._along(pos) - float(reach)

    def _place_step(self, height: float, distance: float) -> None:
        edge = self._start_along + distance
        # the box's own x is the heading (body_quat), so its offset in the body moves the box along it
        along = edge + self._half[0] - self._box_offset[0]
        xy = along * self.heading + (self._side @ self._step_pos0[:2]) * self._side
        self.model.body_pos[self._step_id] = [xy[0], xy[1], height - self._half[2] - self._box_offset[2]]
        self.step_height, self.step_edge = height, edge

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

    def _draw_step(self) -> None:
        rng = self.np_random
        # (share 0 draws nothing extra, so runs without the knob keep their random stream)
        self._flat_episode = (self._fixed_height is None and self._height_range is not None
                              and self._flat_share > 0 and rng.uniform() < self._flat_share)
        if self._fixed_height is not None:
            height = self._fixed_height
        elif self._flat_episode:
            height = 0.0
        elif self._height_range is not None:
            low, high = self._height_range
            if self._curriculum:
                # (share 1 draws nothing extra, so runs without the knob keep their random stream)
                if self._band is not None and (self._band_share >= 1 or rng.uniform() < self._band_share):
                    low = max(low, self.level - self._band)
                high = self.level
            height = float(rng.uniform(low, high))
        else:
            height = self.model_step[0]
        distance = float(rng.uniform(*self._distance_range)) if self._distance_range else self.model_step[1]
        self._place_step(height, distance)

    def _record_outcome(self, success: bool) -> None:
        """The curriculum: widen [min, level] by curriculum_step once the success rate of a full window
        reaches the threshold; narrow it by as much when it falls to the down threshold (if set)."""
        self.outcomes.append(bool(success))
        self.recent.append(bool(success))
        if len(self.outcomes) < self.outcomes.maxlen:
            return
        rate = np.mean(self.outcomes)
        if rate >= self._threshold:
            self.level = min(self.level + self._level_step, self._height_range[1])
            self.outcomes.clear()
        elif self._down_threshold is not None and rate <= self._down_threshold:
            self.level = max(self.level - self._level_step, self._height_range[0])
            self.outcomes.clear()

    def terrain_metrics(self) -> dict:
        """What a training run logs of its curriculum: the top of the height range now (m) and the share of
        the last curriculum_window episodes that crossed; {} without a curriculum (evaluation included)."""
        if not (self.has_step and self._curriculum):
            return {}
        return {"env/terrain_level": self.level, "env/terrain_success": float(np.mean(self.recent)) if self.recent else 0.0}

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

    def crossed(self) -> bool:
        """Success on a step env: the main body is success_margin beyond the step's edge."""
        return self._along(self.data.xpos[self._body_id]) >= self.step_edge + self.success_margin

    def _ground_under_body(self) -> float:
        """The terrain's height under main_body (m)."""
        if not self.has_step:  # terrain_height for one point, without an array (once or twice a step)
            return 0.0
        return float(self.step_height) if self._along(self.data.xpos[self._body_id]) >= self.step_edge else 0.0

    def terrain_height(self, x: np.ndarray) -> np.ndarray:
        """Ground height at coordinate x along the heading (the step's top beyond its edge, else the floor at 0)."""
        if not self.has_step:
            return np.zeros_like(x)
        return np.where(x >= self.step_edge, self.step_height, 0.0)

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
                self.gait.add(feet, float(speeds.max()) if len(speeds) else 0.0, body > 0, model.opt.timestep,
                              self._moving)
        self._step_peak = peak
        mujoco.mj_rnePostConstraint(model, data)

    def _ground_partners(self) -> np.ndarray:
        """The geoms in contact with the ground or the step (one entry per contact, in contact order)."""
        kinds = self._kinds  # a handful of contacts: Python over their list beats numpy's per-call cost
        return np.array([b if kinds[a] == 1 else a for a, b in self.data.contact.geom.tolist()
                         if kinds[a] == 1 or kinds[b] == 1], np.int64)

    def _read_contacts(self) -> tuple:
        """(the geoms touching the ground or the step, a ground-contact flag per foot, the number of
        geoms of non-foot bodies among them), as the simulator stands now."""
        feet, body = np.zeros(len(self.feet), bool), set()
        partners = self._ground_partners()
        for geom in partners.tolist():
            kind = self._kinds[geom]
            if kind == 2:
                feet[self._foot_of[geom]] = True
            elif kind == 3:
                body.add(geom)
        return partners, feet, len(body)

    def _contacts(self) -> tuple:
        """(a ground-contact flag per foot, the number of geoms of non-foot bodies touching the ground):
        within `step`, its one reading after the control step; elsewhere read now."""
        _, feet, body = self._now if self._now is not None else self._read_contacts()
        return feet, body

    def step(self, action):
        self._now = self._healthy_now = None
        xy_before = self.data.xpos[self._body_id, :2].copy()
        self.do_simulation(action, self.frame_skip)
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

    def _get_rew(self, speed: float, action):
        if self._target_speed is not None:
            speed = min(speed, self._target_speed)
        return super()._get_rew(speed, action)

    # Ant-v5's two costs, the same floats with fewer numpy calls (they run at every control step)
    def control_cost(self, action):
        return self._ctrl_cost_weight * np.square(action).sum()

    @property
    def contact_cost(self):
        low, high = self._contact_force_range  # np.clip's values, clipped in place in a buffer
        forces = np.maximum(self.data.cfrc_ext, low, out=self._forces)
        return self._contact_cost_weight * np.square(np.minimum(forces, high, out=forces), out=forces).sum()

    def _legged_terms(self, action) -> tuple:
        """The legged-locomotion reward terms whose weight is not 0: (their sum, each term signed)."""
        w, data, terms = self._w, self.data, {}
        if w["torque_cost_weight"]:
            terms["reward_torque"] = -w["torque_cost_weight"] * float(np.square(data.actuator_force).sum())
        if w["joint_speed_cost_weight"]:
            terms["reward_joint_speed"] = -w["joint_speed_cost_weight"] * float(np.square(data.qvel[self._act_qvel]).sum())
        if w["joint_speed_limit_cost_weight"]:
            excess = np.maximum(self._step_peak - self._speed_limit, 0.0)
            terms["reward_joint_speed_limit"] = -w["joint_speed_limit_cost_weight"] * float(excess.sum())
        if w["action_rate_cost_weight"]:
            terms["reward_action_rate"] = -w["action_rate_cost_weight"] * float(np.square(action - self._prev_action).sum())
        self._prev_action = np.asarray(action, dtype=np.float64).copy()
        body = data.xpos[self._body_id]
        if w["base_height_cost_weight"]:
            height = body[2] - self._ground_under_body()
            terms["reward_base_height"] = -w["base_height_cost_weight"] * (height - self._height_target) ** 2
        if w["orientation_cost_weight"]:
            up = data.xmat[self._body_id].reshape(3, 3)[2] @ self._up0  # cos(tilt from the initial attitude)
            terms["reward_orientation"] = -w["orientation_cost_weight"] * (1.0 - float(up))
        if self._needs_contacts:
            feet, body_contacts = self._contacts()
            feet_xy = data.geom_xpos[self.feet, :2]
            if w["foot_slip_cost_weight"]:
                slip = np.square((feet_xy - self._prev_feet_xy) / self._dt).sum(axis=1)
                terms["reward_foot_slip"] = -w["foot_slip_cost_weight"] * float(slip[feet].sum())
            if w["feet_air_time_weight"]:
                touchdown = feet & (self._air_time > 0)
                terms["reward_air_time"] = w["feet_air_time_weight"] * float(
                    ((self._air_time - self._air_target) * touchdown).sum())
            if w["body_contact_cost_weight"]:
                terms["reward_body_contact"] = -w["body_contact_cost_weight"] * body_contacts
            if w["gait_clock_weight"]:  # the phase this step was taken in
                meant = self.feet_meant_down()
                terms["reward_gait_clock"] = w["gait_clock_weight"] * float(np.count_nonzero(feet == meant) / len(feet))
            self._air_time = np.where(feet, 0.0, self._air_time + self._dt)
            self._prev_contact = feet
            self._prev_feet_xy = feet_xy.copy()
        return sum(terms.values()), terms

    def _get_obs(self):
        observation = super()._get_obs()
        extras = []
        if self.observe_contacts:
            extras.append(self._contacts()[0].astype(np.float64))
        if self.height_samples:
            body = self.data.xpos[self._body_id]
            ahead = self._along(body) + self._sample_offsets
            extras.append(self.terrain_height(ahead))
        if self._period is not None:
            angle = 2.0 * math.pi * self.clock_phase()
            extras.append(np.array([math.sin(angle), math.cos(angle)]))
        return np.concatenate([observation, *extras]) if extras else observation

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
    return ([positive(k) for k in ("target_speed", "torque_limit", "base_height_target")]
            + [(speed_limit is None or speed_limit >= MIN_JOINT_SPEED_LIMIT,
                f"env.locomotion.joint_speed_limit={speed_limit} must be >= {MIN_JOINT_SPEED_LIMIT} rad/s "
                "(or null: as the model has it)")]
            + [(loco.get("gait_period") is None or loco.get("gait_period") > 0,
                f"env.locomotion.gait_period={loco.get('gait_period')} must be > 0 s (or null: no trot clock)")]
            + [non_negative(k) for k in ("kp", "kd", "armature", "feet_air_time_target", *weights)])


def terrain_checks(terrain) -> list:
    """env.terrain: heights >= 0, [min, max] ranges with min <= max, a threshold in (0, 1], counts >= 1."""
    if terrain is None:
        return []

    def span(key, low_ok):
        value = terrain.get(key)
        if value is None:
            return True, ""
        value = list(value)
        ok = len(value) == 2 and low_ok(value[0]) and value[0] <= value[1]
        floor = "0 <= min" if key == "step_height_range" else "0 < min"
        return ok, f"env.terrain.{key}={value} must be [min, max] with {floor} <= max (m)"

    height, eval_height = terrain.get("step_height"), terrain.get("eval_step_height")
    return [
        (height is None or height >= 0, f"env.terrain.step_height={height} must be >= 0 (m)"),
        (eval_height is None or eval_height >= 0, f"env.terrain.eval_step_height={eval_height} must be >= 0 (m)"),
        span("step_height_range", lambda low: low >= 0),
        span("step_distance", lambda low: low > 0),
        (0 < terrain.curriculum_threshold <= 1,
         f"env.terrain.curriculum_threshold={terrain.curriculum_threshold} must be in (0, 1]: a success rate"),
        (terrain.curriculum_window >= 1, f"env.terrain.curriculum_window={terrain.curriculum_window} must be >= 1"),
        (terrain.curriculum_step > 0, f"env.terrain.curriculum_step={terrain.curriculum_step} must be > 0 (m)"),
        (terrain.curriculum_down_threshold is None or 0 <= terrain.curriculum_down_threshold < terrain.curriculum_threshold,
         f"env.terrain.curriculum_down_threshold={terrain.curriculum_down_threshold} must be in "
         f"[0, curriculum_threshold={terrain.curriculum_threshold}): a success rate"),
        (terrain.get("curriculum_band") is None or terrain.curriculum_band > 0,
         f"env.terrain.curriculum_band={terrain.get('curriculum_band')} must be > 0 (m) or null"),
        (0 <= terrain.curriculum_band_share <= 1,
         f"env.terrain.curriculum_band_share={terrain.curriculum_band_share} must be in [0, 1]: a share of episodes"),
        (0 <= terrain.flat_share <= 1, f"env.terrain.flat_share={terrain.flat_share} must be in [0, 1]: a share of episodes"),
        (not terrain.curriculum or terrain.step_height_range is not None,
         "env.terrain.curriculum=true needs env.terrain.step_height_range=[min, max] to widen"),
        (terrain.success_margin >= 0, f"env.terrain.success_margin={terrain.success_margin} must be >= 0 (m)"),
        (terrain.height_samples >= 0, f"env.terrain.height_samples={terrain.height_samples} must be >= 0"),
        (terrain.height_sample_spacing > 0,
         f"env.terrain.height_sample_spacing={terrain.height_sample_spacing} must be > 0 (m)"),
    ]
