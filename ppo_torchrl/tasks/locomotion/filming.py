"""What a filmed robot needs in its model (only the rendered copy: no contact or force reads these): a `track`
camera on the main body where the model has none, and, for models whose visual meshes were left out (Menagerie's
keep collision geoms in group 3, which MuJoCo does not draw), the robot's group-3 geoms drawn."""

from __future__ import annotations

import math

import mujoco
import numpy as np

DRAWN_GROUPS = 3  # MuJoCo's default visual options draw geom groups 0, 1 and 2
HIDDEN_GROUP = 3  # where MuJoCo Menagerie's models keep their collision geoms
TRACK = "track"


def draw_hidden_robot(spec) -> bool:
    """Moves the robot's group-3 geoms into group 0 when none of its geoms (those of a body under a free joint) is
    drawn (groups 0-2, not transparent); True if it did. (spec.bodies lists the bodies in the compiled order.)"""
    plain = spec.compile()
    free_roots = {plain.jnt_bodyid[j] for j in range(plain.njnt) if plain.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE}
    on_robot = np.isin(plain.body_rootid, list(free_roots))  # per body
    robot_geoms = on_robot[plain.geom_bodyid]
    drawn = robot_geoms & (plain.geom_group < DRAWN_GROUPS) & (plain.geom_rgba[:, 3] > 0)
    if drawn.any():
        return False
    hidden = [g for body, robot in zip(spec.bodies, on_robot) if robot for g in body.geoms if g.group == HIDDEN_GROUP]
    for geom in hidden:
        geom.group = 0
    return bool(hidden)


def ground_heading(angle, axis_xy) -> np.ndarray:
    """The heading as a unit ground vector: an angle in degrees, else (None: auto) `axis_xy`."""
    if angle is None:
        return axis_xy / max(np.linalg.norm(axis_xy), 1e-9)
    return np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])


def add_track_camera(spec, main_body, heading) -> bool:
    """Adds the `track` camera on the main body (heading: degrees from +x, None for its own +x axis), beside it and
    looking at it, where the model has none; False (no
    camera: render from the free camera) where it has one already or the main body has no name."""
    plain = spec.compile()
    if any(plain.camera(i).name == TRACK for i in range(plain.ncam)):
        return False
    body = plain.body(main_body)
    data = mujoco.MjData(plain)
    mujoco.mj_kinematics(plain, data)
    sub = [g for g in range(plain.ngeom) if plain.body_rootid[plain.geom_bodyid[g]] == plain.body_rootid[body.id]]
    origin = data.xpos[body.id]
    extent = max([np.linalg.norm(data.geom_xpos[g] - origin) + plain.geom_rbound[g] for g in sub] or [0.5])
    heading = ground_heading(heading, data.xmat[body.id].reshape(3, 3)[:2, 0])
    left = np.array([-heading[1], heading[0], 0.0])
    forward = np.array([heading[0], heading[1], 0.0])
    distance = 4.0 * extent
    offset = -distance * left + 0.15 * distance * forward + np.array([0, 0, distance / 3])
    z_axis = offset / np.linalg.norm(offset)  # the camera looks along -z, at the body
    y_axis = np.cross(z_axis, forward)
    rotation = data.xmat[body.id].reshape(3, 3)  # world from body: the camera is given in the body's frame
    target = spec.body(plain.body(body.id).name) if plain.body(body.id).name else None
    if target is None:
        return False
    target.add_camera(name=TRACK, mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM, pos=rotation.T @ offset,
                      xyaxes=np.concatenate([rotation.T @ forward, rotation.T @ y_axis]))
    return True
