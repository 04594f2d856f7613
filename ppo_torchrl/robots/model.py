"""A legged robot read from its MuJoCo model (env=legged): everything robot-specific the recipe needs,
derived from the MJCF and nothing else.

- **Standing pose**: the keyframe named by env.legged.keyframe, else `home` when the model has one,
  else qpos0; the trunk's height there.
- **Trunk**: the body of the free joint that carries the actuators.
- **Legs**: the chains of actuated hinge joints under each child body of the trunk, root to tip; a
  leg's hip-flexion joint is its second-last, its knee its last.
- **Feet**: in each leg's last body (the deepest; the lowest where a leg forks), its colliding geom
  whose name holds 'foot', else its lowest colliding sphere, else its lowest colliding geom.
- **Heading**: the trunk's +x axis at the standing pose, on the ground (the convention of robot
  descriptions: x forward). **Corners** (LF, RF, LH, RH): each foot left or right of the feet's
  centre and ahead of it or behind, along that heading.
- **Drives**: position servos as the model has them (their kp, kv and force range). Torque motors
  become PD servos around the standing pose, built in MuJoCo's own position actuator (so the PD is
  integrated with the physics, not in Python): kp = the motor's peak torque / PD_SATURATION_RAD (the
  motor saturates at that angle error; Menagerie's position servos saturate at 0.24-0.4 rad), kd =
  2 sqrt(kp I), critical damping of the joint's own inertia I at the standing pose (the mass matrix's
  diagonal, armature included); the force range is the motor's.
- **Action scale**: a full action moves each joint's target by env.legged.action_scale, or (with
  env.legged.saturation_cap) by its servo's saturation angle (peak torque / kp) where that is smaller
  (`Robot.action_scales`).
- **Size**: leg length l, thigh plus shank (hip-flexion joint to knee joint to foot centre, whatever
  the pose), the mean over the legs; mass, the sum of the robot's bodies.
- **Contacts** (`filter_contacts`, env.legged.contacts=terrain): the robot's geoms touch the terrain (the
  geoms of bodies welded to the world: the floor, the step) and nothing else; robot-robot contacts only
  where the model asks for them by name (its `<pair>` elements; MuJoCo's default contype = conaffinity = 1
  on every geom is no such request). env.legged.contacts=model: as the model has them.

A model that cannot be read this way is one ConfigError line: no free joint, no floor (a colliding geom
fixed to the world: a robot file without its scene), not four legs with a foot each, feet not one at each
corner, an unknown keyframe, an actuator on no joint, an actuator that is neither a position servo nor a
torque motor.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import mujoco
import numpy as np

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.robots.gait import CORNERS

DEFAULT_KEYFRAME = "home"  # Menagerie's name for the standing pose
PD_SATURATION_RAD = 0.3  # torque motors: the joint-angle error at which the derived PD servo reaches peak torque
GRAVITY = 9.81


@dataclass(frozen=True)
class Robot:
    """What env=legged knows of a robot, all of it read from the model (module doc). Ids are the compiled
    model's; sequences are per leg (feet, corners, leg lengths) or per actuator (the drives)."""

    name: str  # the model's name (go1), for run dirs and start lines
    path: str
    trunk: str  # the body of the free joint
    keyframe: Optional[str]  # the standing pose's keyframe; None: qpos0
    qpos: tuple  # the standing pose
    height: float  # the trunk's z there (m)
    feet: tuple  # geom ids, one per leg
    foot_names: tuple  # their names, or '<body> foot' where a geom has none
    corners: tuple  # each foot's corner (CORNERS)
    heading: tuple  # the ground direction the trunk faces (unit x, y)
    leg_length: float  # m, thigh + shank
    leg_lengths: tuple
    mass: float  # kg
    drive: tuple  # per actuator: 'position' (the model's servo) or 'motor' (a PD servo derived here)
    kp: tuple  # N m/rad per actuator, as driven (derived for motors)
    kd: tuple  # N m s/rad
    peak_torque: tuple  # N m per actuator: its force range, else its joint's, else inf
    home_angle: tuple  # each actuator's joint angle at the standing pose (rad)
    gear: tuple
    timestep: float  # s, the model's physics step
    inertia: tuple  # kg m^2 per actuator: its joint's at the standing pose (mass matrix diagonal, armature included)
    time_constant: float  # s: the shortest of the robot's contacts and joint limits (solref[0]; _time_constant)
    implicit_damping: bool  # the model's integrator takes the servos' damping implicitly (implicit, implicitfast)

    def action_scales(self, most: float, cap: bool = True) -> tuple:
        """Per actuator, the angle (rad) a full action moves its joint's target from the standing pose: `most`
        (env.legged.action_scale), or with `cap` less where the servo saturates sooner, at its peak torque / kp
        (a larger offset asks for torque the drive does not have; but it also bounds how far a joint can go)."""
        return tuple(min(most, peak / kp) if cap and kp > 0 else most for peak, kp in zip(self.peak_torque, self.kp))

    @property
    def servo_rate(self) -> float:
        """rad/s: the stiffest servo's natural frequency, sqrt(kp / I) on its joint's own inertia (the fastest
        motion the drives make; a leg on the ground moves more mass, so slower)."""
        return max(math.sqrt(kp / i) for kp, i in zip(self.kp, self.inertia))

    @property
    def damping_rate(self) -> float:
        """1/s: the largest servo damping per inertia, kd / I."""
        return max(kd / i for kd, i in zip(self.kd, self.inertia))

    @property
    def speed_scale(self) -> float:
        """sqrt(g l): the robot's natural speed (m/s); speeds in the recipe are multiples of it."""
        return math.sqrt(GRAVITY * self.leg_length)

    @property
    def time_scale(self) -> float:
        """sqrt(l / g): the robot's natural time (s); periods in the recipe are multiples of it."""
        return math.sqrt(self.leg_length / GRAVITY)

    def describe(self) -> str:
        """The start line's account of what was read (env=legged)."""
        drives = sorted(set(self.drive))
        finite = [t for t in self.peak_torque if math.isfinite(t)]
        torque = f"{min(finite):g}-{max(finite):g} N m" if finite else "no limit"
        return (f"robot {self.name}: {self.mass:.1f} kg, leg {self.leg_length:.3f} m, trunk {self.trunk} at "
                f"{self.height:.3f} m ({'keyframe ' + self.keyframe if self.keyframe else 'qpos0'}), heading "
                f"({self.heading[0]:+.2f}, {self.heading[1]:+.2f}), feet "
                + ", ".join(f"{c}={n}" for c, n in zip(self.corners, self.foot_names))
                + f", drives {'/'.join(drives)} (peak {torque})")


def model_name(model: mujoco.MjModel, path: Path) -> str:
    """go1 for a model named 'go1 scene' (Menagerie's scenes) or 'go1'; the file's name (its folder's for a
    scene.xml) when the model has no name of its own."""
    raw = model.names[:model.names.index(b"\0")].decode() if model.names else ""
    words = [w for w in re.split(r"[\s_]+", raw.strip().lower()) if w and w != "scene"]
    if raw.strip() in ("", "MuJoCo Model") or not words:
        return path.parent.name if path.stem == "scene" else path.stem
    return re.sub(r"[^a-z0-9_.-]", "", "_".join(words)) or path.stem


def _actuator_drive(model, a: int, where: str) -> str:
    if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
        raise ConfigError(f"{where}: actuator '{model.actuator(a).name or a}' drives no joint (transmission "
                          f"{mujoco.mjtTrn(model.actuator_trntype[a]).name}); env=legged drives joints")
    gain, bias = model.actuator_gainprm[a], model.actuator_biasprm[a]
    if (model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE and gain[0] > 0
            and np.isclose(bias[1], -gain[0])):
        return "position"
    if model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE and model.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED:
        return "motor"
    raise ConfigError(f"{where}: actuator '{model.actuator(a).name or a}' is neither a position servo nor a torque "
                      "motor; env=legged drives one or the other")


def _peak_torque(model, a: int, drive: str) -> float:
    gear, joint = abs(float(model.actuator_gear[a, 0])) or 1.0, model.actuator_trnid[a, 0]
    if model.actuator_forcelimited[a]:
        return float(np.abs(model.actuator_forcerange[a]).max()) * gear
    if drive == "motor" and model.actuator_ctrllimited[a]:
        return float(np.abs(model.actuator_ctrlrange[a]).max() * model.actuator_gainprm[a, 0]) * gear
    if model.jnt_actfrclimited[joint]:
        return float(np.abs(model.jnt_actfrcrange[joint]).max())
    return math.inf


def _depth(model, body: int) -> int:
    depth = 0
    while body:
        body, depth = model.body_parentid[body], depth + 1
    return depth


def _colliding(model, geom: int) -> bool:
    return bool(model.geom_contype[geom] or model.geom_conaffinity[geom])


def _foot(model, data, bodies: list, where: str, leg: str) -> int:
    """The foot of a leg whose bodies are `bodies` (module doc's rule)."""
    deepest = max(_depth(model, b) for b in bodies)
    last = min((b for b in bodies if _depth(model, b) == deepest), key=lambda b: data.xpos[b, 2])
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == last and _colliding(model, g)]
    if not geoms:
        raise ConfigError(f"{where}: leg {leg} has no colliding geom in its last body "
                          f"'{model.body(last).name}' to stand on")
    named = [g for g in geoms if "foot" in model.geom(g).name.lower()]
    if len(named) == 1:
        return named[0]
    spheres = [g for g in geoms if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
    return min(spheres or geoms, key=lambda g: data.geom_xpos[g, 2] - model.geom_rbound[g])


def read_robot(path, keyframe: Optional[str] = None) -> Robot:
    """The robot of the model file at `path` (a robot or a scene that includes one), read as the module doc
    says; the standing pose from `keyframe` (else 'home', else qpos0). One ConfigError line where it
    cannot be read."""
    return _read_robot(str(Path(path).resolve()), keyframe)


@functools.lru_cache(maxsize=32)
def _read_robot(path: str, keyframe: Optional[str]) -> Robot:
    where = f"env.xml_file={path}"
    try:
        model = mujoco.MjModel.from_xml_path(path)
    except ValueError as exc:
        first = next((l.strip() for l in str(exc).splitlines() if l.strip()), type(exc).__name__)
        raise ConfigError(f"{where} is not a valid MuJoCo model: {first}") from None
    name = model_name(model, Path(path))
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if not free:
        raise ConfigError(f"{where}: {name} has no free joint; env=legged needs a free-floating trunk "
                          "(<freejoint/> in the robot's root body)")
    if model.nu == 0:
        raise ConfigError(f"{where}: {name} has no actuators")
    drive = [_actuator_drive(model, a, where) for a in range(model.nu)]
    joints = [int(model.actuator_trnid[a, 0]) for a in range(model.nu)]
    roots = {int(model.body_rootid[model.jnt_bodyid[j]]) for j in joints}
    trunk = next((int(model.jnt_bodyid[j]) for j in free if int(model.jnt_bodyid[j]) in roots),
                 int(model.jnt_bodyid[free[0]]))

    data = mujoco.MjData(model)
    keys = [model.key(k).name for k in range(model.nkey)]
    if keyframe is not None and keyframe not in keys:
        raise ConfigError(f"env.legged.keyframe={keyframe}: {name} has no keyframe '{keyframe}' (its keyframes: "
                          f"{', '.join(k or '<unnamed>' for k in keys) or 'none'})")
    key = keyframe if keyframe is not None else DEFAULT_KEYFRAME if DEFAULT_KEYFRAME in keys else None
    if key is None:
        mujoco.mj_resetData(model, data)
    else:
        mujoco.mj_resetDataKeyframe(model, data, keys.index(key))
    mujoco.mj_forward(model, data)

    # legs: the trunk's child bodies under which actuated hinge joints hang
    def leg_of(body: int) -> int:
        while model.body_parentid[body] != trunk:
            if body == 0:
                return -1
            body = model.body_parentid[body]
        return body

    legs: dict = {}
    for j in joints:
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and leg_of(model.jnt_bodyid[j]) > 0:
            legs.setdefault(leg_of(model.jnt_bodyid[j]), []).append(j)
    if len(legs) != 4 or any(len(chain) < 2 for chain in legs.values()):
        raise ConfigError(f"{where}: {name} has {len(legs)} legs of actuated hinge joints under its trunk "
                          f"'{model.body(trunk).name}' (each with a hip and a knee); env=legged needs four feet")
    feet, lengths = [], []
    for top, chain in legs.items():
        chain.sort(key=lambda j: (_depth(model, model.jnt_bodyid[j]), j))
        bodies = [b for b in range(model.nbody) if leg_of(b) == top]
        foot = _foot(model, data, bodies, where, model.body(top).name)
        hip, knee = data.xanchor[chain[-2]], data.xanchor[chain[-1]]
        lengths.append(float(np.linalg.norm(knee - hip) + np.linalg.norm(data.geom_xpos[foot] - knee)))
        feet.append(foot)

    axis = data.xmat[trunk].reshape(3, 3)[:2, 0]
    if np.linalg.norm(axis) < 1e-6:
        raise ConfigError(f"{where}: {name}'s trunk points straight up or down at its standing pose: no heading")
    heading = axis / np.linalg.norm(axis)
    xy = data.geom_xpos[feet, :2] - data.geom_xpos[feet, :2].mean(axis=0)
    ahead, left = xy @ heading, xy @ np.array([-heading[1], heading[0]])
    corners = [("L" if y > 0 else "R") + ("F" if x > 0 else "H") for x, y in zip(ahead, left)]
    if sorted(corners) != sorted(CORNERS):
        raise ConfigError(f"{where}: {name}'s feet are not one at each corner of the trunk ({', '.join(corners)})")
    order = sorted(range(4), key=lambda i: CORNERS.index(corners[i]))  # LF, RF, LH, RH
    feet = [feet[i] for i in order]

    kp, kd, peak, inertia = [], [], [], []
    for a, j in enumerate(joints):
        peak.append(_peak_torque(model, a, drive[a]))
        unit, column = np.zeros(model.nv), np.zeros(model.nv)
        unit[model.jnt_dofadr[j]] = 1.0
        mujoco.mj_mulM(model, data, column, unit)  # the mass matrix's column: its diagonal, armature included
        inertia.append(float(column[model.jnt_dofadr[j]]))
        if drive[a] == "position":  # on length gear x q: joint gains are the actuator's x gear^2
            gear2 = float(model.actuator_gear[a, 0]) ** 2
            kp.append(float(model.actuator_gainprm[a, 0]) * gear2)
            kd.append(abs(float(model.actuator_biasprm[a, 2])) * gear2)
        else:
            if not math.isfinite(peak[-1]):
                raise ConfigError(f"{where}: torque motor '{model.actuator(a).name or a}' has no torque limit "
                                  "(ctrlrange, forcerange or its joint's actuatorfrcrange): no PD gain can be derived")
            gain = peak[-1] / PD_SATURATION_RAD
            kp.append(gain)
            kd.append(2.0 * math.sqrt(gain * inertia[-1]))
    if not any(_colliding(model, g) and model.body_weldid[model.geom_bodyid[g]] == 0 for g in range(model.ngeom)):
        scene = Path(path).with_name("scene.xml")  # Menagerie's layout: the robot file beside the scene that holds it
        then = (f"give the scene beside it, env.xml_file={scene}" if scene.is_file() and str(scene) != path else
                'add one to its <worldbody>, e.g. <geom type="plane" size="0 0 0.05"/>')
        raise ConfigError(f"{where}: {name}'s model has no floor (no colliding geom fixed to the world), so the robot "
                          f"would fall through the world; {then}")
    subtree = [b for b in range(model.nbody) if model.body_rootid[b] == model.body_rootid[trunk]]
    return Robot(
        name=name, path=path, trunk=model.body(trunk).name, keyframe=key,
        qpos=tuple(float(q) for q in data.qpos), height=float(data.xpos[trunk, 2]),
        feet=tuple(int(f) for f in feet),
        foot_names=tuple(model.geom(f).name or f"{model.body(model.geom_bodyid[f]).name} foot" for f in feet),
        corners=tuple(CORNERS), heading=(float(heading[0]), float(heading[1])),
        leg_length=float(np.mean(lengths)), leg_lengths=tuple(lengths[i] for i in order),
        mass=float(model.body_mass[subtree].sum()), drive=tuple(drive), kp=tuple(kp), kd=tuple(kd),
        peak_torque=tuple(peak), home_angle=tuple(float(data.qpos[model.jnt_qposadr[j]]) for j in joints),
        gear=tuple(float(model.actuator_gear[a, 0]) or 1.0 for a in range(model.nu)),
        timestep=float(model.opt.timestep), inertia=tuple(inertia), time_constant=_time_constant(model, subtree),
        implicit_damping=model.opt.integrator in (mujoco.mjtIntegrator.mjINT_IMPLICIT,
                                                  mujoco.mjtIntegrator.mjINT_IMPLICITFAST))


def _time_constant(model, robot_bodies: list) -> float:
    """The shortest time constant (solref[0], s; MuJoCo's standard form, solref[0] > 0) of the constraints a
    locomotion step makes: contacts of the robot's colliding geoms and the world's, the robot's joint limits."""
    bodies = set(robot_bodies) | {0}
    geoms = [g for g in range(model.ngeom) if _colliding(model, g)
             and (model.geom_bodyid[g] in bodies or model.body_weldid[model.geom_bodyid[g]] == 0)]
    limits = [j for j in range(model.njnt) if model.jnt_limited[j] and model.jnt_bodyid[j] in bodies]
    refs = [model.geom_solref[g, 0] for g in geoms] + [model.jnt_solref[j, 0] for j in limits]
    return float(min([r for r in refs if r > 0] or [mujoco.MjOption().o_solref[0]]))


CONTACT_MODES = ("terrain", "model")  # env.legged.contacts (module doc)
TERRAIN_BIT = 1 << 30  # the contype bit of the robot's geoms and, in conaffinity, of the terrain's (filter_contacts)


def filter_contacts(spec) -> tuple:
    """Makes the robot's geoms touch the terrain only (module doc), in a model being built (mujoco.MjSpec,
    after any terrain is added): the terrain, every colliding geom of a body welded to the world, gets
    TERRAIN_BIT in its conaffinity; each robot geom (a body under a free joint) that could touch some terrain
    geom gets contype TERRAIN_BIT and conaffinity 0, the others contype = conaffinity = 0. MuJoCo makes a
    contact where (contype1 & conaffinity2) | (contype2 & conaffinity1): robot-terrain pairs pass, robot-robot
    pairs never do (a robot geom's conaffinity is 0); the model's <pair> elements bypass these bits and stay,
    as do its excludes. Returns (robot geoms left colliding, robot geoms made non-colliding) for the start line.
    (spec.bodies lists the bodies in the compiled model's order, the world first.)"""
    plain = spec.compile()
    static = plain.body_weldid == 0  # per body
    free_roots = {plain.body_rootid[plain.jnt_bodyid[j]] for j in range(plain.njnt)
                  if plain.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE}
    terrain, robot = [], []
    for b, body in enumerate(spec.bodies):
        for geom in body.geoms:
            if not (geom.contype or geom.conaffinity):
                continue
            if static[b]:
                terrain.append(geom)
            elif plain.body_rootid[b] in free_roots:
                robot.append(geom)
    kept = dropped = 0
    for geom in robot:
        touches = any((geom.contype & t.conaffinity) or (t.contype & geom.conaffinity) for t in terrain)
        geom.contype, geom.conaffinity = (TERRAIN_BIT if touches else 0), 0
        kept, dropped = kept + touches, dropped + (not touches)
    for geom in terrain:
        geom.conaffinity |= TERRAIN_BIT
    return kept, dropped


def robot_label(path) -> str:
    """A run's name for a model file: the model's name (go1 for Menagerie's unitree_go1/scene.xml), else the
    file's stem; never an error (run dirs are named before the config is checked). Read once per process:
    a run's summary names its env at every iteration."""
    return _robot_label(str(path))


@functools.lru_cache(maxsize=32)
def _robot_label(path: str) -> str:
    path = Path(path)
    try:
        return model_name(mujoco.MjModel.from_xml_path(str(path)), path)
    except Exception:  # noqa: BLE001 - a bad file is reported by the config check, with its reason
        return path.stem
