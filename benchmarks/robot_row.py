"""A robot row over training seeds: every seed's figures side by side and their mean +- sample std, from each
seed's height sweep (`python -m ppo_torchrl.evaluate run=<seed dir> ... heights=... out=<seed dir>/<sweep>`).

    python benchmarks/robot_row.py <seed dir> [<seed dir> ...] --sweep sweep_seed7777 [--goal-height 0.15] [--out table.md]
        [--curves curves.png]

Tables: success (crossed and not terminated) per height; per height and seed, each foot's share on the ground,
touchdowns per second, the episodes with a foot up over 0.5 s while the robot moves (and the median episode's
longest such swing), the diagonal pairs' figure, the stride and the joint-speed line; then the trot's goals
(issue 31 item 3) and the climb's (item 4), each seed passed or missed. --curves: each seed's training curves
through both stages (`<seed dir>/stage1/metrics.csv`, then `<seed dir>/metrics.csv` from where stage 1 ended).
"""

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from ppo_torchrl.records import has_record, open_record, read_record_text
from ppo_torchrl.report import read_metrics, write_png

SWING_S = 0.5  # the trot's longest swing while moving
SHARE = (0.35, 0.65)  # each foot's share on the ground
STRIDE_HZ = 3.0  # touchdowns per second per foot, under


def mean_std(values) -> str:
    """mean +- sample std (ddof=1), the house's +- over seeds."""
    x = np.asarray(values, float)
    return f"{x.mean():.3g} +- {x.std(ddof=1):.2g}" if len(x) > 1 else f"{x.mean():.3g}"


def load(seed_dir: Path, sweep: str) -> dict:
    """{height: that height's eval result with 'episodes_rows' (the per-episode CSV rows) added}."""
    result = json.loads(read_record_text(seed_dir / sweep / "height_sweep.json"))
    with open_record(seed_dir / sweep / "height_sweep_episodes.csv", newline="") as f:
        episodes = list(csv.DictReader(f))
    by_height = {}
    for h in result["heights"]:
        height = round(h["step_height_m"], 4)
        h["episodes_rows"] = [r for r in episodes if round(float(r["step_height_m"]), 4) == height]
        by_height[height] = h
    return by_height


def long_swings(h: dict) -> tuple:
    """(the share of episodes with some foot up over SWING_S while moving, the median episode's longest)."""
    feet = h["feet"]
    longest = [max(float(r[f"longest_air_moving_s {f}"]) for f in feet) for r in h["episodes_rows"]]
    return float(np.mean(np.asarray(longest) > SWING_S)), float(np.median(longest))


def table(seeds: dict, goal_height: float) -> str:
    names = list(seeds)
    heights = sorted(set.intersection(*(set(s) for s in seeds.values())))
    n = {len(seeds[name][h]["outcomes"]) for name in names for h in heights}
    out = [f"Episodes per height and seed: {', '.join(map(str, sorted(n)))}.", "",
           "| step | " + " | ".join(names) + " | mean +- sample std |", "|---|" + "---|" * (len(names) + 1)]
    for h in heights:
        rates = [seeds[name][h]["success_rate"] for name in names]
        out.append(f"| {h * 100:g} cm | " + " | ".join(f"{r:.0%}" for r in rates)
                   + f" | {mean_std(np.asarray(rates) * 100)}% |")
    feet = seeds[names[0]][heights[0]]["feet"]
    short = " ".join(f.split("_")[0] for f in feet)
    out += ["", f"| step | seed | each foot's share on the ground {short} | touchdowns/s {short} | episodes with a foot "
            f"up > {SWING_S} s while moving (median episode's longest) | diagonal pairs together | stride (Hz) "
            "| physics steps over the joint-speed line |", "|---|---|---|---|---|---|---|---|"]
    for h in heights:
        for name in names:
            r = seeds[name][h]
            share, median = long_swings(r)
            out.append(f"| {h * 100:g} cm | {name} | " + " ".join(f"{x:.2f}" for x in r["foot_contact_share"])
                       + " | " + " ".join(f"{x:.1f}" for x in r["touchdown_frequency"])
                       + f" | {share:.0%} ({median:.2f} s) | {r['diagonal_pairs_together']:.2f} "
                       f"| {r['stride_frequency']:.2f} | {r['over_speed_limit_share']:.2%} |")
    out += ["", "| goal | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]

    def row(goal: str, passed) -> None:
        out.append(f"| {goal} | " + " | ".join(passed(seeds[name]) for name in names) + " |")

    def verdict(ok: bool, figure: str) -> str:
        return f"{'met' if ok else 'missed'} ({figure})"

    row(f"crosses {goal_height * 100:g} cm in >= 90% (item 4)",
        lambda s: verdict(s[goal_height]["success_rate"] >= 0.9, f"{s[goal_height]['success_rate']:.0%}"))
    row(f"each foot on the ground {SHARE[0]:.0%}-{SHARE[1]:.0%}, every height",
        lambda s: verdict(all(SHARE[0] <= x <= SHARE[1] for h in heights for x in s[h]["foot_contact_share"]),
                          f"{min(min(s[h]['foot_contact_share']) for h in heights):.2f}-"
                          f"{max(max(s[h]['foot_contact_share']) for h in heights):.2f}"))
    row(f"no foot up > {SWING_S} s while moving, every height",
        lambda s: verdict(all(long_swings(s[h])[0] == 0 for h in heights),
                          f"{min(long_swings(s[h])[0] for h in heights):.0%}-"
                          f"{max(long_swings(s[h])[0] for h in heights):.0%} of episodes have one"))
    row(f"every foot under {STRIDE_HZ:g} touchdowns/s, every height",
        lambda s: verdict(all(x < STRIDE_HZ for h in heights for x in s[h]["touchdown_frequency"]),
                          f"highest {max(max(s[h]['touchdown_frequency']) for h in heights):.1f}"))
    row("joint-speed line held (physics steps over it)",
        lambda s: f"{max(s[h]['over_speed_limit_share'] for h in heights):.2%} at most")
    return "\n".join(out) + "\n"


CURVES = (("train/return_last100", "train return, mean of the last 100 episodes"),
          ("eval/return_mean", "in-training eval return (deterministic, the eval step)"),
          ("eval/success_rate", "in-training eval success (crossed, not terminated)"),
          ("env/terrain_level", "curriculum: the step's top height (m)"))


def curves(seed_dirs, out: Path, panels=CURVES) -> None:
    """One panel per (metrics key, title) of `panels`, one line per seed dir: stage 1, then stage 2 from the frame
    stage 1 ended on."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True)
    stage_ends = set()  # where a seed's second stage starts: a dotted line
    for d in seed_dirs:
        stages = [read_metrics(p) for p in (d / "stage1" / "metrics.csv", d / "metrics.csv") if has_record(p)]
        starts = np.cumsum([0.0] + [m["frames"][-1] for m in stages[:-1]])
        stage_ends.update(starts[1:])
        x = np.concatenate([start + np.asarray(m["frames"]) for start, m in zip(starts, stages)])
        for ax, (key, title) in zip(axes.flat, panels):
            y = np.concatenate([m.get(key, [np.nan] * len(m["frames"])) for m in stages])
            keep = ~np.isnan(y)
            ax.plot(x[keep], y[keep], marker="o" if keep.sum() < 50 else None, markersize=3, label=d.name)
            ax.set(title=title, xlabel="frames (both stages)" if stage_ends else "frames")
    for ax in axes.flat:
        for end in stage_ends:
            ax.axvline(end, color="grey", linestyle=":", linewidth=1)
        ax.grid(alpha=0.3)
        ax.legend(loc="best")
    write_png(fig, out, 80)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seed_dirs", nargs="+", type=Path)
    parser.add_argument("--sweep", default="sweep_seed7777", help="the sweep's folder in each seed dir")
    parser.add_argument("--goal-height", type=float, default=0.15)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--curves", type=Path, help="write the seeds' training curves here (PNG)")
    args = parser.parse_args()
    if args.curves:
        curves(args.seed_dirs, args.curves)
    text = table({d.name: load(d, args.sweep) for d in args.seed_dirs}, args.goal_height)
    if args.out:
        args.out.write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
