"""How fast a legged run trains, and where its time goes (issue 72 item 4).

    .venv/bin/python benchmarks/legged_speed.py [--robots go1,anymal_b,spot] [--num-envs 1,8,32,64]
        [--iterations 6] [--warmup 2] [--code <checkout>] [--label after] [--set key=value ...] [--out results/speed/<dir>]

For each robot and `collector.num_envs`, in a process of its own started in `--code` (a checkout: its package is
the one imported, so `--code` at an older commit measures the env before the rebuild), a Trainer of
experiment=legged_trot_v2 runs `--warmup` iterations (the compile, the first episodes), then `--iterations` more,
timed part by part: collection (the fast collector's rollout) and the update (advantages, epochs x minibatches).
The batch size per update is the recipe's (collector.frames_per_batch 2048, minibatch 64, 10 epochs) unless --set
changes it; the rollout per env is then 2048 / num_envs steps. Where the env is the batched one, the collection is
split further by the env's own clock: the physics (mj_step over the rows, on its threads) and the task (gathering
the rows, rewards, observations, resets); the rest of the collection is the policy and the batch's bookkeeping.
The physics' own rate (frames over the physics time: the same model, contacts and states, no Python around it)
is the limit a collection can reach here. Prints one table row per run and writes them (--out: table.md, rows.json).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ROBOTS = {"go1": "unitree_go1", "anymal_b": "anybotics_anymal_b", "spot": "boston_dynamics_spot",
          "a1": "unitree_a1", "go2": "unitree_go2", "barkour_vb": "google_barkour_vb"}


def child(robot: str, num_envs: int, iterations: int, warmup: int, overrides: list) -> dict:
    import os

    sys.path.insert(0, os.getcwd())  # the package of --code's checkout, not the one this script sits in
    import torch  # noqa: F401 (the trainer's imports, before the clock starts)

    from ppo_torchrl.compose import compose
    from ppo_torchrl.trainer import Trainer

    xml = f"menagerie/{ROBOTS[robot]}/scene.xml"
    cfg = compose(["experiment=legged_trot_v2", f"env.xml_file={xml}", f"collector.num_envs={num_envs}",
                   "eval.every_frames=0", "eval.final_episodes=0", "checkpoint.every_frames=0", "logger=none",
                   *overrides])
    with tempfile.TemporaryDirectory() as tmp:
        trainer = Trainer(cfg, Path(tmp) / "run")
        collector = trainer.collector.collector
        rows = getattr(collector, "env_state", None)
        batch_env = getattr(getattr(rows, "rows", None), "batch", None)
        parts = {"collect": 0.0, "update": 0.0, "physics": 0.0, "task": 0.0}
        for it in range(warmup + iterations):
            if it == warmup and batch_env is not None:
                batch_env.timing = {"physics": 0.0, "task": 0.0}
            trainer._set_lr()
            t0 = time.perf_counter()
            batch = trainer.collector.collect()
            t1 = time.perf_counter()
            trainer.update(batch)
            t2 = time.perf_counter()
            if it >= warmup:
                parts["collect"] += t1 - t0
                parts["update"] += t2 - t1
        if batch_env is not None:
            parts.update(batch_env.timing)
        trainer.collector.close()
    frames = iterations * cfg.collector.frames_per_batch
    return {"robot": robot, "num_envs": num_envs, "frames": frames, "batched": batch_env is not None,
            "threads": getattr(batch_env, "threads", 1), **parts,
            "frames_per_s": frames / (parts["collect"] + parts["update"]),
            "collect_frames_per_s": frames / parts["collect"],
            "physics_frames_per_s": frames / parts["physics"] if parts["physics"] else None}


def row_line(r: dict) -> str:
    total = r["collect"] + r["update"]
    split = (f"physics {r['physics'] / total:.0%}, task {r['task'] / total:.0%}, policy and batch "
             f"{(r['collect'] - r['physics'] - r['task']) / total:.0%}" if r["batched"] else
             f"collection {r['collect'] / total:.0%}")
    physics = f"{r['physics_frames_per_s']:,.0f}" if r["physics_frames_per_s"] else "-"
    share = f"{r['collect_frames_per_s'] / r['physics_frames_per_s']:.0%}" if r["physics_frames_per_s"] else "-"
    return (f"| {r['label']} | {r['robot']} | {r['num_envs']} | {r['threads']} | {r['frames_per_s']:,.0f} | "
            f"{r['collect_frames_per_s']:,.0f} | {physics} | {share} | {split}, update {r['update'] / total:.0%} |")


HEADER = ("| code | robot | num_envs | physics threads | loop frames/s | collection frames/s | physics frames/s | "
          "collection / physics | where the loop's time goes |\n|---|---|---|---|---|---|---|---|---|")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", default="go1,anymal_b,spot")
    p.add_argument("--num-envs", default="1,8,32,64")
    p.add_argument("--iterations", type=int, default=6)
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--code", default=str(ROOT), help="the checkout whose package runs (default: this one)")
    p.add_argument("--label", default="this checkout")
    p.add_argument("--set", action="append", default=[], help="a config override for every run (key=value)")
    p.add_argument("--out")
    p.add_argument("--child", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        robot, envs = args.child.split(":")
        print(json.dumps(child(robot, int(envs), args.iterations, args.warmup, args.set)))
        return 0
    robots = [r for r in args.robots.split(",") if r]
    unknown = [r for r in robots if r not in ROBOTS]
    counts = [int(k) for k in args.num_envs.split(",") if k.strip()] if args.num_envs.replace(",", "").isdigit() else []
    if unknown or not counts or min(counts) < 1 or args.iterations < 1 or args.warmup < 0 \
            or not (Path(args.code) / "ppo_torchrl").is_dir():
        print(f"error: --robots from {', '.join(ROBOTS)}; --num-envs counts >= 1; --iterations >= 1; --code a checkout "
              "holding ppo_torchrl/", file=sys.stderr)
        return 2
    rows = []
    print(HEADER, flush=True)
    for robot in robots:
        for k in counts:
            cmd = [sys.executable, str(Path(__file__).resolve()), "--child", f"{robot}:{k}",
                   "--iterations", str(args.iterations), "--warmup", str(args.warmup)]
            for s in args.set:
                cmd += ["--set", s]
            out = subprocess.run(cmd, cwd=args.code, capture_output=True, text=True, timeout=3600)
            if out.returncode != 0:
                print(f"error: {robot} at {k} envs failed: {out.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
                return 1
            row = {"label": args.label, "overrides": args.set, **json.loads(out.stdout.strip().splitlines()[-1])}
            rows.append(row)
            print(row_line(row), flush=True)
    if args.out:
        out_dir = Path(args.out)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "rows.json").write_text(json.dumps(rows, indent=1))
        (out_dir / "table.md").write_text(HEADER + "\n" + "\n".join(row_line(r) for r in rows) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
