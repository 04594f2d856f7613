"""Which gait does a legged run's policy use, and do its foot contacts read right? For each run dir, on flat ground,
deterministic episodes of its checkpoint through the Python API (`ppo_torchrl.load`, normalization frozen) on its
eval env (a batch of one row, envs.make_batch), read after every control step as the sweeps read them:
- the share of steps with 0, 1, 2, 3 and 4 feet down, and with each foot pattern that names a gait: both diagonal
  feet of one pair down and the other pair up (a trot), both feet of one side (a pace), both fore or both hind (a
  bound); 0 feet down is flight, 4 a pronk's stance;
- the share of steps each kind of robot geom touches the ground: the feet, the other geoms of the feet's bodies
  (a shank capsule) and the geoms of the other bodies (a thigh, the trunk): where a non-foot geom carries the robot,
  the feet's share of time down understates its stance;
- the trunk's height (min, mean, max) in leg lengths l;
- each foot's share of steps down, and its body's (the foot or another geom of the foot's body, such as the shank
  capsule): where the body's share is well above the foot's, the leg stands on its shank, not its foot.

    .venv/bin/python benchmarks/gait_check.py <run dir> [...] [--seed 60] [--episodes 10] [--out <table.md>]

Episode seeds are `seed*1000 + i` as in `evaluate seed=` (60 -> 60000-60009, a sweep's first ten). Bad input (a
missing dir, a run that is not env=legged, --episodes 0, a directory as --out) is one `error:` line and exit 2, before
any episode runs or anything is written (cli_args.py).
"""

import sys
from pathlib import Path

import numpy as np
from cli_args import ConfigError, Parser, existing_dir, out_file, positive_int, seed
from cli_args import run as run_main

import ppo_torchrl
from ppo_torchrl.envs.make import episode_seeds, make_batch
from ppo_torchrl.robots.gait import CORNERS, FOOT_PAIRS
from ppo_torchrl.tasks.locomotion.sensors import Contacts
from ppo_torchrl.tasks.locomotion.world import FOOT, NON_FOOT, OTHER

PATTERNS = {"trot": "diagonal", "pace": "same_side", "bound": "same_end"}  # one pair down, the other pair up


def legged_policy(run: Path):
    """The run's last checkpoint as a policy, or one line: a run of another kind has no robot read from its model."""
    policy = ppo_torchrl.load(run, checkpoint="last")
    if policy.config.env.get("legged") is None or not policy.config.env.get("xml_file"):
        raise ConfigError(f"{run} is a run of {policy.config.env.id}, not of env=legged: gait_check reads the feet of "
                          "a robot read from its model (a run of experiment=legged_trot_v2, make robot)")
    return policy


def check(run: Path, seed: int, episodes: int, policy=None) -> dict:
    policy = policy or legged_policy(run)
    env_cfg = policy.config.env
    env_cfg.terrain.step_height = 0.0
    batch = make_batch(env_cfg, 1, evaluation=True)  # one row: the episodes one after another, as evaluate's seeds
    world, data = batch.world, batch.datas[0]
    sensor = Contacts(1, world)
    corners = list(world.corners or CORNERS)
    pairs = {gait: [[corners.index(c) for c in pair] for pair in FOOT_PAIRS[kind]] for gait, kind in PATTERNS.items()}
    foot_body = world.model.geom_bodyid[world.feet]
    down, body_down, touching, heights = [], [], {"feet": 0, "foot bodies' other geoms": 0, "other bodies": 0}, []
    for s in episode_seeds(seed, episodes):
        observation, _ = batch.reset(seed=s)
        while True:
            observation, _, terminated, truncated, _ = batch.step(policy.predict(observation))
            partners, _ = sensor.partners(data)  # the geoms on the terrain after the step, as the sweeps read them
            down.append(np.isin(world.feet, partners))
            kinds = set(world.kind[partners].tolist())
            body_down.append(np.isin(foot_body, world.model.geom_bodyid[partners]))
            for kind, name in ((FOOT, "feet"), (OTHER, "foot bodies' other geoms"), (NON_FOOT, "other bodies")):
                touching[name] += kind in kinds
            heights.append(float(data.xpos[world.trunk][2]))
            if terminated[0] or truncated[0]:
                break
    batch.close()
    down = np.array(down)
    n = len(down)
    row = {"run": run.name, "steps": n, "feet": " ".join(corners)}
    row.update({f"{k} down": float(np.mean(down.sum(1) == k)) for k in range(5)})
    for gait, (a, b) in pairs.items():
        one = down[:, a].all(1) & ~down[:, b].any(1)
        other = down[:, b].all(1) & ~down[:, a].any(1)
        row[gait] = float(np.mean(one | other))
    row.update({f"touching: {k}": v / n for k, v in touching.items()})
    l = world.robot.leg_length
    row["trunk height / l (min mean max)"] = " ".join(f"{h / l:.2f}" for h in (min(heights), np.mean(heights),
                                                                               max(heights)))
    row["each foot down"] = " ".join(f"{x:.2f}" for x in down.mean(0))
    row["each foot's body down"] = " ".join(f"{x:.2f}" for x in np.mean(body_down, 0))
    return row


def main(argv=None) -> int:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=existing_dir)
    parser.add_argument("--seed", type=seed, default=60)
    parser.add_argument("--episodes", type=positive_int, default=10)
    parser.add_argument("--out", type=out_file, default=None)
    args = parser.parse_args(argv)
    policies = [legged_policy(run) for run in args.runs]  # every run's kind, before any episode
    rows = [check(run, args.seed, args.episodes, policy) for run, policy in zip(args.runs, policies)]
    columns = list(rows[0])
    lines = [f"Gait check: `python benchmarks/gait_check.py {' '.join(str(r) for r in args.runs)} --seed {args.seed} "
             f"--episodes {args.episodes}`; flat ground, deterministic, episode seeds {args.seed * 1000}-"
             f"{args.seed * 1000 + args.episodes - 1}; shares of control steps.", "",
             "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(f"{r[c]:.2f}" if isinstance(r[c], float) else str(r[c]) for c in columns) + " |"
              for r in rows]
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
