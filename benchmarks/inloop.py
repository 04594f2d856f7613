"""The training loop's frames/s for one config, start-up and compilation left out: builds a Trainer, runs
`--batches` batches (collect + update) and times the last `--batches - 2`. Prints one JSON line.

    .venv/bin/python benchmarks/inloop.py [--batches 8] env=Hopper-v4 collector.workers=2 ...
"""

import argparse
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

warnings.filterwarnings("ignore")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from conftest import compose_config  # noqa: E402
from ppo_torchrl.trainer import Trainer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--batches", type=int, default=8)
    args, overrides = parser.parse_known_args()
    cfg = compose_config(["eval.every_frames=0", "eval.final_episodes=0", "logger=none", "checkpoint.every_frames=0",
                          *overrides])
    with tempfile.TemporaryDirectory() as run_dir:
        trainer = Trainer(cfg, Path(run_dir))
        collect_s = update_s = 0.0
        try:
            for i in range(args.batches):
                t0 = time.perf_counter()
                batch = trainer.collector.collect()
                t1 = time.perf_counter()
                trainer.update(batch)
                t2 = time.perf_counter()
                if i >= 2:  # the first two: warm-up (and, with compile, compilation)
                    collect_s, update_s = collect_s + t1 - t0, update_s + t2 - t1
        finally:
            trainer.collector.close()
    timed = args.batches - 2
    frames = cfg.collector.frames_per_batch * timed
    print(json.dumps({"collect_ms": collect_s / timed * 1e3, "update_ms": update_s / timed * 1e3,
                      "frames_per_s": frames / (collect_s + update_s)}))


if __name__ == "__main__":
    main()
