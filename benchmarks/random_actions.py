"""How long a robot of env=legged survives random actions: control steps until an episode ends (and why), over
20 episodes with actions N(0, 1) clipped to [-1, 1], the curriculum off (a flat start). A quick read of how hard
the recipe's action range makes a robot to explore, before any training (issue 46's tuning).

    python benchmarks/random_actions.py ../shared/robots/unitree_go1/scene.xml [env.legged.action_scale=0.25 ...]
"""

from __future__ import annotations

import collections
import sys

import numpy as np

from ppo_torchrl.compose import compose
from ppo_torchrl.envs import make_gym_env


def main(model: str, overrides: list, episodes: int = 20) -> None:
    cfg = compose(["experiment=legged_trot", f"env.xml_file={model}", "env.terrain.curriculum=false", *overrides])
    env = make_gym_env(cfg.env)
    rng = np.random.default_rng(0)
    lengths, ends = [], collections.Counter()
    for episode in range(episodes):
        env.reset(seed=episode)
        for n in range(1, 10**6):
            _, _, terminated, truncated, _ = env.step(np.clip(rng.normal(size=env.action_space.shape), -1, 1))
            if terminated or truncated:
                lengths.append(n)
                ends[str(env.unwrapped.termination)] += 1
                break
    scales = env.unwrapped._ctrl_per_action
    print(f"{model}: {np.mean(lengths):.1f} control steps per episode (min {min(lengths)}), ends {dict(ends)}, "
          f"action scale {scales.min():.3f}-{scales.max():.3f} rad")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
