"""What a user waits for: a whole training run of this app beside Stable-Baselines3, process start to exit.

    .venv/bin/python benchmarks/whole_run.py --frames 1000000 [--tuned] [--sequential] [--seed 1] [--out results/speed/whole_run]
        [--backends fast,envpool] [--num-envs 8] [--sb3-vec dummy,subproc]

- The app runs with its defaults (periodic evals, checkpoints, csv logging all on):
  `python -m ppo_torchrl env=gym env.id=Hopper-v4 collector.total_frames=N`, whose untuned values are
  SB3's PPO defaults; `--tuned` runs `env=Hopper-v4` (the tuned file) and gives SB3 the same values.
- SB3 runs `model.learn(N)` at the same settings (VecNormalize, 1 env, 1 torch thread), its episodes
  logged by a Monitor so the time to a score can be read from both logs.
- Side by side (the default): the two start together, each pinned to its own core (taskset): neither
  uses the other's core, so the app's evals run in line (eval.background=auto is off on one core).
- --sequential: A then B, each alone on the machine and free to use both cores. The app's periodic
  evals then run in its second process (eval.background=auto); its training stays on one thread, as
  SB3's does (1 torch thread each).
- --backends: the app once per `collector.backend` named (e.g. `fast,envpool`: Gymnasium's step in Python, EnvPool's
  in C++), each beside the same SB3 run; the raw rate is then measured for both env kinds (EnvPool: one env, one
  thread, its reset step included) and each app row's share is of its own env kind's raw rate.
- --num-envs N: both sides step N envs and keep the 2048 frames of a batch (the app's `collector.num_envs=N`, SB3's
  `n_envs=N, n_steps=2048 // N`); --sb3-vec names SB3's vector env, one SB3 row each (`dummy`: DummyVecEnv, the N envs
  stepped in its process; `subproc`: SubprocVecEnv, one process per env). The raw rate of the envpool kind is then
  EnvPool's at N envs on the threads the app gives it (min(N, CPUs)); Gymnasium's stays one env's loop (the N are
  stepped one after another in Python on either side).
Prints and writes (--out/table.md): wall time, the ratio, the in-loop rate, the share of the raw env
step rate, peak RSS, and the wall-clock time until the last-100 train return first reaches --score.
Bad input (--frames 0 or below, a file as --out, a backend that is not one) is one `error:` line and exit 2, before
anything runs or is written (cli_args.py).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
from cli_args import Parser, finite, out_dir, positive_int, seed  # noqa: E402
from cli_args import run as run_main  # noqa: E402
from envpool_speed import envpool_rate  # noqa: E402
from speed import raw_env_rate  # noqa: E402

BACKENDS = ("fast", "envpool", "auto", "torchrl")
SB3_VECS = ("dummy", "subproc")
VEC_NAMES = {"dummy": "DummyVecEnv", "subproc": "SubprocVecEnv"}

# conf/env/Hopper-v4.yaml's tuned values, in SB3's terms (checked against the file at start).
TUNED = {"gamma": 0.995, "clip_range": 0.1, "learning_rate": 1e-4, "width": 128}


def sb3_child(frames: int, out: Path, tuned: bool, seed: int, num_envs: int = 1, vec: str = "dummy") -> None:
    import warnings

    warnings.filterwarnings("ignore")
    import resource

    import torch

    torch.set_num_threads(1)
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

    gamma = TUNED["gamma"] if tuned else 0.99
    width = TUNED["width"] if tuned else 64
    vec_cls = SubprocVecEnv if vec == "subproc" else DummyVecEnv
    env = VecNormalize(make_vec_env("Hopper-v4", n_envs=num_envs, seed=seed, monitor_dir=str(out), vec_env_cls=vec_cls),
                       gamma=gamma)
    model = PPO("MlpPolicy", env, n_steps=2048 // num_envs, batch_size=64, n_epochs=10, gae_lambda=0.95, gamma=gamma,
                learning_rate=(lambda f: f * TUNED["learning_rate"]) if tuned else (lambda f: f * 3e-4),
                clip_range=TUNED["clip_range"] if tuned else 0.2, ent_coef=0.0, vf_coef=0.5, max_grad_norm=0.5,
                policy_kwargs=dict(net_arch=dict(pi=[width, width], vf=[width, width])), seed=seed, device="cpu",
                verbose=0)
    tick = time.perf_counter()
    model.learn(frames)
    inner = frames / (time.perf_counter() - tick)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    env.close()
    if vec == "subproc":  # its env processes: the largest of them beside SB3's own
        peak = max(peak, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)
    (out / "bench.json").write_text(json.dumps({"inner_sps": inner, "peak_rss_mb": peak}))


def time_to_score_app(run: Path, score: float):
    with open(run / "metrics.csv", newline="") as f:
        for row in csv.DictReader(f):
            if row["train/return_last100"] and float(row["train/return_last100"]) >= score:
                return float(row["time_s"])
    return None


def sb3_episodes(out: Path) -> list:
    """SB3's Monitor files (one per env): every episode's return `r`, length `l` and seconds since start `t`, by `t`."""
    rows = []
    for path in sorted(out.glob("*.monitor.csv")):
        rows += list(csv.DictReader(line for line in path.read_text().splitlines() if not line.startswith("#")))
    return sorted(rows, key=lambda row: float(row["t"]))


def time_to_score_sb3(out: Path, score: float):
    rows = sb3_episodes(out)
    returns = []
    for row in rows:
        returns = (returns + [float(row["r"])])[-100:]
        if sum(returns) / len(returns) >= score:
            return float(row["t"])
    return None


def main(argv=None) -> int:
    parser = Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=positive_int, default=1_000_000)
    parser.add_argument("--score", type=finite, default=2000.0)
    parser.add_argument("--tuned", action="store_true", help="env=Hopper-v4 (tuned) and SB3 with the same values")
    parser.add_argument("--sequential", action="store_true", help="A then B, each alone on the machine")
    parser.add_argument("--seed", type=seed, default=1, help="the seed of both sides (the app's seed=, SB3's seed)")
    parser.add_argument("--out", type=out_dir, default=ROOT / "results" / "speed" / "whole_run")
    parser.add_argument("--backends", default="fast", help="the app's collector.backend, one run each (fast,envpool)")
    parser.add_argument("--num-envs", type=positive_int, default=1, help="envs per side (a batch stays 2048 frames)")
    parser.add_argument("--sb3-vec", default="dummy", help="SB3's vector env, one row each: dummy, subproc")
    parser.add_argument("--sb3-child", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    backends = [b for b in args.backends.split(",") if b]
    if not backends or set(backends) - set(BACKENDS) or (len(backends) > 1 and not args.sequential):
        parser.error(f"argument --backends: {args.backends!r}: takes {', '.join(BACKENDS)}; more than one needs "
                     "--sequential")
    vecs = [v for v in args.sb3_vec.split(",") if v]
    if not vecs or set(vecs) - set(SB3_VECS) or len(set(vecs)) < len(vecs) or (len(vecs) > 1 and not args.sequential):
        parser.error(f"argument --sb3-vec: {args.sb3_vec!r}: takes {', '.join(SB3_VECS)}; both need --sequential")
    if 2048 % args.num_envs:
        parser.error(f"argument --num-envs: {args.num_envs} does not divide the 2048 frames of a batch")
    if args.sb3_child:
        sb3_child(args.frames, args.sb3_child, args.tuned, args.seed, args.num_envs, vecs[0])
        return 0

    stamp = time.strftime("%Y-%m-%d_%H-%M-%S")
    work = ROOT / "outputs" / "bench_whole_run" / stamp
    sb3_dirs = {v: work / (f"sb3_{v}" if len(vecs) > 1 else "sb3") for v in vecs}
    app_runs = {b: work / (f"app_{b}" if len(backends) > 1 else "app") for b in backends}
    for sb3_dir in sb3_dirs.values():
        sb3_dir.mkdir(parents=True)
    n = args.num_envs
    env_args = ["env=Hopper-v4"] if args.tuned else ["env=gym", "env.id=Hopper-v4"]
    can_pin = shutil.which("taskset") and os.cpu_count() >= 2 and not args.sequential
    pin = (lambda core: ["taskset", "-c", str(core)]) if can_pin else (lambda core: [])
    env = {**os.environ, "PYTHONWARNINGS": "ignore", "OMP_NUM_THREADS": "1"}
    # The raw step rate drifts with the shared host by up to ~30% within minutes: measured before and
    # after each side, and the share column divides by the mean of those measurements.
    pool_threads = min(n, len(os.sched_getaffinity(0)))
    kinds = {"envpool": lambda: envpool_rate(n, 20_000, pool_threads)} if "envpool" in backends else {}
    kinds = {"gymnasium": raw_env_rate, **kinds}
    raws = {kind: [measure()] for kind, measure in kinds.items()}
    app_cmds = {b: [*pin(0), sys.executable, "-m", "ppo_torchrl", *env_args, f"collector.total_frames={args.frames}",
                    "torch_threads=1", f"seed={args.seed}", f"collector.backend={b}", f"collector.num_envs={n}",
                    f"hydra.run.dir={run}"]
                for b, run in app_runs.items()}
    sb3_cmds = {f"sb3_{v}": [*pin(1), sys.executable, __file__, "--frames", str(args.frames), "--sb3-child", str(d),
                             "--seed", str(args.seed), "--num-envs", str(n), "--sb3-vec", v,
                             *(["--tuned"] if args.tuned else [])] for v, d in sb3_dirs.items()}
    walls, app_peaks = {}, {}
    apps = [(f"app_{b}", cmd) for b, cmd in app_cmds.items()]
    sb3s = list(sb3_cmds.items())
    groups = [[side] for side in apps + sb3s] if args.sequential else [[*apps, *sb3s]]
    for group in groups:
        tick = time.perf_counter()
        procs = {name: subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                 for name, cmd in group}
        while any(name not in walls for name in procs):
            for name, proc in procs.items():
                if name not in walls and proc.poll() is not None:
                    walls[name] = time.perf_counter() - tick
                    if name.startswith("app") and not any(k.startswith("sb3") for k in walls):  # RUSAGE_CHILDREN: so far
                        import resource

                        app_peaks[name] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
                    if proc.returncode != 0:
                        raise SystemExit(f"{name} failed:\n{proc.stderr.read().decode()[-3000:]}")
            time.sleep(0.5)
        for kind, measure in kinds.items():
            raws[kind].append(measure())
    raw = {kind: sum(values) / len(values) for kind, values in raws.items()}
    rows = []
    for b, run in app_runs.items():
        summary = json.loads((run / "summary.json").read_text())
        name = "ppo_torchrl" + (f" (collector.backend={b})" if len(backends) > 1 or b != "fast" else "")
        name += f", {n} envs" if n > 1 else ""
        rows.append((name, walls[f"app_{b}"], summary["sps"], raw["envpool" if b == "envpool" else "gymnasium"],
                     time_to_score_app(run, args.score), app_peaks.get(f"app_{b}")))
    frames_app = summary["frames"]
    for v, sb3_dir in sb3_dirs.items():
        sb3 = json.loads((sb3_dir / "bench.json").read_text())
        parts = [VEC_NAMES[v]] if len(vecs) > 1 or v != "dummy" else []
        parts += [f"{n} envs"] if n > 1 else []
        name = "SB3" + (f" ({', '.join(parts)})" if parts else "")
        rows.append((name, walls[f"sb3_{v}"], sb3["inner_sps"], raw["gymnasium"],
                     time_to_score_sb3(sb3_dir, args.score), sb3["peak_rss_mb"]))
    raw_text = "; ".join(f"raw {kind} Hopper-v4 step rate {raw[kind]:,.0f} steps/s (the mean of "
                         f"{', '.join(f'{r:,.0f}' for r in raws[kind])})" for kind in kinds)
    setting = "env=Hopper-v4 (tuned; SB3 given the same values)" if args.tuned else "env=gym env.id=Hopper-v4 (SB3's defaults)"
    lines = [f"# Whole run, {setting}, {args.frames:,} frames ({frames_app:,} for the app: whole batches)", "",
             f"`python benchmarks/whole_run.py --frames {args.frames}{' --tuned' if args.tuned else ''}"
             f"{' --sequential' if args.sequential else ''}{f' --seed {args.seed}' if args.seed != 1 else ''}"
             f"{f' --backends {args.backends}' if backends != ['fast'] else ''}"
             f"{f' --num-envs {n}' if n > 1 else ''}{f' --sb3-vec {args.sb3_vec}' if vecs != ['dummy'] else ''}` ({stamp}); "
             + ("one after the other, each alone on the machine (the app's evals in its second process)"
                if args.sequential else "side by side, one core each (the app's evals in line)")
             + f"; {raw_text}: measured before and after each side", "",
             f"| side | wall s (process) | in-loop frames/s | share of raw env rate | time to last-100 >= {args.score:.0f} (s) | peak RSS MB |",
             "|---|---|---|---|---|---|"]
    for name, wall, inner, own_raw, tts, peak in rows:
        lines.append(f"| {name} | {wall:.0f} | {inner:,.0f} | {inner / own_raw:.0%} | "
                     f"{'not reached' if tts is None else f'{tts:.0f}'} | {'-' if peak is None else f'{peak:.0f}'} |")
    lines.append("")
    fastest = min(vecs, key=lambda v: walls[f"sb3_{v}"])
    if len(vecs) > 1:
        lines.append(f"SB3's faster vector env here: {fastest}")
    goal = "issue 75's goal at 8 envs: >= 5x" if n > 1 else "issue 62's goal: >= 5x; issue 75's at one env: >= 3.5x"
    for b in backends:
        lines.append(f"ratio SB3 wall / app wall{f' ({b})' if len(backends) > 1 else ''}"
                     f"{f' (SB3: {fastest}, its faster)' if len(vecs) > 1 else ''}: "
                     f"{walls[f'sb3_{fastest}'] / walls[f'app_{b}']:.2f}x ({goal})")
    args.out.mkdir(parents=True, exist_ok=True)
    for b, run in app_runs.items():
        tag = f"_{b}" if len(backends) > 1 else ""
        shutil.copy(run / "summary.json", args.out / f"app{tag}_summary.json")
        shutil.copy(run / "metrics.csv", args.out / f"app{tag}_metrics.csv")
    for v, sb3_dir in sb3_dirs.items():  # every env's episodes in one file, by time
        episodes = sb3_episodes(sb3_dir)
        with open(args.out / (f"sb3_{v}_monitor.csv" if len(vecs) > 1 else "sb3_monitor.csv"), "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=["r", "l", "t"], extrasaction="ignore")
            writer.writeheader()
            writer.writerows(episodes)
    (args.out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
