"""The GPU path in one call (issue 61 item 4): Hopper-v4 for 100k frames with `device=cuda`, then resume it to 120k,
evaluate it, export it; the same on CPU; frames/s of each and the returns side by side.

    python benchmarks/gpu_check.py [--out results/gpu/<date>] [--frames 100000] [--workdir /tmp/gpu_check]

Every step is the real command (`python -m ppo_torchrl ...`, `.evaluate`, `.export`) in a subprocess, each with a
time limit; the whole check stays under ~8 minutes on a machine with a GPU. Without one it says so plainly in its
first line and in the table, and checks the CPU path alone. Needs no network: a GPU machine gets the project's
packages as wheels (docs/speed.md, "On a GPU"). Writes <out>/table.md and <out>/output.txt.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STEP_LIMIT_S = 240


def command(args: list, log: list) -> tuple:
    """(exit code, seconds, last stderr line) of `python -m <args>`, logged."""
    start = time.time()
    try:
        done = subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, cwd=ROOT,
                              timeout=STEP_LIMIT_S)
        code, err = done.returncode, done.stderr
    except subprocess.TimeoutExpired as exc:
        code, err = "timeout", (exc.stderr or b"").decode(errors="replace") if isinstance(exc.stderr, bytes) else ""
    seconds = time.time() - start
    lines = [line for line in (err or "").splitlines() if line.strip()]
    log.append(f"$ python -m {' '.join(args)}\n  exit {code} after {seconds:.1f} s; last line: "
               f"{lines[-1] if lines else ''}")
    return code, seconds, lines[-1] if lines else ""


def check(device: str, frames: int, workdir: Path, log: list) -> dict:
    run = workdir / device
    row = {"device": device}
    code, seconds, _ = command(["ppo_torchrl", "env=Hopper-v4", f"device={device}", "seed=1",
                                f"collector.total_frames={frames}", "logger=none", f"hydra.run.dir={run}",
                                "overwrite=true"], log)
    summary = json.loads((run / "summary.json").read_text()) if (run / "summary.json").is_file() else {}
    row.update(train=code, train_s=seconds, sps=summary.get("sps"), train_return=summary.get("train_return_last100"),
               eval_return=summary.get("eval_return_mean"))
    more = frames + frames // 5
    code, _, _ = command(["ppo_torchrl", f"resume={run}", f"collector.total_frames={more}"], log)
    summary = json.loads((run / "summary.json").read_text()) if (run / "summary.json").is_file() else {}
    row.update(resume=code, resumed_frames=summary.get("frames"))
    code, _, last = command(["ppo_torchrl.evaluate", f"run={run}", "checkpoint=last", "episodes=5", "seed=7"], log)
    row.update(evaluate=code, evaluate_line=last)
    code, _, _ = command(["ppo_torchrl.export", f"run={run}", "checkpoint=last"], log)
    row.update(export=code, policy=(run / "policy.pt").is_file())
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/gpu_check"))
    args = parser.parse_args()
    import torch

    gpu = torch.cuda.is_available()
    first = (f"GPU found: {torch.cuda.get_device_name(0)} (torch {torch.__version__}, CUDA {torch.version.cuda})" if gpu
             else f"no GPU found (torch {torch.__version__}, CUDA build: {torch.version.cuda or 'none'}): "
                  "checking the CPU path only")
    print(first, flush=True)
    log = [first]
    rows = [check(d, args.frames, args.workdir, log) for d in (["cuda", "cpu"] if gpu else ["cpu"])]
    lines = [f"{first}.", "", f"Hopper-v4, seed 1, {args.frames:,} frames, then resumed to {args.frames + args.frames // 5:,}; "
             "evaluate (5 episodes, checkpoint=last) and export.", "",
             "| device | train exit | wall s | frames/s | train return (last 100) | eval return (final) | resume exit "
             "(frames) | evaluate exit | export exit (policy.pt) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        def num(v, fmt):
            return format(v, fmt) if isinstance(v, (int, float)) else "-"
        lines.append(f"| {r['device']} | {r['train']} | {r['train_s']:.0f} | {num(r['sps'], '.0f')} | "
                     f"{num(r['train_return'], '.0f')} | {num(r['eval_return'], '.0f')} | {r['resume']} "
                     f"({num(r['resumed_frames'], ',')}) | {r['evaluate']} | {r['export']} ({r['policy']}) |")
    if not gpu:
        lines.append("| cuda | not run: no GPU found | | | | | | | |")
    table = "\n".join(lines) + "\n"
    print(table)
    ok = all(r[k] == 0 for r in rows for k in ("train", "resume", "evaluate", "export"))
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "table.md").write_text(table)
        (args.out / "output.txt").write_text("\n".join(log) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
