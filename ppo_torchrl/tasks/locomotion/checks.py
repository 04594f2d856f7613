"""env.locomotion's values, checked before anything is built (envs.env_checks; env.terrain's are terrain.py's
`terrain_checks`): limits > 0, gains and weights >= 0, a joint speed limit that leaves the joints free to move."""

from __future__ import annotations

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
