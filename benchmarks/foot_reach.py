"""How high a foot of a robot read from its model (env=legged) can rise within the recipe's action range: over
every combination of -1, 0 and +1 actions on one leg's three joints (targets reached, the trunk still at the
standing pose; MuJoCo's kinematics only, no dynamics), the largest rise of that leg's foot above its standing
height, in m and leg lengths, beside the step of 0.25 l (issue 46's tuning).

    python benchmarks/foot_reach.py ppo_torchrl/assets/menagerie/unitree_go1/scene.xml [env.legged.saturation_cap=true ...]
"""

from __future__ import annotations

import itertools
import sys

import mujoco

from ppo_torchrl.compose import compose
from ppo_torchrl.envs.make import make_batch


def main(model_file: str, overrides: list) -> None:
    cfg = compose(["experiment=legged_trot", f"env.xml_file={model_file}", *overrides])
    world = make_batch(cfg.env, 1).world  # the batch's compiled model and what the task reads of it (world.py)
    model, data, robot = world.model, mujoco.MjData(world.model), world.robot
    joints = [int(model.actuator_trnid[a, 0]) for a in range(model.nu)]
    leg_root = model.jnt_bodyid[joints[0]]  # the first leg: the actuators on the first joint's subtree

    def on_leg(body: int) -> bool:
        while body > 0:
            if body == leg_root:
                return True
            body = model.body_parentid[body]
        return False

    leg = [a for a, j in enumerate(joints) if on_leg(model.jnt_bodyid[j])]
    foot = next(int(f) for f in world.feet if on_leg(model.geom_bodyid[f]))
    scales = world.ctrl_per_action / model.actuator_gear[:, 0]
    data.qpos[:] = robot.qpos
    mujoco.mj_kinematics(model, data)
    standing = data.geom_xpos[foot][2]
    best = 0.0
    for signs in itertools.product((-1, 0, 1), repeat=len(leg)):
        data.qpos[:] = robot.qpos
        for a, sign in zip(leg, signs):
            data.qpos[model.jnt_qposadr[joints[a]]] += sign * scales[a]
        mujoco.mj_kinematics(model, data)
        best = max(best, data.geom_xpos[foot][2] - standing)
    l = robot.leg_length
    print(f"{robot.name}: joints move up to {', '.join(f'{scales[a]:.3f}' for a in leg)} rad; the foot rises at most "
          f"{best:.3f} m = {best / l:.2f} l (the step: {0.25 * l:.3f} m = 0.25 l)")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
