"""Curriculum curves of step runs: python benchmarks/plot_curriculum.py <out.png> <run dir>... (each with a metrics.csv)."""

import csv
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def column(rows, key):
    pairs = [(int(r["frames"]), float(r[key])) for r in rows if r.get(key) not in (None, "")]
    return [p[0] / 1e6 for p in pairs], [p[1] for p in pairs]


def main(out, runs):
    fig, axes = plt.subplots(4, 1, figsize=(8, 11), sharex=True)
    for run in runs:
        rows = list(csv.DictReader(open(Path(run) / "metrics.csv")))
        name = Path(run).name
        for ax, key, scale in zip(axes, ("env/terrain_level", "env/terrain_success", "train/return_last100",
                                         "eval/success_rate"), (100, 1, 1, 100)):
            x, y = column(rows, key)
            if key == "env/terrain_success":  # a mean over 50 iterations: the window itself jumps by 1/20
                y = [sum(y[max(0, i - 49):i + 1]) / len(y[max(0, i - 49):i + 1]) for i in range(len(y))]
            ax.plot(x, [v * scale for v in y], "o-" if key.startswith("eval") else "-", label=name, lw=1)
    for ax, label in zip(axes, ("curriculum level (cm)", "success, last 20 train episodes\n(mean over 50 iterations)",
                                "train return, last 100", "eval: % of 10 crossing 15 cm")):
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend()
    axes[-1].set_xlabel("frames (M)")
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
