"""A legged task composed of parts: the robot's world (world.py), a terrain (terrain.py), a command (commands.py),
the contact sensors (sensors.py), the episode memory (memory.py) and the named reward terms (rewards.py). Given
what the physics left in each row (`Reading`), it computes the observation, the reward and each term, and why an
episode ends, as arrays over the rows; the batched env (batch.py) steps the physics and resets the rows.

The observation: Gymnasium Ant-v5's (the trunk's height and attitude, the joint angles, all velocities; with
env.legged.obs_frame=heading the attitude and linear velocity with the trunk's yaw taken out, `heading_frame`; the
clipped contact forces where asked), then the opt-in extras: a 0/1 contact flag per foot, terrain heights at
points ahead of the trunk along the heading (relative to the trunk with env.legged.obs_layout=segments), the
command's segment, the trot clock's sin and cos. `layout()` says how each segment is scaled (layout.py).

The privileged observation (policy.critic_obs=privileged: the asymmetric critic's input, never the actor's): the
observation as it is, before the randomization's noise, then what a robot cannot sense but the simulator knows,
each in the robot's units: a 0/1 flag per foot on the ground, each foot's time off it (sqrt(l / g)), the trunk's
height over the ground under it (l), its ground velocity in its heading frame (sqrt(g l)) and yaw rate
(sqrt(g / l)), and the episode's world (randomize.py's draw: friction, trunk mass, its centre's offset in l,
motor strength, a one-step delay). MuJoCo Playground's `privileged_state` holds the same kinds of figure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional

import numpy as np

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.envs.layout import ObservationLayout, Segment
from ppo_torchrl.robots.gait import FOOT_PAIRS, MOVING_SPEED
from ppo_torchrl.tasks.locomotion.commands import make_command
from ppo_torchrl.tasks.locomotion.memory import EpisodeMemory
from ppo_torchrl.tasks.locomotion.randomize import Randomization
from ppo_torchrl.tasks.locomotion.rewards import TERMS, Step
from ppo_torchrl.tasks.locomotion.sensors import Contacts
from ppo_torchrl.tasks.locomotion.terrain import ground_under, make_terrain

HEIGHT_CLIP = 1.0  # x l: terrain heights relative to the trunk read within +-1 leg length (layout)
ENDINGS = (None, "fall", "too high", "non-finite state")  # termination codes; contact endings are "contact: <body>"


@dataclass
class Reading:
    """What the physics left in the rows, [N, ...] (batch.py gathers it after each control step)."""

    qpos: np.ndarray
    qvel: np.ndarray
    xpos: np.ndarray  # [N, nbody, 3] (as mj_step leaves them: from the start of its last physics step)
    trunk_xmat: np.ndarray  # [N, 9]
    feet_xy: np.ndarray  # [N, F, 2]
    actuator_force: np.ndarray
    cfrc_ext: Optional[np.ndarray]
    step_peak: Optional[np.ndarray]


WORLD_DRAW = ("friction", "trunk_mass", "com", "strength", "delayed")  # the privileged observation's world, in order
NOMINAL_DRAW = {"friction": 1.0, "trunk_mass": 1.0, "com": [0.0, 0.0, 0.0], "strength": 1.0, "delayed": False}


def heading_frame(qpos: np.ndarray, qvel: np.ndarray) -> tuple:
    """(qpos[2:], qvel) of free-joint trunks, [N, nq - 2] and [N, nv], with each trunk's yaw taken out
    (env.legged.obs_frame=heading): the attitude quaternion (w x y z) becomes conj(q_yaw) q, the roll and pitch left
    once the yaw about the world's z is removed (w >= 0), and the linear velocity is turned into the heading frame,
    the frame the joystick's command is given in; the yaw is the trunk's x axis's angle on the ground, as `motion`
    reads it. Height, joint angles, the trunk's own-frame angular velocity and the joint speeds are as they are."""
    qpos, qvel = qpos.copy(), qvel.copy()
    w, x, y, z = qpos[:, 1], qpos[:, 2], qpos[:, 3], qpos[:, 4]
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    c, s = np.cos(0.5 * yaw), np.sin(0.5 * yaw)
    tilt = np.stack([c * w + s * z, c * x + s * y, c * y - s * x, c * z - s * w], axis=1)
    qpos[:, 1:5] = tilt * np.where(tilt[:, :1] < 0, -1.0, 1.0)
    cy, sy = np.cos(yaw), np.sin(yaw)
    vx, vy = qvel[:, 0].copy(), qvel[:, 1].copy()
    qvel[:, 0], qvel[:, 1] = cy * vx + sy * vy, -sy * vx + cy * vy
    return qpos, qvel


class LeggedTask:
    def __init__(self, n: int, world, kwargs: dict, evaluation: bool, privileged: bool = False):
        legged, terrain = dict(kwargs.get("legged") or {}), dict(kwargs.get("terrain") or {})
        self.n, self.world = n, world
        self.terrain = make_terrain(n, world, terrain, evaluation)
        self.command = make_command(n, world, legged, world.dt)
        self.randomize = Randomization(n, world, legged.get("randomize"), evaluation)
        named = dict(legged.get("rewards") or {})
        unknown = sorted(set(named) - {name for name, t in TERMS.items() if t.weight_key is None})
        if unknown:
            raise ConfigError(f"env.legged.rewards.{unknown[0]}: no such reward term; the terms weighted there: "
                              + ", ".join(name for name, t in TERMS.items() if t.weight_key is None))
        weights = {name: float(named.get(name, 0.0) if t.weight_key is None else
                               (kwargs if t.base else legged).get(t.weight_key) or 0.0) for name, t in TERMS.items()}
        self.terms = [TERMS[name] for name in TERMS if TERMS[name].base or weights[name]]
        self.weights = np.array([weights[t.name] for t in self.terms])
        self.names = [t.name for t in self.terms]
        needs = {need for t in self.terms for need in t.needs}
        self.observe_contacts = bool(terrain.get("observe_contacts", False))
        self.height_samples = int(terrain.get("height_samples") or 0)
        self._offsets = float(terrain.get("height_sample_spacing") or 0.1) * np.arange(self.height_samples)
        self.segments = (kwargs.get("robot") or {}).get("obs_layout") == "segments"
        self.heading_frame = (kwargs.get("robot") or {}).get("obs_frame") == "heading"
        self.period = None if legged.get("gait_period") is None else float(legged["gait_period"])
        if self.period is None and weights["gait_clock"]:
            raise ConfigError("env.locomotion.gait_clock_weight needs env.locomotion.gait_period (s)")
        if self.period is not None and world.corners is None:
            raise ConfigError("env.locomotion.gait_period needs a robot with four feet, one at each corner")
        if self.period is not None:
            first = set(FOOT_PAIRS["diagonal"][0])
            self._first_half = np.array([c in first for c in world.corners])  # down in the first half: LF, RH
        if weights["joint_speed_limit"] and legged.get("joint_speed_limit") is None:
            raise ConfigError("env.locomotion.joint_speed_limit_cost_weight needs env.locomotion.joint_speed_limit")
        self.needs_contacts = self.observe_contacts or "contacts" in needs or privileged  # (privileged: its feet)
        self.needs_peak = "peak" in needs
        self.needs_cfrc = "cfrc" in needs or bool(kwargs.get("include_cfrc_ext_in_observation"))
        self.include_cfrc = bool(kwargs.get("include_cfrc_ext_in_observation"))
        self.contacts = Contacts(n, world, faces="faces" in needs)
        self.reads_contacts = self.needs_contacts or "faces" in needs or self.contacts.any_ending
        self.healthy_z = tuple(float(z) for z in kwargs["healthy_z_range"])
        self.z_above_terrain = bool(legged.get("healthy_z_above_terrain"))
        self.terminate_unhealthy = bool(kwargs.get("terminate_when_unhealthy", True))
        self.positive_only = bool(legged.get("only_positive_rewards"))
        self.noise = float(kwargs.get("reset_noise_scale", 0.1))
        target = legged.get("base_height_target")
        command = legged.get("command") or {}
        self.params = {"dt": world.dt, "healthy_reward": weights["survive"],
                       "speed": world.units[0], "time": world.units[1],
                       "sigma_lin": float(command.get("sigma_lin", 0.25)), "sigma_yaw": float(command.get("sigma_yaw", 0.25)),
                       "home_angle": world.init_qpos[world.act_qpos],
                       "joint_speed_limit": legged.get("joint_speed_limit"),
                       "base_height_target": world.init_z if target is None else float(target),
                       "feet_air_time_target": float(legged.get("feet_air_time_target", 0.5)),
                       "long_swing_limit": float(legged.get("long_swing_limit", 0.5))}
        model = world.model
        self.memory = EpisodeMemory.zeros(n, model.nu, len(world.feet), len(self.terms))
        self.ending = np.zeros(n, np.int64)  # why each row's last step ended its episode (ENDINGS index; -1: contact)
        self.ending_body: List[Optional[str]] = [None] * n
        self.progress = np.zeros(n)  # the last step's velocity along the heading
        self.last_terms = np.zeros((n, len(self.terms)))  # the last step's signed, weighted terms
        self._no_command = np.zeros((n, 3))
        nq, nv = model.nq, model.nv
        self.obs_dim = (nq - 2 + nv + (model.nbody - 1) * 6 * self.include_cfrc + len(world.feet) * self.observe_contacts
                        + self.height_samples + self.command.size + 2 * (self.period is not None))
        self.privileged_dim = self.obs_dim + 2 * len(world.feet) + 1 + 3 + 7

    # ---------------------------------------------------------------- the clock
    def clock_phase(self) -> Optional[np.ndarray]:
        return None if self.period is None else (self.memory.clock_steps * self.world.dt / self.period) % 1.0

    def meant_down(self) -> Optional[np.ndarray]:
        phase = self.clock_phase()
        return None if phase is None else np.where((phase < 0.5)[:, None], self._first_half, ~self._first_half)

    # ---------------------------------------------------------------- observation
    def observe(self, r: Reading, rows=slice(None)) -> np.ndarray:
        """The observation of rows `rows` (all by default) from their reading."""
        m = self.memory
        parts = list(heading_frame(r.qpos[rows, 2:], r.qvel[rows])) if self.heading_frame else \
            [r.qpos[rows, 2:], r.qvel[rows]]
        if self.include_cfrc:
            parts.append(np.clip(r.cfrc_ext[rows, 1:], -1.0, 1.0).reshape(len(parts[0]), -1))
        if self.observe_contacts:
            parts.append(self.contacts.feet[rows].astype(np.float64))
        if self.height_samples:
            body = r.xpos[rows, self.world.trunk]
            points = body[:, None, :2] + self._offsets[None, :, None] * self.world.heading
            heights = self.terrain.height_at(rows, points)
            parts.append(heights - body[:, 2:3] if self.segments else heights)
        if self.command.size:
            parts.append(self.command.observe()[rows])
        if self.period is not None:
            angle = 2.0 * math.pi * ((m.clock_steps[rows] * self.world.dt / self.period) % 1.0)
            parts.append(np.stack([np.sin(angle), np.cos(angle)], axis=1))
        return np.concatenate(parts, axis=1)

    def layout(self) -> ObservationLayout:
        """How each segment is scaled (layout.py; module doc). whole: one running segment over everything (runs
        saved before issue 59, env.legged.obs_layout=whole)."""
        if not self.segments:
            return ObservationLayout.whole(self.obs_dim)
        robot, feet = self.world.robot, len(self.world.feet) * self.observe_contacts
        clock = 2 * (self.period is not None)
        parts = (Segment.running("proprioception", self.obs_dim - feet - self.height_samples - self.command.size - clock),
                 Segment.none("foot_contacts", feet),
                 Segment.fixed("terrain_heights", self.height_samples, -robot.height, robot.leg_length, HEIGHT_CLIP),
                 Segment.none("command", self.command.size),
                 Segment.none("clock", clock))
        return ObservationLayout(tuple(p for p in parts if p.size))

    def privileged(self, r: Reading, rows=slice(None)) -> np.ndarray:
        """The privileged observation of rows `rows` (module doc), from their reading; its contact flags and air
        times are those of the last control step (the task must be built with privileged=True to keep them)."""
        w, m = self.world, self.memory
        speed, time = w.units
        length = speed * time  # l (1 m for a model without a robot read from it)
        trunk = r.xpos[rows, w.trunk]
        height = (trunk[:, 2] - ground_under(self.terrain, rows, trunk[:, :2])) / length
        motion = self.motion(r)
        draws = [{**NOMINAL_DRAW, **self.randomize.draws[i]} for i in np.arange(self.n)[rows]]
        world_draw = np.array([[d["friction"], d["trunk_mass"], *np.asarray(d["com"]) / length,
                                d["strength"], float(d["delayed"])] for d in draws], np.float64).reshape(-1, 7)
        return np.concatenate([self.observe(r, rows), self.contacts.feet[rows].astype(np.float64),
                               m.air_time[rows] / time, height[:, None], motion["velocity"][rows] / speed,
                               (motion["yaw_rate"][rows] * time)[:, None], world_draw], axis=1)

    def privileged_layout(self) -> ObservationLayout:
        """The observation's own segments, then the feet's flags as they are and the rest running (module doc)."""
        feet = len(self.world.feet)
        return ObservationLayout(self.layout().segments + (Segment.none("privileged_feet_down", feet),
                                                           Segment.running("privileged_state", feet + 1 + 3 + 7)))

    # ---------------------------------------------------------------- one control step
    def step(self, actions: np.ndarray, r: Reading, xy_before: np.ndarray, rngs: list) -> tuple:
        """(reward [N], terminated [N]) of the control step the physics just took, the memory moved on (rngs: each
        row's, for a command drawn again)."""
        w, m, c = self.world, self.memory, self.contacts
        velocity = (r.xpos[:, w.trunk, :2] - xy_before) / w.dt
        self.progress = self.command.progress(velocity)
        m.stepped[:] = True
        m.moving[:] = self.progress >= MOVING_SPEED
        trunk = r.xpos[:, w.trunk]
        ground = ground_under(self.terrain, slice(None), trunk[:, :2])
        unhealthy = self._unhealthy(r)
        s = Step(action=actions, prev_action=m.prev_action, speed=self.command.speed(self.progress),
                 healthy=unhealthy == 0, cfrc_ext=r.cfrc_ext, actuator_force=r.actuator_force,
                 joint_speed=r.qvel[:, w.act_dofs], step_peak=r.step_peak, height=trunk[:, 2] - ground,
                 up=r.trunk_xmat[:, 6:9] @ w.up0, feet=c.feet if self.needs_contacts else None,
                 feet_xy=r.feet_xy, prev_feet_xy=m.prev_feet_xy, air_time=m.air_time,
                 body_contacts=c.body, on_face=c.on_face, meant_down=self.meant_down(),
                 command=self.command.value if self.command.size else self._no_command, **self.motion(r),
                 params=self.params)
        values = np.stack([t.fn(s) for t in self.terms], axis=1) * self.weights  # signed, weighted: [N, T]
        self.last_terms = values
        reward = (values[:, 0] + values[:, 1]) + (values[:, 2] + values[:, 3])  # Ant-v5's (forward, survive, ctrl, contact)
        if len(self.terms) > 4:
            extra = values[:, 4]
            for k in range(5, len(self.terms)):
                extra = extra + values[:, k]
            reward = reward + extra
        if self.positive_only:  # legged_gym's only_positive_rewards: costs never make an early fall pay
            reward = np.maximum(reward, 0.0)
        m.prev_action[:] = actions
        if self.needs_contacts:
            m.air_time[:] = np.where(c.feet, 0.0, m.air_time + w.dt)
            m.prev_contact[:] = c.feet
            m.prev_feet_xy[:] = r.feet_xy
        m.clock_steps += 1
        m.term_sums += values
        self.command.tick(rngs)  # the next observation shows the command the next step is paid for
        # why an episode ends here: a terminate_on_contact body on the ground first, then the health check's reason
        contact = c.ending >= 0 if c.any_ending else np.zeros(self.n, bool)
        self.ending[:] = np.where(contact, -1, unhealthy if self.terminate_unhealthy else 0)
        for i in np.flatnonzero(contact):
            self.ending_body[i] = w.model.body(w.model.geom_bodyid[c.ending[i]]).name
        return reward, self.ending != 0

    def motion(self, r: Reading) -> dict:
        """The trunk's motion the joystick's terms and tracking read: ground velocity in its heading frame, yaw rate,
        vertical speed, roll and pitch rates (a free joint's qvel: world linear, body angular), the joint angles."""
        xmat = r.trunk_xmat
        yaw = np.arctan2(xmat[:, 3], xmat[:, 0])
        c, s = np.cos(yaw), np.sin(yaw)
        vx, vy = r.qvel[:, 0], r.qvel[:, 1]
        omega = np.einsum("nij,nj->ni", xmat.reshape(-1, 3, 3), r.qvel[:, 3:6])  # to the world frame
        return {"velocity": np.stack([c * vx + s * vy, -s * vx + c * vy], axis=1), "yaw_rate": omega[:, 2],
                "vz": r.qvel[:, 2], "tilt_rate": omega[:, :2], "joint_angle": r.qpos[:, self.world.act_qpos]}

    def _unhealthy(self, r: Reading) -> np.ndarray:
        """[N] ENDINGS code of the health check: fall (the trunk's z under healthy_z_range, above the terrain with
        healthy_z_above_terrain), too high, non-finite state; 0 while healthy (Gymnasium Ant-v5's is_healthy)."""
        z = r.qpos[:, 2]
        if self.z_above_terrain:
            z = z - ground_under(self.terrain, slice(None), r.xpos[:, self.world.trunk, :2])
        low, high = self.healthy_z
        finite = np.isfinite(r.qpos).all(axis=1) & np.isfinite(r.qvel).all(axis=1)
        return np.where(~finite, 3, np.where(z < low, 1, np.where(z > high, 2, 0)))

    def termination(self, i: int) -> Optional[str]:
        """Why row i's last step ended its episode ('contact: <body>', 'fall', ...), None while it runs."""
        code = int(self.ending[i])
        return f"contact: {self.ending_body[i]}" if code == -1 else ENDINGS[code]

    def term_metrics(self) -> List[dict]:
        """Per row, each reward term's sum over its last finished episode (`reward/<term>`), where it has one."""
        sums = self.memory.last_term_sums
        return [{f"reward/{name}": float(v) for name, v in zip(self.names, sums[i])}
                for i in range(self.n) if not np.isnan(sums[i, 0])]

    def metric_keys(self) -> List[str]:
        """metrics.csv's columns of the task: its in-training eval's figures (figures.COLUMNS), the terrain's
        curriculum, each reward term's episode sum; the trainer logs them without naming them."""
        from ppo_torchrl.tasks.locomotion.figures import COLUMNS as EVAL_COLUMNS

        return list(EVAL_COLUMNS) + self.terrain.metric_keys() + [f"reward/{name}" for name in self.names]

    def metrics(self) -> List[dict]:
        """What a training run logs of the rows: the terrain's curriculum, the reward terms' episode sums."""
        return self.terrain.metrics() + self.term_metrics()  # mean_metrics averages each key over the dicts holding it
