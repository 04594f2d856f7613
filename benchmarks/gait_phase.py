"""Does a policy trained with a trot clock (env.locomotion.gait_period) follow it? One deterministic episode of
a run's checkpoint on its eval env; for each twelfth of the clock's period, the share of steps each foot is on
the ground, and the share of feet whose contact matches the clock's schedule (LF+RH down in the first half,
RF+LH in the second). A trot that follows the clock reads ~1 for LF and RH in bins 0-5 and for RF and LH in
bins 6-11.

    .venv/bin/python benchmarks/gait_phase.py <run dir> [--checkpoint last] [--seed 12345] [--height 0.0]
"""

import argparse
import warnings
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

warnings.filterwarnings("ignore")

from ppo_torchrl.run.checkpoint import load_policy  # noqa: E402
from ppo_torchrl.envs.make import make_batch  # noqa: E402
from ppo_torchrl.envs.normalization import make_observation_normalizer  # noqa: E402
from ppo_torchrl.tasks.locomotion.sensors import Contacts  # noqa: E402

BINS = 12


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("run", type=Path)
    parser.add_argument("--checkpoint", default="last")
    parser.add_argument("--seed", type=int, default=12345)
    parser.add_argument("--height", type=float, default=0.0, help="the step's height (m); 0: flat ground")
    args = parser.parse_args()
    cfg, ac, state = load_policy(args.run, args.checkpoint)
    cfg.env.terrain.step_height = args.height
    normalizer = make_observation_normalizer(cfg.env.transforms, len(state["normalization"]["obs"]["mean"]),
                                             state["normalization"]["obs"], frozen=True)
    batch = make_batch(cfg.env, 1, evaluation=True)  # one row (tasks/locomotion/batch.py)
    task, world = batch.task, batch.world
    sensor = Contacts(1, world)
    if task.clock_phase() is None:
        raise SystemExit("error: this run has no trot clock (env.locomotion.gait_period)")
    down, steps, match = np.zeros((BINS, len(world.feet))), np.zeros(BINS), []
    obs, _ = batch.reset(seed=args.seed)
    for _ in range(batch.max_steps):
        phase, meant = float(task.clock_phase()[0]), task.meant_down()[0]
        x = torch.as_tensor(normalizer(obs, update=False), dtype=torch.float32)[0]
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            action = ac.actor(TensorDict({"observation": x}, []))["action"]
        obs, _, terminated, truncated, _ = batch.step(action.numpy()[None])
        feet = np.isin(world.feet, sensor.partners(batch.datas[0])[0])  # each foot on the terrain after the step
        b = int(phase * BINS)
        down[b] += feet
        steps[b] += 1
        match.append(float((feet == meant).mean()))
        if terminated[0] or truncated[0]:
            break
    print(f"{args.run} ({args.checkpoint}), step {args.height:.2f} m, episode seed {args.seed}: {len(match)} steps, "
          f"clock period {cfg.env.locomotion.gait_period} s; share of feet matching the clock: {np.mean(match):.3f}")
    print("| phase bin | " + " | ".join(world.corners or world.foot_names) + " |")
    print("|---|" + "---|" * len(world.feet))
    for b in range(BINS):
        print(f"| {b} | " + " | ".join(f"{v:.2f}" for v in down[b] / max(steps[b], 1)) + " |")


if __name__ == "__main__":
    main()
