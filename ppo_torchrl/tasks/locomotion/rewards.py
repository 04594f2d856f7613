"""The named reward terms of a legged task: each one small pure function of the step's context (`Step`, arrays
over the rows), registered with the config key of its weight; the task sums `weight x term` over the terms whose
weight is not 0 and logs each term's episode sum (legged_gym's `_reward_<name>` found for every non-zero scale).

A term returns its value with its sign (a cost is negative); the weights are >= 0 (validation refuses others).
Gymnasium Ant-v5's four (forward, survive, ctrl, contact) are always summed first, as that env did; the legged
terms follow in the order below. A new term is one function here and its weight's config key (config.py, with the
recipe's scaling in robots/recipe.py where a size enters).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, Optional

import numpy as np


@dataclass
class Step:
    """What the reward terms read of one control step, [N, ...] over the rows (task.py fills it)."""

    action: np.ndarray  # [N, nu] the policy's action, as given
    prev_action: np.ndarray
    speed: np.ndarray  # [N] forward speed the command rewards (capped at its target)
    healthy: np.ndarray  # [N] bool
    cfrc_ext: Optional[np.ndarray]  # [N, nbody, 6]
    actuator_force: np.ndarray  # [N, nu]
    joint_speed: np.ndarray  # [N, na] actuated joints' speeds
    step_peak: Optional[np.ndarray]  # [N, na] their top |speed| over the control step's physics steps
    height: np.ndarray  # [N] the trunk's height above the ground under it
    up: np.ndarray  # [N] cos of the trunk's tilt from its standing attitude
    feet: Optional[np.ndarray]  # [N, F] bool, on the ground
    feet_xy: Optional[np.ndarray]  # [N, F, 2]
    prev_feet_xy: Optional[np.ndarray]
    air_time: Optional[np.ndarray]  # [N, F] before this step
    body_contacts: Optional[np.ndarray]  # [N] non-foot geoms on the ground
    on_face: Optional[np.ndarray]  # [N, F] feet on an upright face
    meant_down: Optional[np.ndarray]  # [N, F] the trot clock's schedule for this step
    command: np.ndarray  # [N, 3] a velocity command's (vx, vy, yaw rate) in SI; zeros for the heading command
    velocity: np.ndarray  # [N, 2] the trunk's ground velocity in its heading frame (m/s)
    yaw_rate: np.ndarray  # [N] rad/s, about the world's vertical
    vz: np.ndarray  # [N] the trunk's vertical speed
    tilt_rate: np.ndarray  # [N, 2] its roll and pitch rates (the world's x and y components of its angular velocity)
    joint_angle: np.ndarray  # [N, na] the actuated joints' angles
    params: dict  # the task's constants: dt, healthy_reward, speed limits, targets, speed and time scales, sigmas


@dataclass(frozen=True)
class Term:
    name: str
    # in the env's keyword arguments (top level: Ant-v5's; else env.locomotion's legged keys); None: the term's
    # weight is env.locomotion.rewards.<name> (env=legged: env.legged.rewards.<name>), dimensionless
    weight_key: Optional[str]
    fn: Callable[[Step], np.ndarray]
    needs: tuple = ()  # "contacts", "faces", "peak", "cfrc", "clock"
    base: bool = False  # one of Ant-v5's four


TERMS: Dict[str, Term] = {}


def term(name: str, weight_key: Optional[str] = None, needs: tuple = (), base: bool = False):
    def register(fn):
        TERMS[name] = Term(name, weight_key, fn, needs, base)
        return fn
    return register


# ---------------------------------------------------------------- Gymnasium Ant-v5's four
@term("forward", "forward_reward_weight", base=True)
def forward(s: Step) -> np.ndarray:
    return s.speed


@term("survive", "healthy_reward", base=True)
def survive(s: Step) -> np.ndarray:
    return s.healthy.astype(np.float64)


@term("ctrl", "ctrl_cost_weight", base=True)
def ctrl(s: Step) -> np.ndarray:
    # in float64 (Gymnasium's control_cost on a float32 action is float32 through NumPy 2's promotion: ~3e-9 apart)
    return -np.square(s.action.astype(np.float64)).sum(axis=1)


@term("contact", "contact_cost_weight", needs=("cfrc",), base=True)
def contact(s: Step) -> np.ndarray:
    return -np.square(np.clip(s.cfrc_ext, -1.0, 1.0)).sum(axis=(1, 2))


# ---------------------------------------------------------------- legged_gym's set, and the trot's
@term("torque", "torque_cost_weight")
def torque(s: Step) -> np.ndarray:
    return -np.square(s.actuator_force).sum(axis=1)


@term("joint_speed", "joint_speed_cost_weight")
def joint_speed(s: Step) -> np.ndarray:
    return -np.square(s.joint_speed).sum(axis=1)


@term("joint_speed_limit", "joint_speed_limit_cost_weight", needs=("peak",))
def joint_speed_limit(s: Step) -> np.ndarray:
    return -np.maximum(s.step_peak - s.params["joint_speed_limit"], 0.0).sum(axis=1)


@term("action_rate", "action_rate_cost_weight")
def action_rate(s: Step) -> np.ndarray:
    return -np.square(s.action - s.prev_action).sum(axis=1)


@term("base_height", "base_height_cost_weight")
def base_height(s: Step) -> np.ndarray:
    return -(s.height - s.params["base_height_target"]) ** 2


@term("orientation", "orientation_cost_weight")
def orientation(s: Step) -> np.ndarray:
    return -(1.0 - s.up)


@term("stumble", "stumble_cost_weight", needs=("faces",))
def stumble(s: Step) -> np.ndarray:
    return -(np.count_nonzero(s.on_face, axis=1) / s.on_face.shape[1])


@term("foot_slip", "foot_slip_cost_weight", needs=("contacts",))
def foot_slip(s: Step) -> np.ndarray:
    slip = np.square((s.feet_xy - s.prev_feet_xy) / s.params["dt"]).sum(axis=2)
    return -(slip * s.feet).sum(axis=1)


@term("air_time", "feet_air_time_weight", needs=("contacts",))
def air_time(s: Step) -> np.ndarray:
    touchdown = s.feet & (s.air_time > 0)
    return ((s.air_time - s.params["feet_air_time_target"]) * touchdown).sum(axis=1)


@term("body_contact", "body_contact_cost_weight", needs=("contacts",))
def body_contact(s: Step) -> np.ndarray:
    return -s.body_contacts.astype(np.float64)


@term("long_swing", "long_swing_cost_weight", needs=("contacts",))
def long_swing(s: Step) -> np.ndarray:
    held = (~s.feet) & (s.air_time + s.params["dt"] > s.params["long_swing_limit"])
    return -(np.count_nonzero(held, axis=1) / s.feet.shape[1])


@term("gait_clock", "gait_clock_weight", needs=("contacts", "clock"))
def gait_clock(s: Step) -> np.ndarray:
    return np.count_nonzero(s.feet == s.meant_down, axis=1) / s.feet.shape[1]


# ---------------------------------------------------------------- the joystick's (velocity command), weights in rewards
@term("tracking_lin_vel")
def tracking_lin_vel(s: Step) -> np.ndarray:
    """exp(-|v_xy - command_xy|^2 / sigma): the trunk's ground velocity in its heading frame against the command."""
    return np.exp(-np.square(s.velocity - s.command[:, :2]).sum(axis=1) / s.params["sigma_lin"])


@term("tracking_ang_vel")
def tracking_ang_vel(s: Step) -> np.ndarray:
    return np.exp(-np.square(s.yaw_rate - s.command[:, 2]) / s.params["sigma_yaw"])


@term("lin_vel_z")
def lin_vel_z(s: Step) -> np.ndarray:
    return -np.square(s.vz / s.params["speed"])


@term("ang_vel_xy")
def ang_vel_xy(s: Step) -> np.ndarray:
    return -np.square(s.tilt_rate * s.params["time"]).sum(axis=1)


@term("stand_still")
def stand_still(s: Step) -> np.ndarray:
    """- sum |joint angle - standing angle| (rad) while the command is zero."""
    still = ~np.any(s.command != 0.0, axis=1)
    return -np.abs(s.joint_angle - s.params["home_angle"]).sum(axis=1) * still
