"""Facts of a MuJoCo model file that every env of one needs: whether it can run (a free joint, actuators with control
bounds: `check_mjcf`), and, for filming, a floor drawn to the horizon (`floor_to_the_horizon`)."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ppo_torchrl.errors import ConfigError


@dataclass(frozen=True)
class MjcfInfo:
    cameras: tuple  # camera names
    bodies: tuple  # body names, by id
    ctrl_from_force: tuple  # (actuator id, low, high): no ctrlrange, control bounds from its forcerange


@functools.lru_cache(maxsize=None)
def check_mjcf(path: Path) -> MjcfInfo:
    """The model must compile in MuJoCo, have a free-floating base and at least one actuator, each
    actuator with control bounds: its ctrlrange or, without one, its forcerange / gear."""
    import mujoco

    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:
        first = next((l.strip() for l in str(exc).splitlines() if l.strip()), type(exc).__name__)
        raise ConfigError(f"env.xml_file={path} is not a valid MuJoCo model: {first}") from None
    if not (model.jnt_type == mujoco.mjtJoint.mjJNT_FREE).any():
        raise ConfigError(f"env.xml_file={path} has no free joint: env=mjcf needs a free-floating base "
                          "(add <freejoint/> to the robot's root body)")
    if model.nu == 0:
        raise ConfigError(f"env.xml_file={path} has no actuators: there is nothing for the policy to control")
    from_force = []
    for i in range(model.nu):
        low, high = model.actuator_ctrlrange[i]
        if model.actuator_ctrllimited[i] and low < high:
            continue
        gear = float(model.actuator_gear[i][0]) or 1.0
        if not (model.actuator_forcelimited[i] and model.actuator_forcerange[i][0] < model.actuator_forcerange[i][1]):
            raise ConfigError(f"env.xml_file={path}: actuator '{model.actuator(i).name or i}' has no ctrlrange (nor "
                              "forcerange), so its action bounds would be [0, 0]; give it ctrlrange=\"low high\"")
        bounds = sorted(float(f) / gear for f in model.actuator_forcerange[i])
        from_force.append((i, bounds[0], bounds[1]))
    return MjcfInfo(cameras=tuple(model.camera(i).name for i in range(model.ncam)),
                    bodies=tuple(model.body(i).name for i in range(model.nbody)), ctrl_from_force=tuple(from_force))


FLOOR_DRAWN_M = 500.0  # half-width a filmed floor is drawn to


def floor_to_the_horizon(env) -> None:
    """A MuJoCo plane collides everywhere but is drawn only within its size: Gymnasium's Hopper floor ends
    at 20 m, which its best policies pass in 1000 steps and then hop over the void. For filming, planes are
    drawn FLOOR_DRAWN_M wide, their texture repeated in proportion (the same squares); nothing the physics
    reads changes."""
    import mujoco

    model = env if isinstance(env, mujoco.MjModel) else getattr(env, "model", None)  # a model, or an env with one
    if not isinstance(model, mujoco.MjModel):  # not a MuJoCo env (env=gym Pendulum-v1): nothing to widen
        return
    for g in np.flatnonzero(model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE):
        size = model.geom_size[g, :2].copy()
        if size.min() <= 0 or size.min() >= FLOOR_DRAWN_M:  # 0: drawn without end already
            continue
        model.geom_size[g, :2] = FLOOR_DRAWN_M
        material = model.geom_matid[g]
        if material >= 0 and not model.mat_texuniform[material]:
            model.mat_texrepeat[material] *= FLOOR_DRAWN_M / size
