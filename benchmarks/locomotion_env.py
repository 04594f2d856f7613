"""Steps per second of the locomotion env alone (no policy, no torch), for env-side speed work.

    .venv/bin/python benchmarks/locomotion_env.py [steps] [overrides, e.g. env=quadruped]

Steps `experiment=quadruped_climb`'s env (contacts and terrain heights observed, the speed-limit cost
read at every physics step, trunk-contact ends) with fixed random actions from seed 0, resetting on
each end. To compare two commits, run it in a `git worktree` of each, at the same time on separate cores
(`taskset -c 0` / `taskset -c 1`), and swap the cores for a second round.
"""

import sys
import time
import warnings
from pathlib import Path

import numpy as np

warnings.filterwarnings("ignore")
ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's package, not the one installed in the venv

from conftest import compose_config  # noqa: E402
from ppo_torchrl.envs import make_gym_env  # noqa: E402

steps = int(sys.argv[1]) if len(sys.argv) > 1 else 8000
env = make_gym_env(compose_config(["experiment=quadruped_climb", *sys.argv[2:]]).env)
actions = np.random.default_rng(0).uniform(-0.3, 0.3, (steps, env.action_space.shape[0])).astype(np.float32)
env.reset(seed=0)
start = time.perf_counter()
for action in actions:
    _, _, terminated, truncated, _ = env.step(action)
    if terminated or truncated:
        env.reset()
print(f"{steps / (time.perf_counter() - start):.0f} env steps/s")
