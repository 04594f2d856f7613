"""A joystick round's learning curves in one figure: per row (robot x seed), the training return (last 100
episodes) and the two tracking terms' per-episode sums against frames, robots by colour, seeds by line style, each a
running mean over the last 500,000 frames (logs thinned to different strides read alike).

    python benchmarks/joystick_curves.py <dir of row dirs> [--out <dir>/curves.png] [--running]

It reads each `<robot>_seed<s>/metrics.csv` (or the record's `metrics.csv.xz`) as `python -m ppo_torchrl.report` does
and stands for the round in place of one `report.png` per row (the tree's room, results/README.md); a row's own
report is still `python -m ppo_torchrl.report <row dir>` on its record. A row whose summary.json does not yet say
`finished` (training, or interrupted before its last frame) is left out, so the figure drawn beside a round's records
shows only rows those records hold; `--running` draws those too, marked "(running)", to watch a round train.
"""

from __future__ import annotations

import sys
from pathlib import Path

from cli_args import ConfigError, Parser, out_file
from cli_args import run as run_main
from joystick_table import ROW

PANELS = (("train/return_last100", "train return (last 100 episodes)"),
          ("reward/tracking_lin_vel", "tracking_lin_vel, episode sum"),
          ("reward/tracking_ang_vel", "tracking_ang_vel, episode sum"))
STYLES = ("-", "--", ":", "-.")
WINDOW = 500_000  # frames a plotted value is the mean over: logs thinned to different strides read alike


def smooth(frames, values, window: int = WINDOW):
    """At each logged frame count, the mean of the values logged in the `window` frames up to it (NaN cells left
    out)."""
    import numpy as np

    f, v = np.asarray(frames, float), np.asarray(values, float)
    ok = ~np.isnan(v)
    total = np.concatenate([[0.0], np.cumsum(np.where(ok, v, 0.0))])
    count = np.concatenate([[0], np.cumsum(ok)])
    start = np.searchsorted(f, f - window, side="right")
    n = count[1:] - count[start]
    return np.where(n > 0, (total[1:] - total[start]) / np.maximum(n, 1), np.nan)


def finished(row: Path) -> bool:
    """The row's training is done: its summary.json says so (a crafted row without one counts as done)."""
    from ppo_torchrl.run.lifecycle import unfinished

    return not (row / "summary.json").is_file() or not unfinished(row)


def curves(report: Path, running: bool = False) -> dict:
    """{(robot, seed): metrics columns} of every row dir with metrics; with running=False only finished rows."""
    from ppo_torchrl.records import has_record
    from ppo_torchrl.report import read_metrics

    found = {}
    for row in sorted(p for p in report.iterdir() if p.is_dir() and ROW.match(p.name)):
        if has_record(row / "metrics.csv") and (running or finished(row)):
            m = ROW.match(row.name)
            found[(m["robot"], int(m["seed"]))] = read_metrics(row / "metrics.csv", required=("frames",))
    if not found:
        raise ConfigError(f"{report}: no <robot>_seed<s> dir with metrics")
    return found


def plot(report: Path, out: Path, running: bool = False) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ppo_torchrl.report import write_png

    found = curves(report, running)
    robots = sorted({r for r, _ in found})
    seeds = sorted({s for _, s in found})
    colours = {r: f"C{i}" for i, r in enumerate(robots)}
    fig, axes = plt.subplots(1, len(PANELS), figsize=(15, 4.6), constrained_layout=True)
    for ax, (column, label) in zip(axes, PANELS):
        for (robot, seed), m in sorted(found.items()):
            if column in m:
                style = STYLES[seeds.index(seed) % len(STYLES)]
                ax.plot(m["frames"], smooth(m["frames"], m[column]), color=colours[robot], linestyle=style,
                        linewidth=1.2, label=f"{robot} seed {seed}"
                        + ("" if finished(report / f"{robot}_seed{seed}") else " (running)"))
        ax.set(xlabel="frames", title=label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(f"{report.name}: training curves of {len(found)} rows "
                 f"(each point the mean over the last {WINDOW:,} frames)")
    write_png(fig, out, 80)
    plt.close(fig)
    return out


def main(argv=None) -> int:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path)
    parser.add_argument("--out", type=out_file, default=None)
    parser.add_argument("--running", action="store_true", help="also draw rows still training")
    args = parser.parse_args(argv)
    if not args.report.is_dir():
        raise ConfigError(f"{args.report}: no such directory")
    out = plot(args.report, args.out or args.report / "curves.png", args.running)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
