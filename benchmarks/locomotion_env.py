"""Steps per second of the locomotion env alone (no policy, no torch), for env-side speed work.

    .venv/bin/python benchmarks/locomotion_env.py [steps] [--hash] [overrides, e.g. env=quadruped]

Steps `experiment=quadruped_climb`'s env (contacts and terrain heights observed, the speed-limit cost
read at every physics step, trunk-contact ends) with fixed random actions from seed 0, resetting on
each end. To compare two commits, run it in a `git worktree` of each, at the same time on separate cores
(`taskset -c 0` / `taskset -c 1`), and swap the cores for a second round. `--hash` also prints a hash of the
trajectory (observations, rewards, ends and every info value): a rewrite that must give the same floats gives the
same hash (the rate is then lower, hashing included).
"""

import hashlib
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

args = sys.argv[1:]
steps = int(args.pop(0)) if args and args[0].isdigit() else 8000
digest = hashlib.sha256() if "--hash" in args else None
env = make_gym_env(compose_config(["experiment=quadruped_climb", *(a for a in args if a != "--hash")]).env)
actions = np.random.default_rng(0).uniform(-0.3, 0.3, (steps, env.action_space.shape[0])).astype(np.float32)
observation, _ = env.reset(seed=0)
start = time.perf_counter()
for action in actions:
    observation, reward, terminated, truncated, info = env.step(action)
    if digest is not None:
        digest.update(observation.tobytes() + np.float64(reward).tobytes() + bytes([terminated, truncated]))
        for key in sorted(info):
            value = info[key]
            digest.update(key.encode() + (value.tobytes() if isinstance(value, np.ndarray) else repr(value).encode()))
    if terminated or truncated:
        observation, _ = env.reset()
        if digest is not None:
            digest.update(observation.tobytes())
rate = f"{steps / (time.perf_counter() - start):.0f} env steps/s"
print(rate if digest is None else f"{rate}, trajectory hash {digest.hexdigest()[:16]}")
