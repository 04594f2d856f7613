"""A multi-seed Optuna study (hparams_search=optuna_seeds) as a markdown table: one row per trial with a finished
seed, its overrides, each tuning seed's last-100 training return and their mean +- sample std, best first; a trial
with fewer seeds says how many (and "pruned" where trial_prune_below stopped it).

    .venv/bin/python benchmarks/study_table.py outputs/multirun/<study> [--out results/<dir>/study.md]
"""

import argparse
import json
from pathlib import Path

import yaml


def rows(study_dir: Path) -> list:
    found = []
    for trial in sorted(study_dir.glob("*/*/trial.json")):
        record = json.loads(trial.read_text())
        overrides = yaml.safe_load((trial.parent / ".hydra" / "overrides.yaml").read_text())
        searched = [o for o in overrides if not o.startswith(("hparams_search=", "env=", "trial_prune_below="))]
        found.append({"sweep": trial.parent.parent.name, "trial": trial.parent.name, "overrides": searched,
                      "seeds": record["seeds"], "objective": record["objective"], "mean": record["mean"],
                      "std": record["std"], "pruned": record.get("pruned", False)})
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


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("study_dir", type=Path)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    text = table(rows(args.study_dir), args.seeds)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
