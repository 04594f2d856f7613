"""How often a policy's joints pass the drives' speed line, sampled at every physics step.

python joint_speed_check.py <run dir> [height m] [episodes] [seed]   (deterministic episodes, checkpoint best)

Prints the peak actuated joint speed (eval's figure), the share of physics steps in which any actuated
joint is over env.locomotion.joint_speed_limit, and high percentiles of the per-step maximum. The drive's
torque-speed line (locomotion.py) keeps its own torque from driving a joint past the limit, so a joint
over it was pushed there by contacts or by the motion of the rest of the body.
"""

import sys
from pathlib import Path

import numpy as np

import ppo_torchrl.locomotion as locomotion
from ppo_torchrl.checkpoint import load_policy
from ppo_torchrl.evaluate import apply_overrides, run_episodes


def main(run, height=0.15, episodes=20, seed=1):
    cfg, ac, state = load_policy(Path(run), "best")
    cfg = apply_overrides(cfg, [f"env.terrain.step_height={height}"])
    speeds = []  # the highest actuated joint speed of each physics step (GaitMeter.add's joint_speed)
    add = locomotion.GaitMeter.add

    def record(self, feet, joint_speed, body_contact, dt):
        speeds.append(joint_speed)
        return add(self, feet, joint_speed, body_contact, dt)

    locomotion.GaitMeter.add = record
    result = run_episodes(cfg, ac, state["normalization"]["obs"], [seed * 1000 + i for i in range(episodes)],
                          progress=False)
    speeds = np.array(speeds)
    limit = cfg.env.locomotion.joint_speed_limit
    print(f"{run} @ {state['frames']} frames, {height} m step, {episodes} episodes (seeds {seed * 1000}-"
          f"{seed * 1000 + episodes - 1}), {len(speeds)} physics steps: {np.mean(result['crossed']):.0%} cross; "
          f"peak joint speed {speeds.max():.1f} rad/s (limit {limit}); over the limit in {np.mean(speeds > limit):.2%} "
          f"of physics steps; percentiles 99 / 99.9: {np.percentile(speeds, 99):.1f} / {np.percentile(speeds, 99.9):.1f} rad/s")


if __name__ == "__main__":
    main(sys.argv[1], *(float(a) for a in sys.argv[2:3]), *(int(a) for a in sys.argv[3:5]))
