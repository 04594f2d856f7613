"""Gait measurement: what evaluate reports of a legged robot's steps (`measure_gait`), sampled at every
physics step: stride frequency, duty factor, each foot's share of time on the ground, touchdowns per
second and longest time in the air (also counting only the time the robot moved forward, its previous
control step at MOVING_SPEED or more), for four feet at four corners the share of time both feet of a
pair are down (diagonal, same side, same end: a trot, a pace, a bound), peak joint speed, the joint
torques against the model's own limits (the largest share of its limit any joint reached, and the share of
time some joint was at it), and the share of time a non-foot body touches the ground.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

MIN_AIR_S = 0.02  # a touchdown counts after at least this long in the air (contact chatter is not a stride)
MOVING_SPEED = 0.1  # m/s: the robot moves when its last control step went forward at least this fast
AT_LIMIT = 0.99  # a joint torque at this share of its limit or more is at the limit
CORNERS = ("LF", "RF", "LH", "RH")  # a four-footed robot's feet: left/right, fore/hind
# the foot pairs whose time down together tells the gaits apart (a trot, a pace, a bound)
FOOT_PAIRS = {"diagonal": (("LF", "RH"), ("RF", "LH")), "same_side": (("LF", "LH"), ("RF", "RH")),
              "same_end": (("LF", "RF"), ("LH", "RH"))}


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
        self.peak_torque_share = None  # None: no torque limits known (a model not read by robots/model.py)
        self.torque_at_limit_time = 0.0
        self.body_contact_time = 0.0
        self.pair_together_time = np.zeros(len(self._first))  # both feet of the pair down
        self.pair_down_time = np.zeros(len(self._first))  # at least one of them down

    def add(self, feet: np.ndarray, joint_speed: float, body_contact: bool, dt: float, moving: bool = True,
            torque_share: Optional[float] = None) -> None:
        """torque_share: the largest |joint torque| / the model's limit over the actuated joints this step."""
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
        if torque_share is not None:
            self.peak_torque_share = max(self.peak_torque_share or 0.0, torque_share)
            self.torque_at_limit_time += dt * (torque_share >= AT_LIMIT)

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
            # the largest |joint torque| / the model's limit (1.0: a servo saturated), the share of time a joint was
            # at AT_LIMIT of it or more; None where the limits are not known
            "peak_torque_share": self.peak_torque_share,
            "torque_at_limit_share": None if self.peak_torque_share is None else float(self.torque_at_limit_time / t),
        }

