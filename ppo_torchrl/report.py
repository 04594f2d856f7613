"""Plot a run: `python -m ppo_torchrl.report <run dir>` writes <run dir>/report.png.

Panels: raw training return (per-iteration mean and last-100 mean) and deterministic eval return
against frames, then the PPO debugging quantities: entropy, approx KL, clip fraction, value loss,
explained variance and policy std.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path
from typing import Dict, List

from ppo_torchrl.errors import ConfigError

PANELS = [
    ("train/entropy", "policy entropy"),
    ("train/approx_kl", "approx KL"),
    ("train/clipfrac", "clip fraction"),
    ("loss/critic", "value loss"),
    ("train/explained_variance", "explained variance"),
    ("policy/scale_mean", "policy std (mean)"),
]


def read_metrics(path: Path) -> Dict[str, List[float]]:
    """Columns of metrics.csv as float lists; empty cells become NaN."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ConfigError(f"{path} has no rows yet: the run has not finished an iteration")
    return {key: [float(r[key]) if r[key] not in ("", None) else float("nan") for r in rows] for key in rows[0]}


def plot_run(run_dir: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    metrics_path = Path(run_dir) / "metrics.csv"
    if not metrics_path.is_file():
        raise ConfigError(f"{run_dir} is not a ppo_torchrl run dir (no metrics.csv)")
    m = read_metrics(metrics_path)
    frames = np.asarray(m["frames"])
    fig = plt.figure(figsize=(14, 9), constrained_layout=True)
    grid = fig.add_gridspec(3, 3)
    ax = fig.add_subplot(grid[0, :])
    ax.plot(frames, m["train/episode_return"], alpha=0.35, label="train return (iteration mean)")
    ax.plot(frames, m["train/return_last100"], label="train return (last 100 episodes)")
    evals = ~np.isnan(np.asarray(m["eval/return_mean"]))
    if evals.any():
        mean, std = np.asarray(m["eval/return_mean"])[evals], np.asarray(m["eval/return_std"])[evals]
        ax.errorbar(frames[evals], mean, yerr=std, fmt="o-", capsize=3, label="eval return (deterministic)")
    ax.set(xlabel="frames", ylabel="raw episode return")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    for i, (key, title) in enumerate(PANELS):
        panel = fig.add_subplot(grid[1 + i // 3, i % 3])
        panel.plot(frames, m.get(key, [float("nan")] * len(frames)))
        panel.set(title=title, xlabel="frames")
        panel.grid(alpha=0.3)
    summary = Path(run_dir) / "summary.json"
    title = Path(run_dir).name
    if summary.exists():
        import json

        s = json.loads(summary.read_text())
        title = f"{s['env']}  seed {s['seed']}  {s.get('loss', '')}/{s.get('policy', '')}  {s['frames']:,} frames"
    fig.suptitle(title)
    out = Path(run_dir) / "report.png"
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def main(argv: List[str]) -> Path:
    if len(argv) != 1:
        raise ConfigError("usage: python -m ppo_torchrl.report <run dir>")
    out = plot_run(Path(argv[0]))
    print(f"wrote {out}")
    return out


if __name__ == "__main__":
    from ppo_torchrl.errors import report_and_exit

    try:
        main(sys.argv[1:])
    except ConfigError as error:
        report_and_exit(error)
