"""Frames per second of ppo_torchrl against Stable-Baselines3 PPO at identical settings.

Settings (the speed issue's): Hopper-v4, 2048 frames per batch, 10 epochs, minibatch 64, 64-64 tanh
actor and critic, observation + reward normalization, 1 torch thread, CPU, no evaluation. Each
measurement is a whole fresh process (imports, env creation, training) timed from spawn to exit,
run alternately A B A B so drift on the machine hits both sides alike.

    python benchmarks/speed.py                    # app vs SB3, 1 env, 2 rounds
    python benchmarks/speed.py --batched          # also 8 envs x 256 steps
    python benchmarks/speed.py --no-sb3           # the app alone (SB3 not installed)
    python benchmarks/speed.py --backends fast,torchrl --batched   # both collector backends beside SB3
    python benchmarks/speed.py --backends fast,torchrl --envs 1,8,16 --no-sb3 --rounds 1   # the two paths by env count

SB3 is a benchmark-only dependency: `pip install -e ".[bench]"` (or `make bench`).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ENV_ID = "Hopper-v4"
# SB3's settings spelled out, so tuned per-env values in conf/env/Hopper-v4.yaml do not apply here.
SB3_IDENTICAL = ["policy=normal", "policy.width=null", "policy.hidden_sizes=[64,64]", "policy.critic_hidden_sizes=[64,64]",
                 "policy.activation=tanh", "loss=clip_ppo", "loss.epochs=10", "loss.minibatch_size=64",
                 "loss.clip_epsilon=0.2", "loss.entropy_coef=0.0", "loss.critic_coef=0.5", "advantage.gamma=0.99",
                 "advantage.lmbda=0.95", "optim.lr=3e-4", "optim.max_grad_norm=0.5"]


def child_app(frames: int, num_envs: int, extra: list[str]) -> None:
    import runpy

    run_dir = tempfile.mkdtemp(prefix="bench_app_")
    sys.argv = ["ppo_torchrl", f"env={ENV_ID}", f"collector.total_frames={frames}",
                f"collector.num_envs={num_envs}", "collector.frames_per_batch=2048",
                "eval.every_frames=0", "eval.final_episodes=0", "checkpoint.every_frames=0",
                "checkpoint.keep_last=0", "logger=none", "torch_threads=1", f"hydra.run.dir={run_dir}",
                *SB3_IDENTICAL, *extra]
    runpy.run_module("ppo_torchrl", run_name="__main__")
    summary = json.loads((Path(run_dir) / "summary.json").read_text())
    report(inner_sps=summary["sps"])


def child_sb3(frames: int, num_envs: int) -> None:
    import warnings

    warnings.filterwarnings("ignore")
    import torch

    torch.set_num_threads(1)
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    env = VecNormalize(make_vec_env(ENV_ID, n_envs=num_envs, seed=1), gamma=0.99)
    model = PPO("MlpPolicy", env, n_steps=2048 // num_envs, batch_size=64, n_epochs=10, learning_rate=3e-4,
                gae_lambda=0.95, gamma=0.99, clip_range=0.2, ent_coef=0.0, vf_coef=0.5, max_grad_norm=0.5,
                policy_kwargs=dict(net_arch=dict(pi=[64, 64], vf=[64, 64])), seed=1, device="cpu", verbose=0)
    tick = time.perf_counter()
    model.learn(frames)
    report(inner_sps=frames / (time.perf_counter() - tick))


def report(**extra) -> None:
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print("BENCH " + json.dumps({"peak_rss_mb": round(peak_mb, 1), **extra}), flush=True)


def run_child(kind: str, frames: int, num_envs: int, extra: list[str]) -> dict:
    cmd = [sys.executable, __file__, "--child", kind, "--frames", str(frames), "--num-envs", str(num_envs), *extra]
    env = {**os.environ, "PYTHONWARNINGS": "ignore", "OMP_NUM_THREADS": "1"}
    tick = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env)
    wall = time.perf_counter() - tick
    if out.returncode != 0:
        raise SystemExit(f"{kind} run failed:\n{out.stderr[-3000:]}")
    line = next(l for l in out.stdout.splitlines() if l.startswith("BENCH "))
    return {"wall_s": wall, "sps": frames / wall, **json.loads(line[6:])}


def raw_env_rate(steps: int = 20_000) -> float:
    import warnings

    warnings.filterwarnings("ignore")
    import gymnasium as gym

    env = gym.make(ENV_ID)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    tick = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - tick)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=49_152)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--batched", action="store_true", help="also run 8 envs x 256 steps per batch")
    parser.add_argument("--envs", help="the env counts to run, comma-separated, e.g. 1,8,16 (instead of --batched)")
    parser.add_argument("--no-sb3", action="store_true")
    parser.add_argument("--backends", default="fast", help="collector backends of the app, comma-separated")
    parser.add_argument("--child", choices=["app", "sb3"], help=argparse.SUPPRESS)
    parser.add_argument("--num-envs", type=int, default=1, help=argparse.SUPPRESS)
    args, extra = parser.parse_known_args()
    if args.child == "app":
        return child_app(args.frames, args.num_envs, extra)
    if args.child == "sb3":
        return child_sb3(args.frames, args.num_envs)

    raw = raw_env_rate()
    print(f"raw gymnasium {ENV_ID} step, random actions: {raw:,.0f} steps/s")
    settings = [int(n) for n in args.envs.split(",")] if args.envs else [1] + ([8] if args.batched else [])
    for num_envs in settings:
        print(f"\n{ENV_ID}, {num_envs} env(s) x {2048 // num_envs} steps, {args.frames} frames, "
              f"10 epochs x minibatch 64, whole process:")
        sides = [(f"app[{b}]", "app", [f"collector.backend={b}", *extra]) for b in args.backends.split(",")]
        sides += [] if args.no_sb3 else [("sb3", "sb3", [])]
        results: dict[str, list[dict]] = {name: [] for name, _, _ in sides}
        for r in range(args.rounds):
            for name, kind, overrides in sides:
                res = run_child(kind, args.frames, num_envs, overrides)
                results[name].append(res)
                print(f"  round {r + 1} {name:14s} {res['sps']:8,.0f} frames/s  (in-loop {res['inner_sps']:8,.0f})"
                      f"  wall {res['wall_s']:6.1f} s  peak RSS {res['peak_rss_mb']:6.0f} MB", flush=True)
        mean = {name: sum(x["sps"] for x in rows) / len(rows) for name, rows in results.items()}
        for name, sps in mean.items():
            line = f"  mean {name:14s} {sps:8,.0f} frames/s = {sps / raw:.0%} of the raw env step rate"
            if "sb3" in mean and name != "sb3":
                line += f"; {sps / mean['sb3']:.2f}x SB3"
            print(line)


if __name__ == "__main__":
    main()
