"""The tuning table of the legged recipe (issue 46): for each tuning run, its overrides, the trainer's periodic
evals (success at the eval step of 0.25 l, forward speed, return; 10 episodes each, the decision episodes) and the
curriculum's level (m and in leg lengths) at each million frames, read from the run's metrics.csv.

    python benchmarks/tuning_table.py NAME=RUN_DIR[:NOTE] ... > results/robots/tuning_<date>/table.md
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import yaml

from ppo_torchrl.envs.make import resolve_model_file
from ppo_torchrl.records import open_record
from ppo_torchrl.robots.model import read_robot


def rows(run: Path) -> list:
    with open_record(run / "metrics.csv", newline="") as f:
        return list(csv.DictReader(f))


def main(argv: list) -> None:
    print("| run | overrides (besides experiment=legged_trot, env.xml_file, seed, logger) | frames | "
          "eval at 0.25 l per million frames: success / speed m/s | curriculum level at each million: m (x l) |")
    print("|---|---|---|---|---|")
    for arg in argv:
        name, rest = arg.split("=", 1)
        path, _, note = rest.partition(":")
        run = Path(path)
        table = rows(run)
        overrides = [o for o in yaml.safe_load((run / ".hydra" / "overrides.yaml").read_text())
                     if not o.split("=")[0] in ("experiment", "env.xml_file", "seed", "logger")]
        config = yaml.safe_load((run / "config.yaml").read_text())
        leg = read_robot(resolve_model_file(config["env"]["xml_file"])).leg_length
        evals = [f"{int(r['frames']) / 1e6:.0f}M {float(r['eval/success_rate']):.0%} / {float(r['eval/forward_velocity']):.2f}"
                 for r in table if r["eval/return_mean"]]
        levels, mark = [], 1_000_000
        for r in table:
            if int(r["frames"]) >= mark:
                level = float(r["env/terrain_level"])
                levels.append(f"{mark // 1_000_000}M {level:.3f} ({level / leg:.2f} l)")
                mark += 1_000_000
        print(f"| {name} | {' '.join(overrides) or '-'}{' (' + note + ')' if note else ''} | {int(table[-1]['frames']):,} "
              f"| {'; '.join(evals) or '-'} | {'; '.join(levels) or '-'} |")


if __name__ == "__main__":
    main(sys.argv[1:])
