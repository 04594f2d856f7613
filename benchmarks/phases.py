"""Time the two phases of the training loop separately: collect vs update, per 2048-frame batch.

    .venv/bin/python benchmarks/phases.py [--as-configured] [overrides, e.g. compile=true collector.backend=torchrl]

Builds a Trainer from the composed config (Hopper-v4 with the speed issue's settings; with --as-configured, the
overrides alone, e.g. `--as-configured experiment=quadruped_trot`), runs 6 batches and reports the mean of the
last 5 (the first one includes warm-up and, with compile=true, compilation).
"""

import sys
import time
import warnings
from pathlib import Path

warnings.filterwarnings("ignore")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from conftest import compose_config  # noqa: E402
from speed import SB3_IDENTICAL  # noqa: E402  (the speed issue's settings, not the tuned per-env ones)
from ppo_torchrl.trainer import Trainer  # noqa: E402

as_configured = sys.argv[1:2] == ["--as-configured"]
base = [] if as_configured else ["env=Hopper-v4", *SB3_IDENTICAL]
cfg = compose_config([*base, "eval.every_frames=0", "eval.final_episodes=0", "logger=none", "checkpoint.every_frames=0",
                      *sys.argv[1 + as_configured:]])
trainer = Trainer(cfg, Path("outputs") / "bench_phases")
collect_s = update_s = 0.0
for i in range(6):
    t0 = time.perf_counter()
    batch = trainer.collector.collect()
    t1 = time.perf_counter()
    trainer.update(batch)
    t2 = time.perf_counter()
    if i:
        collect_s, update_s = collect_s + t1 - t0, update_s + t2 - t1
frames = cfg.collector.frames_per_batch * 5
print(f"collect {collect_s / 5 * 1e3:.0f} ms/batch  update {update_s / 5 * 1e3:.0f} ms/batch  "
      f"-> {frames / (collect_s + update_s):.0f} frames/s in-loop")
