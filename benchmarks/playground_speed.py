"""A MuJoCo Playground task on EnvPool (env=playground): raw env steps/s, the collector's and a short run's frames/s.

Why: issue 74's goal compares a run's frames/s with the task's raw EnvPool rate at the same num_envs and threads.
- raw: one pool, random actions in the task's range, each ended env's auto-reset step taken at once for the ended
  envs alone (as the collector does); only real steps are counted;
- collector: the app's PlaygroundCollector alone (no update): batches of the recipe's frames_per_batch;
- run: whole fresh processes of `python -m ppo_torchrl experiment=playground_joystick` (no eval, no checkpoints,
  compile off so that a short run's figure has no compile in it), the app's own frames/s from summary.json.
Each figure twice: per second of wall time (what a busy machine's scheduler gave) and per second of CPU time (the
process's, all its threads: EnvPool's C++ ones too), which another process's load changes far less; a run's CPU
time is its whole process's (start-up included), so its per-CPU-second figure is a lower bound; --marginal adds a run
of 3x the frames and reports the extra frames over the extra CPU seconds (the start-up cancels).

    python benchmarks/playground_speed.py                        # Go1JoystickFlatTerrain-v1, envs 8,32 x threads 1,2
    python benchmarks/playground_speed.py --steps 40000 --frames 65536 --no-run
    python benchmarks/playground_speed.py --envs 32 --threads 2 --marginal --set torch_threads=2
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
# before numpy: ppo_torchrl puts numpy's OpenBLAS on one thread as the app runs it (read when numpy loads it; numpy
# imported first gave the collector's 512-wide numpy policy many threads, a tenth of its frames/s on a busy machine)
import ppo_torchrl  # noqa: E402,F401

import numpy as np  # noqa: E402


def raw_rate(task: str, num_envs: int, threads: int, steps: int) -> float:
    import envpool

    pool = envpool.make(task, env_type="gymnasium", num_envs=num_envs, seed=0, num_threads=threads)
    pool.reset()
    space = pool.action_space
    rng = np.random.default_rng(0)
    every = np.arange(num_envs)
    zeros = np.zeros((num_envs, space.shape[0]))
    rows = max(1, steps // num_envs)
    actions = rng.uniform(space.low, space.high, (rows, num_envs, space.shape[0]))
    start, cpu = time.perf_counter(), time.process_time()
    for row in actions:
        _, _, term, trunc, _ = pool.step(row, every)
        ended = np.flatnonzero(term | trunc)
        if ended.size:
            pool.step(zeros[: ended.size], ended)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    pool.close()
    return {"per_s": round(rows * num_envs / wall), "per_cpu_s": round(rows * num_envs / cpu)}


def collector_rate(task: str, num_envs: int, threads: int, frames: int) -> float:
    import torch

    from ppo_torchrl.collectors import make_collector
    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.rl.models import make_actor_critic

    cfg = compose(["experiment=playground_joystick", f"env.id={task}", f"collector.num_envs={num_envs}",
                   f"env.playground.threads={threads}"])
    torch.set_num_threads(1)
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    collection = make_collector(cfg, ac, 0, torch.device("cpu"))
    try:
        collection.collect()  # the pool built, the first batch's start-up
        batches = max(1, frames // cfg.collector.frames_per_batch)
        start, cpu = time.perf_counter(), time.process_time()
        for _ in range(batches):
            collection.collect()
        done = batches * cfg.collector.frames_per_batch
        return {"per_s": round(done / (time.perf_counter() - start)), "per_cpu_s": round(done / (time.process_time() - cpu))}
    finally:
        collection.close()


def run_rate(task: str, num_envs: int, threads: int, frames: int, overrides: tuple = ()) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        args = [sys.executable, "-m", "ppo_torchrl", "experiment=playground_joystick", f"env.id={task}",
                f"collector.num_envs={num_envs}", f"env.playground.threads={threads}",
                f"collector.total_frames={frames}", "eval.every_frames=0", "eval.final_episodes=0",
                "checkpoint.every_frames=0", "logger=none", "compile=false", *overrides, f"hydra.run.dir={tmp}/run"]
        import resource

        started, before = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
        wall, after = time.perf_counter() - started, resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        if done.returncode != 0:
            raise RuntimeError(done.stderr[-2000:])
        summary = json.loads((Path(tmp) / "run" / "summary.json").read_text())
    return {"sps": summary["sps"], "frames": summary["frames"], "process_s": round(wall, 1), "process_cpu_s": round(cpu, 1),
            "frames_per_process_cpu_s": round(summary["frames"] / cpu)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="Go1JoystickFlatTerrain-v1")
    parser.add_argument("--envs", default="8,32")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--steps", type=int, default=40_000, help="raw env steps per case")
    parser.add_argument("--frames", type=int, default=65_536, help="collector and run frames per case")
    parser.add_argument("--no-run", action="store_true", help="raw and collector rates only")
    parser.add_argument("--marginal", action="store_true",
                        help="also a run of 3x the frames: the run's frames per CPU second without its start-up")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="an override of the runs (e.g. torch_threads=2); repeatable")
    parser.add_argument("--rounds", type=int, default=1, help="each case this many times, the cases alternated")
    args = parser.parse_args()
    for round_ in range(args.rounds):
        for n in (int(v) for v in args.envs.split(",")):
            for threads in (int(v) for v in args.threads.split(",")):
                row = {"round": round_ + 1, "task": args.task, "num_envs": n, "threads": threads, "set": args.set,
                       "raw_steps": raw_rate(args.task, n, threads, args.steps),
                       "collector_frames": collector_rate(args.task, n, threads, args.frames)}
                if not args.no_run:
                    row["run"] = run_rate(args.task, n, threads, args.frames, tuple(args.set))
                    if args.marginal:  # a second, longer run: its extra frames over its extra CPU time, no start-up
                        longer = run_rate(args.task, n, threads, 3 * args.frames, tuple(args.set))
                        row["run_3x"] = longer
                        row["run_marginal_frames_per_cpu_s"] = round(
                            (longer["frames"] - row["run"]["frames"]) / (longer["process_cpu_s"] - row["run"]["process_cpu_s"]))
                row["load_average"] = [round(v, 2) for v in os.getloadavg()]
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
