"""Which robot geoms other than the feet touch the ground, per control step, in one deterministic episode
of quadruped_realistic_200k (checkpoint last, eval seed 0). Run from the repo root:
    python benchmarks/contacts_by_geom.py <run dir>
"""
import collections
import sys

import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl.checkpoint import load_policy
from ppo_torchrl.envs import make_torchrl_env

cfg, ac, state = load_policy(sys.argv[1], "last")
env = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99, obs_stats=state["normalization"]["obs"], train=False)
loco = env.base_env._env.unwrapped
model, data = loco.model, loco.data
root = model.body_rootid[model.body("trunk").id]
ground = {g for g in range(model.ngeom) if model.body_weldid[model.geom_bodyid[g]] == 0}
robot_not_feet = {g for g in range(model.ngeom) if model.body_rootid[model.geom_bodyid[g]] == root} - set(loco.feet.tolist())
counts, steps = collections.Counter(), [0]


def count(*_):
    steps[0] += 1
    touching = {b for a, b in [tuple(p) for p in data.contact.geom] + [tuple(p[::-1]) for p in data.contact.geom]
                if a in ground and b in robot_not_feet}
    counts.update(model.geom(g).name for g in touching)


env.set_seed(0)
start = env.reset()
with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
    env.rollout(1000, policy=ac.actor, break_when_any_done=True, auto_reset=False, tensordict=start, callback=count)
print(f"{steps[0]} control steps; share of steps each non-foot robot geom touches the ground:")
for name, n in counts.most_common():
    print(f"  {name}: {n / steps[0]:.3f}")
