"""The reward terms of legged-locomotion practice (legged_gym's set, weights per control step) on top
of Ant-v5's forward, healthy, control and contact terms: joint torque, joint speed, joint speed past
the limit (the largest excess of each joint over the control step's physics steps, so the impacts
that eval's peak joint speed sees are paid for), action rate, foot slip, base height and
orientation, feet air time, a swing held past a limit, a foot meeting an upright face (a stumble), non-foot
contacts, and a trot clock (a periodic reward for the diagonal pairs' contacts, Siekmann et al. 2021);
`target_speed` caps the rewarded forward speed.

`LeggedRewards` is a mixin of `LocomotionEnv` (robots/env.py): it reads the env's weights (`_w`),
its contacts (robots/contacts.py) and the simulator.
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.robots.gait import FOOT_PAIRS


class LeggedRewards:
    """The legged reward terms and the trot clock (module doc)."""

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
        if w["stumble_cost_weight"]:  # feet against the step's riser or low on its edge (contacts.py, FACE_NORMAL_Z)
            terms["reward_stumble"] = -w["stumble_cost_weight"] * float(np.count_nonzero(self.feet_on_a_face()) / len(self.feet))
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
            if w["long_swing_cost_weight"]:  # feet still in the air after this step, past the limit
                held = (~feet) & (self._air_time + self._dt > self._swing_limit)
                terms["reward_long_swing"] = -w["long_swing_cost_weight"] * float(np.count_nonzero(held) / len(feet))
            if w["gait_clock_weight"]:  # the phase this step was taken in
                meant = self.feet_meant_down()
                terms["reward_gait_clock"] = w["gait_clock_weight"] * float(np.count_nonzero(feet == meant) / len(feet))
            self._air_time = np.where(feet, 0.0, self._air_time + self._dt)
            self._prev_contact = feet
            self._prev_feet_xy = feet_xy.copy()
        return sum(terms.values()), terms
