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
    params: dict  # the task's constants: dt, healthy_reward, speed limits, targets


@dataclass(frozen=True)
class Term:
    name: str
    weight_key: str  # in the env's keyword arguments (top level: Ant-v5's; else env.locomotion's legged keys)
    fn: Callable[[Step], np.ndarray]
    needs: tuple = ()  # "contacts", "faces", "peak", "cfrc", "clock"
    base: bool = False  # one of Ant-v5's four


TERMS: Dict[str, Term] = {}


def term(name: str, weight_key: str, needs: tuple = (), base: bool = False):
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
