"""One run on one process and on two (collector.workers=2), the same total env count, in-loop frames/s.

    .venv/bin/python benchmarks/workers.py [--rounds 3] [--out results/workers] [--beside "..."]

For env=Hopper-v4 and env=quadruped, each round measures, one after another in fresh processes
(benchmarks/inloop.py: 8 batches, the last 6 timed, start-up and compilation left out, compile=true as
runs of >= 150k frames use):
- fast x1: one process, FastCollector over collector.num_envs=2;
- fast x2: collector.workers=2 (TorchRL's MultiSyncCollector building FastCollector in each worker), 1 env each;
- torchrl x1 / torchrl x2: the same with TorchRL's Collector (collector.backend=torchrl).
Writes --out/table.md: every round, mean +- sample std, the ratios, the collect/update split and the
projection to 16 and 64 workers from it (batch time = collect of one process / N + the per-batch cost of
the workers measured here + update).
"""

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
VARIANTS = {"fast x1": ["collector.backend=fast", "collector.num_envs=2"],
            "fast x2": ["collector.backend=fast", "collector.workers=2"],
            "torchrl x1": ["collector.backend=torchrl", "collector.num_envs=2"],
            "torchrl x2": ["collector.backend=torchrl", "collector.workers=2"]}


def measure(env: str, overrides: list) -> dict:
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "inloop.py"), f"env={env}", "compile=true",
                          *overrides], cwd=ROOT, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def mean_std(values: list) -> str:
    return f"{statistics.mean(values):,.0f} +- {statistics.stdev(values):,.0f}" if len(values) > 1 else f"{values[0]:,.0f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--envs", default="Hopper-v4,quadruped")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "workers")
    parser.add_argument("--beside", default="nothing else running", help="what ran beside, for the table")
    args = parser.parse_args()
    stamp = time.strftime("%Y-%m-%d %H:%M")
    runs = {}
    for env in args.envs.split(","):
        for r in range(args.rounds):
            for name, overrides in VARIANTS.items():
                runs.setdefault((env, name), []).append(measure(env, overrides))
                print(env, name, r + 1, runs[env, name][-1], flush=True)
    lines = ["# One run on one and two processes, the same total env count (2), in-loop frames/s", "",
             f"`python benchmarks/workers.py --rounds {args.rounds}` ({stamp}, 2-core CPU, {args.beside}); "
             "compile=true; each figure: the last 6 of 8 batches of 2048 frames (benchmarks/inloop.py).", "",
             "| env | variant | frames/s per round | mean +- sample std | collect ms / batch | update ms / batch |",
             "|---|---|---|---|---|---|"]
    for (env, name), rows in runs.items():
        fps = [r["frames_per_s"] for r in rows]
        lines.append(f"| {env} | {name} | {', '.join(f'{x:,.0f}' for x in fps)} | {mean_std(fps)} "
                     f"| {statistics.mean(r['collect_ms'] for r in rows):.0f} "
                     f"| {statistics.mean(r['update_ms'] for r in rows):.0f} |")
    lines += ["", "Two workers against one process (ratio of the mean frames/s), and the projection:", ""]
    for env in args.envs.split(","):
        for kind in ("fast", "torchrl"):
            one, two = runs[env, f"{kind} x1"], runs[env, f"{kind} x2"]
            ratio = statistics.mean(r["frames_per_s"] for r in two) / statistics.mean(r["frames_per_s"] for r in one)
            collect = statistics.mean(r["collect_ms"] for r in one)
            update = statistics.mean(r["update_ms"] for r in one + two)
            overhead = max(statistics.mean(r["collect_ms"] for r in two) - collect / 2, 0.0)
            projected = {n: 2048 / (collect / n + overhead + update) * 1e3 for n in (16, 64)}
            lines.append(f"- {env}, {kind}: **{ratio:.2f}x**; per batch: collect {collect:.0f} ms in one process, "
                         f"{overhead:.0f} ms of per-batch cost with workers, update {update:.0f} ms; on N free cores "
                         f"~{projected[16]:,.0f} frames/s at 16 workers, ~{projected[64]:,.0f} at 64 "
                         f"(ceiling 2048 / (cost + update) = {2048 / (overhead + update) * 1e3:,.0f})")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text("\n".join(lines) + "\n")
    (args.out / "runs.json").write_text(json.dumps({f"{e} | {n}": v for (e, n), v in runs.items()}, indent=1) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
