"""The legged recipe scaled to a robot (env=legged): env.legged's targets, given in the robot's own units,
become the env.locomotion and env.terrain values the env runs on, from the robot read from its model
(robots/model.py). With l the leg length, m the mass and g gravity: lengths are multiples of l, speeds
of sqrt(g l), times of sqrt(l / g), torques of m g l (dynamic similarity: a Go1 and an ANYmal B asked
for the same multiples walk alike). The robot's own facts (trunk, heading, standing height, feet) are
taken as read.

The physics step is derived too (env.legged.physics_dt=rule, `rule_dt`): the longest step that divides the
control step and keeps the model's contacts as soft as it says, its stiffest servo accurate and explicit damping
stable; model keeps the model's own timestep.

Every value derived here has one owner, env.legged: setting the same key in env.locomotion or
env.terrain is refused in one line (env.terrain.step_height, a fixed height, stays the user's: evaluate's
height sweep sets it).
"""

from __future__ import annotations

import dataclasses
import math

from omegaconf import OmegaConf

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.envs.layout import OBS_FRAMES, OBS_LAYOUTS
from ppo_torchrl.robots.model import CONTACT_MODES, GRAVITY, Robot

# env.locomotion / env.terrain keys env=legged derives (module doc), with the env.legged key each comes from
DERIVED = {
    "locomotion": {"main_body": None, "heading": None, "frame_skip": "control_dt", "target_speed": "target_speed",
                   "forward_reward_weight": "forward_reward_weight", "healthy_z_range": "fall_height",
                   "gait_period": "gait_period", "gait_clock_weight": "gait_clock_weight",
                   "long_swing_cost_weight": "long_swing_cost_weight", "long_swing_limit": "long_swing_limit",
                   "stumble_cost_weight": "stumble_cost_weight",
                   "torque_cost_weight": "torque_cost_weight", "joint_speed_cost_weight": "joint_speed_cost_weight",
                   "foot_slip_cost_weight": "foot_slip_cost_weight", "base_height_target": None,
                   "base_height_cost_weight": "base_height_cost_weight", "terminate_on_contact": None,
                   "foot_geoms": None, "friction_scale": "friction_scale", "trunk_mass_scale": "trunk_mass_scale",
                   "command": "command", "rewards": "rewards", "randomize": "randomize"},
    "terrain": {"eval_step_height": "step_height", "step_height_range": "step_height_range",
                "curriculum_step": "curriculum_step", "curriculum_band": "curriculum_band",
                "step_distance": "step_distance", "success_margin": "success_margin",
                "height_sample_spacing": "height_sample_spacing"},
}


PHYSICS_STEPS = ("rule", "model")  # env.legged.physics_dt, besides a step in seconds
FRICTION_CONES = ("model", "pyramidal", "elliptic")  # env.legged.friction_cone
SERVO_PHASE = 0.5  # rad: the stiffest servo turns at most this much of its oscillation per physics step
DAMPING_STEP = 1.0  # kd / I x dt where the integrator takes the servos' damping explicitly (Euler): half its limit of 2


def rule_dt(robot: Robot, control_dt: float) -> float:
    """The physics step by the recipe's rule: the longest that divides the control step into whole steps and keeps
    (1) every contact and joint limit as soft as the model says: dt <= its shortest time constant / 2 (MuJoCo's own
        floor: with a longer step it softens them, to a time constant of 2 dt);
    (2) the stiffest servo accurate: its natural frequency w = sqrt(kp / I) on its joint's own inertia with
        w dt <= SERVO_PHASE (the integrator's frequency error (w dt)^2 / 24 about 1%);
    (3) explicit servo damping stable with a margin: kd / I x dt <= DAMPING_STEP (Euler; implicit integrators take
        it implicitly);
    never finer than the model's own timestep (a model its authors made stiffer than these bounds keeps theirs)."""
    bound = min(robot.time_constant / 2, SERVO_PHASE / robot.servo_rate,
                math.inf if robot.implicit_damping or robot.damping_rate == 0 else DAMPING_STEP / robot.damping_rate)
    return max(control_dt / math.ceil(control_dt / bound - 1e-9), robot.timestep)


def physics_dt(robot: Robot, legged) -> float:
    """The physics step (s) of env.legged.physics_dt: rule (rule_dt), model (the model's own timestep, as runs
    saved before the key trained), or a step in seconds. A control step is a whole number of them (frame_skip)."""
    given = str(legged.get("physics_dt") or "model")
    if given == "rule":
        return rule_dt(robot, legged.control_dt)
    return robot.timestep if given == "model" else float(given)


def in_metres(legs: float, leg_length: float) -> float:
    """A step height given in leg lengths, in m to the micrometre: the one conversion, so that the eval's step,
    a video of it and evaluate's height sweep (heights=0.25l) climb the same step (issue 59 item 7: a video at the
    unrounded height and a sweep at the rounded one ran different episodes)."""
    return round(legs * leg_length, 6)


def derived_values(robot: Robot, legged) -> dict:
    """{'locomotion': {...}, 'terrain': {...}}: the values env.legged's targets take on this robot (with the env's
    contacts and physics step, tasks/locomotion/world.py, which no other env reads)."""
    l, speed, time = robot.leg_length, robot.speed_scale, robot.time_scale
    dt = physics_dt(robot, legged)
    weight_moment = robot.mass * GRAVITY * l  # N m
    band = legged.curriculum_band
    return {
        "locomotion": {
            "main_body": robot.trunk,
            "heading": f"{math.degrees(math.atan2(robot.heading[1], robot.heading[0])):.6f}",
            "frame_skip": max(1, round(legged.control_dt / dt)),
            "physics_dt": dt, "contacts": legged.get("contacts", CONTACT_MODES[0]),
            "friction_cone": legged.get("friction_cone", FRICTION_CONES[0]),
            "target_speed": legged.target_speed * speed,
            "forward_reward_weight": legged.forward_reward_weight / speed,
            "healthy_z_range": [legged.fall_height * l, legged.too_high * l],
            "gait_period": None if legged.gait_period is None else legged.gait_period * time,
            "gait_clock_weight": legged.gait_clock_weight if legged.gait_period is not None else 0.0,
            "long_swing_cost_weight": legged.get("long_swing_cost_weight", 0.0),
            "long_swing_limit": legged.get("long_swing_limit", 2.0) * time,
            "stumble_cost_weight": legged.get("stumble_cost_weight", 0.0),
            "torque_cost_weight": legged.torque_cost_weight / weight_moment ** 2,
            "joint_speed_cost_weight": legged.joint_speed_cost_weight * time ** 2,
            "foot_slip_cost_weight": legged.foot_slip_cost_weight / speed ** 2,
            "base_height_target": robot.height,
            "base_height_cost_weight": legged.base_height_cost_weight / l ** 2,
            "terminate_on_contact": [robot.trunk],
            "friction_scale": legged.get("friction_scale", 1.0),
            "trunk_mass_scale": legged.get("trunk_mass_scale", 1.0),
            "command": command_si(legged.get("command") or _default_command(), speed, time),
            "rewards": dict(legged.get("rewards") or {}),
            "randomize": randomize_si(legged.get("randomize"), l, speed, time),
        },
        "terrain": {
            "eval_step_height": in_metres(legged.step_height, l),
            "step_height_range": [h * l for h in legged.step_height_range],
            "curriculum_step": legged.curriculum_step * l,
            "curriculum_band": None if band is None else band * l,
            "step_distance": [d * l for d in legged.step_distance],
            "success_margin": legged.success_margin * l,
            "height_sample_spacing": legged.height_sample_spacing * l,
        },
    }


def _default_command():
    from ppo_torchrl.config import CommandConfig  # a saved config from before the key: the heading command

    return CommandConfig()


def command_si(command, speed: float, time: float) -> dict:
    """env.legged.command (speeds in sqrt(g l), the yaw rate in sqrt(g / l), times in sqrt(l / g)) in SI."""
    get = command.get if hasattr(command, "get") else lambda k, d=None: getattr(command, k, d)
    return {"kind": get("kind", "heading"), "vx": [v * speed for v in get("vx")], "vy": [v * speed for v in get("vy")],
            "yaw": [w / time for w in get("yaw")], "stand_share": float(get("stand_share")),
            "resample": [t * time for t in get("resample")], "sigma_lin": float(get("sigma_lin")) * speed ** 2,
            "sigma_yaw": float(get("sigma_yaw")) / time ** 2}


def randomize_si(randomize, l: float, speed: float, time: float) -> dict:
    """env.legged.randomize (robot units) in SI; None (a saved config from before the key): nothing randomized."""
    from ppo_torchrl.config import RandomizeConfig

    r = dataclasses.asdict(RandomizeConfig()) if randomize is None else (
        OmegaConf.to_container(randomize) if OmegaConf.is_config(randomize) else dict(randomize))
    return {**r, "com": float(r["com"]) * l, "push_speed": float(r["push_speed"]) * speed,
            "push_interval": [t * time for t in r["push_interval"]]}


def describe(robot: Robot, legged) -> str:
    """The start line's account of a legged run: what was read from the model and what the recipe asks of it."""
    values = derived_values(robot, legged)
    loco, terrain = values["locomotion"], values["terrain"]
    clock = f", trot clock {loco['gait_period']:.2f} s" if loco["gait_period"] else ""
    scales = robot.action_scales(legged.action_scale, legged.get("saturation_cap", True))
    reach = f"{min(scales):.2f}" + (f"-{max(scales):.2f}" if max(scales) > min(scales) else "")
    dt = loco["physics_dt"]
    command = loco["command"]
    if command["kind"] == "velocity":  # a joystick: what it is told, not a step and a target speed it has not
        span = lambda r, unit: f"{r[0]:+.2f} to {r[1]:+.2f} {unit}"  # noqa: E731
        task = (f"commands vx {span(command['vx'], 'm/s')}, vy {span(command['vy'], 'm/s')}, yaw "
                f"{span(command['yaw'], 'rad/s')}, {command['stand_share']:.0%} standing, drawn again every "
                f"{command['resample'][0]:.1f}-{command['resample'][1]:.1f} s")
    else:
        task = (f"step {terrain['eval_step_height'] * 100:.1f} cm ({legged.step_height:g} l), speed up to "
                f"{loco['target_speed']:.2f} m/s")
    return (f"{robot.describe()}; recipe: {task}, fall under {loco['healthy_z_range'][0] * 100:.1f} cm, actions move "
            f"joints up to {reach} rad, control every {loco['frame_skip'] * dt * 1000:g} ms (physics "
            f"{dt * 1000:g} ms, contacts: {loco['contacts']}){clock}")


def scaled_env(env_cfg, robot: Robot):
    """env_cfg with env.legged's targets turned into env.locomotion and env.terrain values for `robot`
    (a copy; the config a run saves keeps the targets, so evaluate derives the same values again)."""
    from ppo_torchrl.config import LocomotionConfig, TerrainConfig

    defaults = {"locomotion": LocomotionConfig(), "terrain": TerrainConfig()}
    for group, keys in DERIVED.items():
        for key, source in keys.items():
            given = env_cfg[group].get(key)
            given = OmegaConf.to_container(given) if OmegaConf.is_config(given) else given
            default = getattr(defaults[group], key)
            default = dataclasses.asdict(default) if dataclasses.is_dataclass(default) else default
            if given != default:
                where = f"env.legged.{source}" if source else "the robot's model"
                raise ConfigError(f"env.{group}.{key}={given}: env=legged derives it from {where} (robots/recipe.py); "
                                  f"leave env.{group}.{key} unset" + (f" and set {where}" if source else ""))
    scaled = OmegaConf.create(OmegaConf.to_container(env_cfg))
    flat = env_cfg.legged.get("terrain", TERRAINS[0]) == "flat"
    for group, values in derived_values(robot, env_cfg.legged).items():
        if group == "terrain" and flat:  # flat ground: no step, no curriculum, nothing of the step derived
            scaled.terrain.curriculum = False
            continue
        for key, value in values.items():
            scaled[group][key] = value
    return scaled


TERRAINS = ("step", "flat")  # env.legged.terrain: a step across the path (the climb recipes'), or flat ground


def legged_checks(legged) -> list:
    """env.legged: positive scales, [min, max] ranges (validation.py calls it)."""
    if legged is None:
        return []
    positive = ("action_scale", "control_dt", "target_speed", "fall_height", "too_high", "step_height",
                "success_margin", "height_sample_spacing", "curriculum_step")
    checks = [(legged[k] > 0, f"env.legged.{k}={legged[k]} must be > 0") for k in positive]
    checks += [(legged[k] >= 0, f"env.legged.{k}={legged[k]} must be >= 0")
               for k in ("forward_reward_weight", "gait_clock_weight", "long_swing_cost_weight", "long_swing_limit",
                         "stumble_cost_weight", "torque_cost_weight", "joint_speed_cost_weight",
                         "foot_slip_cost_weight", "base_height_cost_weight")]
    contacts, dt = legged.get("contacts", CONTACT_MODES[0]), str(legged.get("physics_dt") or "model")
    checks.append((contacts in CONTACT_MODES, f"env.legged.contacts={contacts} is not known; use "
                   + " or ".join(CONTACT_MODES) + " (robots/model.py, filter_contacts)"))
    try:
        seconds = None if dt in PHYSICS_STEPS else float(dt)
    except ValueError:
        seconds = math.nan
    whole = seconds is None or (0 < seconds <= legged.control_dt
                                and abs(legged.control_dt / seconds - round(legged.control_dt / seconds)) < 1e-6)
    checks.append((whole, f"env.legged.physics_dt={dt} must be rule, model or a step in seconds that divides "
                          f"env.legged.control_dt={legged.control_dt} into whole steps"))
    cone = legged.get("friction_cone", FRICTION_CONES[0])
    checks.append((cone in FRICTION_CONES, f"env.legged.friction_cone={cone} is not known; use "
                   + " or ".join(FRICTION_CONES)))
    terrain = legged.get("terrain", TERRAINS[0])
    checks.append((terrain in TERRAINS, f"env.legged.terrain={terrain} is not known; use " + " or ".join(TERRAINS)))
    obs_layout = legged.get("obs_layout", OBS_LAYOUTS[0])
    checks.append((obs_layout in OBS_LAYOUTS, f"env.legged.obs_layout={obs_layout} is not known; use "
                   + " or ".join(OBS_LAYOUTS) + " (layout.py)"))
    obs_frame = legged.get("obs_frame", OBS_FRAMES[0])
    checks.append((obs_frame in OBS_FRAMES, f"env.legged.obs_frame={obs_frame} is not known; use "
                   + " or ".join(OBS_FRAMES)))
    checks.append((legged.fall_height < legged.too_high,
                   f"env.legged.fall_height={legged.fall_height} must be under env.legged.too_high={legged.too_high}"))
    checks.append((legged.gait_period is None or legged.gait_period > 0,
                   f"env.legged.gait_period={legged.gait_period} must be > 0 (x sqrt(l / g)) or null"))
    checks.append((legged.curriculum_band is None or legged.curriculum_band > 0,
                   f"env.legged.curriculum_band={legged.curriculum_band} must be > 0 (x l) or null"))
    for key, floor in (("step_height_range", 0), ("step_distance", 1e-9)):
        span = list(legged[key])
        checks.append((len(span) == 2 and span[0] >= floor and span[0] <= span[1],
                       f"env.legged.{key}={span} must be [min, max] with {'0 <= min' if floor == 0 else '0 < min'} <= max"))
    return checks
