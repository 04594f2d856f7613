"""Issue 62 item 3: does `collector.backend=envpool` learn as the Gymnasium path (`fast`) does? Reads the runs of a
sweep over seeds and backends (each job's summary.json and config.yaml; plain or as records in results/) and
writes, per env, every seed's final eval return and last-100 training return by backend, their mean +- sample
std, and Welch's t-test of the final eval returns (two-sided).

    python benchmarks/backend_equality.py outputs/envpool_learning/Hopper-v4 outputs/envpool_learning/HalfCheetah-v4 \
        --out results/envpool_learning_2026-11-28/table.md
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

import yaml
from scipy import stats


def runs(sweep: Path) -> dict:
    """{backend: {seed: summary}} of the sweep's finished runs (a run not finished is said and left out)."""
    found: dict = {}
    for summary in sorted(sweep.glob("*/summary.json")):
        s = json.loads(summary.read_text())
        if s.get("status") != "finished":
            print(f"left out {summary.parent}: status {s.get('status')}")
            continue
        cfg = yaml.safe_load((summary.parent / "config.yaml").read_text())
        found.setdefault(cfg["collector"]["backend"], {})[int(cfg["seed"])] = s
    return found


def spread(values: list) -> str:
    return f"{statistics.fmean(values):.0f} +- {statistics.stdev(values) if len(values) > 1 else 0.0:.0f}"


def table(sweep: Path) -> list:
    by_backend = runs(sweep)
    env = next((s["env"] for seeds in by_backend.values() for s in seeds.values()), sweep.name)
    lines = [f"## {env}", "", "| backend | seeds | final eval return: mean +- std (per seed) | last-100 training return "
             "(per seed) | wall s (per seed) |", "|---|---|---|---|---|"]
    evals = {}
    for backend, seeds in sorted(by_backend.items()):
        order = sorted(seeds)
        ev = [seeds[k]["eval_return_mean"] for k in order]
        tr = [seeds[k]["train_return_last100"] for k in order]
        wall = [seeds[k].get("wall_s") or 0.0 for k in order]
        evals[backend] = ev
        lines.append(f"| {backend} | {', '.join(map(str, order))} | **{spread(ev)}** ({', '.join(f'{v:.0f}' for v in ev)})"
                     f" | {spread(tr)} ({', '.join(f'{v:.0f}' for v in tr)}) | {', '.join(f'{v:.0f}' for v in wall)} |")
    if len(evals) == 2:
        (a, xa), (b, xb) = sorted(evals.items())
        t, p = stats.ttest_ind(xa, xb, equal_var=False)
        diff = statistics.fmean(xb) - statistics.fmean(xa)
        noise = max(statistics.stdev(xa), statistics.stdev(xb))
        same = p >= 0.05 and abs(diff) <= noise
        lines += ["", f"Welch t ({b} - {a}, final eval return): difference {diff:+.0f}, t = {t:.2f}, p = {p:.3f}; "
                      f"the larger seed std {noise:.0f}. Pre-registered reading (PLAN.md): the same learning when "
                      f"p >= 0.05 and |difference| <= that std: **{'holds' if same else 'does not hold'}**."]
    return lines + [""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweeps", nargs="+", type=Path)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    text = "\n".join(line for sweep in args.sweeps for line in table(sweep))
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(f"# Gymnasium (fast) against EnvPool: the same learning? (issue 62 item 3)\n\n"
                            f"`python benchmarks/backend_equality.py {' '.join(map(str, args.sweeps))} --out {args.out}`"
                            f"\n\n{text}")


if __name__ == "__main__":
    main()
