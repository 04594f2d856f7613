"""Gymnasium against EnvPool (`collector.backend=envpool`) on Hopper-v4: raw env steps/s and training frames/s.

Why: whether stepping the envs in C++ pays for a whole run, measured the same minute on the same machine (issue 62).
- raw: random actions, episodes restarted (Gymnasium: reset(); EnvPool: its reset step for the ended envs), 1 env
  and 8 envs (Gymnasium: a loop over 8 envs, as the fast collector steps them; EnvPool: one pool, 1 and 2 threads);
- training: whole fresh processes of `python -m ppo_torchrl` (no eval, no checkpoints, 1 torch thread), the app's
  own frames/s from summary.json, backends alternated A B A B so drift hits both alike.

    python benchmarks/envpool_speed.py                       # 20k raw steps per case, 50k training frames, 1 round
    python benchmarks/envpool_speed.py --frames 100000 --rounds 2 --envs 1,8
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
ENV_ID = "Hopper-v4"


def gym_rate(num_envs: int, steps: int) -> float:
    import gymnasium as gym

    warnings.filterwarnings("ignore")
    envs = [gym.make(ENV_ID, disable_env_checker=True) for _ in range(num_envs)]
    for i, env in enumerate(envs):
        env.reset(seed=i)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (steps // num_envs, num_envs, 3))
    start = time.perf_counter()
    for row in actions:
        for env, action in zip(envs, row):
            _, _, term, trunc, _ = env.step(action)
            if term or trunc:
                env.reset()
    return (steps // num_envs) * num_envs / (time.perf_counter() - start)


def envpool_rate(num_envs: int, steps: int, threads: int) -> float:
    import envpool

    pool = envpool.make(ENV_ID, env_type="gymnasium", num_envs=num_envs, seed=0, num_threads=threads)
    pool.reset()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (steps // num_envs, num_envs, 3))
    every = np.arange(num_envs)
    zeros = np.zeros((num_envs, 3))
    start = time.perf_counter()
    for row in actions:
        _, _, term, trunc, _ = pool.step(row, every)
        ended = np.flatnonzero(term | trunc)
        if len(ended):
            pool.step(zeros[: len(ended)], ended)  # the reset step, as the collector takes it
    seconds = time.perf_counter() - start
    pool.close()
    return (steps // num_envs) * num_envs / seconds


def train_rate(backend: str, frames: int, num_envs: int) -> float:
    run_dir = tempfile.mkdtemp(prefix="bench_envpool_")
    args = [sys.executable, "-m", "ppo_torchrl", f"env={ENV_ID}", f"collector.backend={backend}",
            f"collector.total_frames={frames}", f"collector.num_envs={num_envs}", "collector.frames_per_batch=2048",
            "eval.every_frames=0", "eval.final_episodes=0", "checkpoint.every_frames=0", "checkpoint.keep_last=0",
            "logger=none", "torch_threads=1", f"hydra.run.dir={run_dir}"]
    result = subprocess.run(args, cwd=ROOT, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"error: {backend} run failed: {result.stderr.strip().splitlines()[-1:]}")
    return float(json.loads((Path(run_dir) / "summary.json").read_text())["sps"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="raw env steps per case")
    parser.add_argument("--frames", type=int, default=50_000, help="training frames per run")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--envs", default="1,8", help="collector.num_envs of the training runs")
    args = parser.parse_args()
    print(f"# {ENV_ID}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print("\n## raw env steps/s (random actions)\n\n| envs | Gymnasium | EnvPool 1 thread | EnvPool 2 threads |")
    print("|---:|---:|---:|---:|")
    for n in (1, 8):
        g = gym_rate(n, args.steps)
        p1 = envpool_rate(n, args.steps, 1)
        p2 = envpool_rate(n, args.steps, 2) if n > 1 else float("nan")
        print(f"| {n} | {g:,.0f} | {p1:,.0f} ({p1 / g:.2f}x) | " + (f"{p2:,.0f} ({p2 / g:.2f}x)" if n > 1 else "-")
              + " |", flush=True)
    print(f"\n## training frames/s ({args.frames:,} frames, 2048 per batch, no eval, 1 torch thread)\n")
    print("| envs | round | fast (Gymnasium) | envpool | ratio |\n|---:|---:|---:|---:|---:|")
    for n in (int(e) for e in args.envs.split(",")):
        for r in range(args.rounds):
            fast = train_rate("fast", args.frames, n)
            pool = train_rate("envpool", args.frames, n)
            print(f"| {n} | {r + 1} | {fast:,.0f} | {pool:,.0f} | {pool / fast:.2f}x |", flush=True)


if __name__ == "__main__":
    main()
