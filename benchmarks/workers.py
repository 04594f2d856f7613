"""frames/s of one run on one process and on two (collector.workers=2), whole process, and the
collect/update split that projects more workers (docs/speed.md: "One run on several processes").

    .venv/bin/python benchmarks/workers.py [--frames 32768] [--out results/workers]

Runs, one after another: env=quadruped and env=Hopper-v4, each with FastCollector and TorchRL's
Collector in one process and in two (collector.workers=2: TorchRL's MultiSyncCollector building the
same class in each worker), eval and checkpoints off; then benchmarks/phases.py for both classes. Copies each
run's summary.json and config.yaml to --out and writes --out/table.md.
"""

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
VARIANTS = {"fast": ["collector.backend=fast"], "fast_workers2": ["collector.backend=fast", "collector.workers=2"],
            "torchrl": ["collector.backend=torchrl"],
            "torchrl_workers2": ["collector.backend=torchrl", "collector.workers=2"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=32_768)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "workers")
    parser.add_argument("--beside", default="nothing else running", help="what ran beside, for the table")
    parser.add_argument("--envs", default="quadruped,Hopper-v4")
    args = parser.parse_args()
    stamp = time.strftime("%Y-%m-%d_%H-%M-%S")
    lines = [f"# One run on one and two processes, {args.frames:,} frames, whole process", "",
             f"`python benchmarks/workers.py --frames {args.frames}` ({stamp}, 2-core CPU, {args.beside})", "",
             "| env | variant | frames/s (summary: frames / train time) | wall s (process, start-up included) |",
             "|---|---|---|---|"]
    measured = {}
    for env in args.envs.split(","):
        for name, overrides in VARIANTS.items():
            run = ROOT / "outputs" / "bench_workers" / stamp / f"{env}_{name}"
            cmd = [sys.executable, "-m", "ppo_torchrl", f"env={env}", f"collector.total_frames={args.frames}",
                   "eval.every_frames=0", "eval.final_episodes=0", "checkpoint.every_frames=0", "logger=none",
                   f"hydra.run.dir={run}", *overrides]
            tick = time.perf_counter()
            subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True)
            wall = time.perf_counter() - tick
            dest = args.out / f"{env}_{name}"
            dest.mkdir(parents=True, exist_ok=True)
            for file in ("summary.json", "config.yaml"):
                shutil.copy(run / file, dest / file)
            sps = json.loads((run / "summary.json").read_text())["sps"]
            measured[env, name] = sps
            lines.append(f"| {env} | {name} | {sps:,.0f} | {wall:.1f} |")
            print(lines[-1], flush=True)
    lines += ["", "Two workers against one process, the same collector class in each (frames/s ratio):", ""]
    for env in args.envs.split(","):
        for kind in ("fast", "torchrl"):
            lines.append(f"- {env}, {kind}: {measured[env, kind + '_workers2'] / measured[env, kind]:.2f}x")
    lines += ["", "Collect / update split per 2048-frame batch (Hopper-v4, SB3-identical settings, one process, "
              "`benchmarks/phases.py`):", ""]
    for backend in ("fast", "torchrl"):
        out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "phases.py"), f"collector.backend={backend}"],
                             cwd=ROOT, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1]
        lines.append(f"- {backend}: {out}")
        print(lines[-1], flush=True)
    (args.out / "table.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
