"""Copy the evidence of a sweep into results/: per run summary.json, config.yaml and metrics.csv as its record
metrics.csv.xz (ppo_torchrl.records), plus the sweep report (PNG, markdown, CSV) and a per-env table over seeds.

    python benchmarks/collect_results.py outputs/multirun/quality_1m results/quality_1m
    python benchmarks/collect_results.py --table results/quality_1m        # the table again, from the records

A peer's rows recorded beside them (benchmarks/sb3_peer.py --out <dest>/sb3-ppo_seed<k>) are a row of the same table,
named by their folder (`sb3-ppo`); they have no periodic evals ("-").
"""

import json
import shutil
import sys
from pathlib import Path

import numpy as np

from ppo_torchrl import report

from ppo_torchrl import records


def copy_finished_runs(sweep: Path, dest: Path, name_of) -> dict:
    """Copy each finished run's summary.json, metrics.csv and config.yaml to dest/<name_of(summary,
    config)>_seed<seed>; returns the summaries by that name (runs not finished are left out, said)."""
    import yaml

    dest.mkdir(parents=True, exist_ok=True)
    rows = {}
    for summary in sorted(sweep.glob("*/summary.json")):
        s = json.loads(summary.read_text())
        if s.get("status") != "finished":
            print(f"left out {summary.parent.name}: status {s.get('status')}")
            continue
        name = name_of(s, yaml.safe_load((summary.parent / "config.yaml").read_text()))
        run = dest / f"{name}_seed{s['seed']}"
        run.mkdir(exist_ok=True)
        for file in ("summary.json", "config.yaml"):
            shutil.copy(summary.parent / file, run / file)
        shutil.copy(records.compress(summary.parent / "metrics.csv"), run / "metrics.csv.xz")
        rows.setdefault(name, []).append(s)
    return rows


def recorded_runs(dest: Path) -> dict:
    """The summaries of the runs collected in dest (<name>_seed<k>/summary.json), by name."""
    rows = {}
    for summary in sorted(dest.glob("*_seed*/summary.json")):
        s = json.loads(summary.read_text())
        rows.setdefault(summary.parent.name.rsplit("_seed", 1)[0], []).append(s)
    return rows


def mean_pm(x: np.ndarray) -> str:
    """A cell of every results table: the mean +- the sample std over seeds (ddof=1); one seed has no spread to show."""
    return f"{x.mean():.0f} +- {x.std(ddof=1):.0f}" if len(x) > 1 else f"{x.mean():.0f} (one seed)"


def main(sweep: Path, dest: Path) -> None:
    report.main([str(sweep)])
    copy_finished_runs(sweep, dest, lambda summary, config: summary["env"])
    for name in ("sweep_report.png", "sweep_report.md", "sweep_report.csv"):
        shutil.copy(sweep / name, dest / name)
    (dest / "table.md").write_text(table(recorded_runs(dest)))
    print(table(recorded_runs(dest)), end="")


def table(rows: dict) -> str:
    # "best periodic eval": the highest of a run's deterministic evals (eval.episodes each, eval.final_episodes at the end), the kind of
    # figure Tianshou's tables give (the max over training), from far fewer evals than theirs.
    lines = ["| env | seeds | frames | train return, last 100 (mean +- sample std) | per seed | deterministic eval (mean +- sample std) | best periodic eval (mean +- sample std) | SPS per run | wall s per run |",
             "|---|---|---|---|---|---|---|---|---|"]
    for env, runs in sorted(rows.items()):
        runs.sort(key=lambda s: s["seed"])
        train = np.array([s["train_return_last100"] for s in runs])
        evals = np.array([s["eval_return_mean"] for s in runs])
        best = np.array([s["best_eval_return"] if s.get("best_eval_return") is not None else np.nan for s in runs])
        lines.append(f"| {env} | {','.join(str(s['seed']) for s in runs)} | {runs[0]['frames']:,} | "
                     f"{mean_pm(train)} | {', '.join(f'{x:.0f}' for x in train)} | {mean_pm(evals)} | "
                     f"{'-' if np.isnan(best).all() else mean_pm(best)} | "
                     f"{np.mean([s['sps'] for s in runs]):.0f} | "
                     f"{np.mean([s['wall_s'] for s in runs]):.0f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    if sys.argv[1] == "--table":
        print(table(recorded_runs(Path(sys.argv[2]))), end="")
    else:
        main(Path(sys.argv[1]), Path(sys.argv[2]))
