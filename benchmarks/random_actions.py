"""How long a robot of env=legged survives random actions: control steps until an episode ends (and why), over
20 episodes with actions N(0, std^2) clipped to [-1, 1], std the recipe's initial policy std (exp(policy.log_std_init)
+ policy.std_min), the curriculum off (a flat start). A quick read of how hard the recipe's action range and
exploration make a robot to explore, before any training (issue 46's tuning).

    python benchmarks/random_actions.py ppo_torchrl/assets/menagerie/unitree_go1/scene.xml [--episodes 20] [env.legged.action_scale=0.25 ...]

Falls are chaotic: 20 episodes move by ~+-15 control steps with the noise's std in the third digit; use 100+
to compare two settings.
"""

from __future__ import annotations

import collections
import math
import sys

import numpy as np

from ppo_torchrl.compose import compose
from ppo_torchrl.envs.make import make_batch


def main(model: str, overrides: list, episodes: int = 20) -> None:
    cfg = compose(["experiment=legged_trot", f"env.xml_file={model}", "env.terrain.curriculum=false", *overrides])
    batch = make_batch(cfg.env, 1)  # one row (tasks/locomotion/batch.py)
    std = math.exp(cfg.policy.log_std_init) + cfg.policy.std_min
    rng = np.random.default_rng(0)
    lengths, ends = [], collections.Counter()
    for episode in range(episodes):
        batch.reset(seed=episode)
        for n in range(1, 10**6):
            _, _, terminated, truncated, _ = batch.step(np.clip(std * rng.normal(size=batch.action_space.shape), -1, 1))
            if terminated[0] or truncated[0]:
                lengths.append(n)
                ends[str(batch.task.termination(0))] += 1
                break
    scales = batch.world.ctrl_per_action
    print(f"{model}: {np.mean(lengths):.1f} control steps per episode (min {min(lengths)}), ends {dict(ends)}, "
          f"action scale {scales.min():.3f}-{scales.max():.3f} rad, std {std:.2f}")


if __name__ == "__main__":
    args = sys.argv[2:]
    episodes = 20
    if "--episodes" in args:
        at = args.index("--episodes")
        episodes = int(args[at + 1])
        args = args[:at] + args[at + 2:]
    main(sys.argv[1], args, episodes)
