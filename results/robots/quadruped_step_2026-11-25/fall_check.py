"""How a step policy's failed episodes end: python fall_check.py <run dir> <height m> <episodes> [seed] [stochastic]

Deterministic episodes (checkpoint best) on episode seeds seed*1000 on (default 7: 7000-..., never used
for a reported figure). Prints the share that cross, fall (the episode ends before its time limit) or
time out short of the line; how the falls end (the trunk under the fall line or a terrain contact of a
terminate_on_contact body); and the trunk height above the terrain under it, in the second before each
fall and over whole episodes that run out their time.
"""

import sys
from pathlib import Path

import numpy as np

import ppo_torchrl.locomotion as locomotion
from ppo_torchrl.checkpoint import load_policy
from ppo_torchrl.evaluate import apply_overrides, run_episodes


def main(run, height, episodes, seed=7, stochastic=False):
    cfg, ac, state = load_policy(Path(run), "best")
    cfg = apply_overrides(cfg, [f"env.terrain.step_height={height}"])
    heights, ends = [[]], []
    step = locomotion.LocomotionEnv.step

    def record(self, action):
        out = step(self, action)
        trunk = self.data.xpos[self._body_id]
        heights[-1].append(float(trunk[2] - self.terrain_height(np.array(self._along(trunk)))))
        if out[2]:
            ends.append("contact" if self.touches_ground() else "trunk under the line")
        if out[2] or len(heights[-1]) >= cfg.env.max_episode_steps:
            heights.append([])
        return out

    locomotion.LocomotionEnv.step = record
    seeds = [seed * 1000 + i for i in range(episodes)]
    result = run_episodes(cfg, ac, state["normalization"]["obs"], seeds, deterministic=not stochastic, progress=False)
    lengths, crossed = np.array(result["lengths"]), np.array(result["crossed"])
    fell = lengths < cfg.env.max_episode_steps
    per_episode = [np.array(h) for h in heights if h]
    second = int(round(1.0 / result["dt"]))
    before_fall = [h[-second:].mean() for h, f in zip(per_episode, fell) if f]
    full = [h.mean() for h, f in zip(per_episode, fell) if not f]
    print(f"{run} @ {state['frames']} frames, {height} m step, {episodes} {'stochastic' if stochastic else 'deterministic'} "
          f"episodes (seeds {seeds[0]}-{seeds[-1]}): cross {crossed.mean():.0%}, fall {fell.mean():.0%} "
          f"({ends.count('trunk under the line')} trunk under the line, {ends.count('contact')} contact; "
          f"{np.mean(lengths[fell] < second * 2):.0%} of falls in the first 2 s), time out short of the line "
          f"{np.mean(~fell & ~crossed):.0%}; trunk above the terrain: {np.mean(before_fall):.2f} m over the second "
          f"before a fall, {np.mean(full):.2f} m over episodes that run their time")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0], float(args[1]), int(args[2]), *(int(a) for a in args[3:4]), *(a == "stochastic" for a in args[4:5]))
