"""A multi-seed Optuna study (hparams_search=optuna_seeds) as a markdown table: one row per trial with a finished
seed, its overrides, each tuning seed's last-100 training return and their mean +- sample std, best first; a trial
with fewer seeds says how many (and "pruned" where trial_prune_below stopped it). --plot: every trial's curve, the
mean over its finished seeds of the last-100 training return against frames (the table's rank in the legend).

    .venv/bin/python benchmarks/study_table.py outputs/multirun/<study> [--out results/<dir>/study.md] [--plot <png>]
"""

import argparse
import json
from pathlib import Path

import yaml

from ppo_torchrl.report import write_png


def rows(study_dir: Path) -> list:
    found = []
    for trial in sorted(study_dir.glob("*/*/trial.json")):
        record = json.loads(trial.read_text())
        overrides = yaml.safe_load((trial.parent / ".hydra" / "overrides.yaml").read_text())
        searched = [o for o in overrides if not o.startswith(("hparams_search=", "env=", "trial_prune_below="))]
        found.append({"dir": trial.parent, "sweep": trial.parent.parent.name, "trial": trial.parent.name,
                      "overrides": searched, "seeds": record["seeds"], "objective": record["objective"],
                      "mean": record["mean"], "std": record["std"], "pruned": record.get("pruned", False)})
    return sorted(found, key=lambda r: -r["mean"])


def table(found: list, expected_seeds: int) -> str:
    lines = ["| rank | sweep / trial | overrides | per seed (last-100 train return) | mean +- sample std |",
             "|---|---|---|---|---|"]
    for i, r in enumerate(found, 1):
        partial = "" if len(r["seeds"]) == expected_seeds else \
            f" ({'pruned: ' if r['pruned'] else ''}{len(r['seeds'])} of {expected_seeds} seeds)"
        per_seed = ", ".join(f"{s}: {v:.0f}" for s, v in zip(r["seeds"], r["objective"]))
        lines.append(f"| {i} | {r['sweep']} / {r['trial']} | `{' '.join(r['overrides'])}` | {per_seed} | "
                     f"{r['mean']:.0f} +- {r['std']:.0f}{partial} |")
    return "\n".join(lines) + "\n"


def plot(found: list, expected_seeds: int, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from ppo_torchrl.records import has_record
    from ppo_torchrl.report import read_metrics

    fig, ax = plt.subplots(figsize=(10, 6), constrained_layout=True)
    for i, r in enumerate(found, 1):
        files = [r["dir"] / f"seed{seed}" / "metrics.csv" for seed in r["seeds"]]
        curves = [read_metrics(f) for f in files if has_record(f)]
        if not curves:
            print(f"no curve for {r['sweep']} / {r['trial']}: its seeds' metrics.csv are gone")
            continue
        grid = np.asarray(min((c["frames"] for c in curves), key=len))
        mean = np.mean([np.interp(grid, c["frames"], np.nan_to_num(c["train/return_last100"])) for c in curves], 0)
        seeds = "" if len(curves) == expected_seeds else f", {len(curves)} seed{'s' if len(curves) > 1 else ''}"
        label = f"#{i} {r['sweep']} / {r['trial']}: {r['mean']:.0f}{seeds}"
        ax.plot(grid, mean, lw=2.5 if i == 1 else 1.2, label=label)
    ax.set(xlabel="frames", ylabel="train return (last 100 episodes), mean over the trial's seeds",
           title=f"{found[0]['dir'].parent.parent.name}: every trial, ranked as in the table")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    write_png(fig, png, 90)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("study_dir", type=Path)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--plot", type=Path)
    args = parser.parse_args()
    found = rows(args.study_dir)
    text = table(found, args.seeds)
    if args.plot:
        plot(found, args.seeds, args.plot)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
