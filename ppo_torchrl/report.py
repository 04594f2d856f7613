"""Plot a run or a sweep: `python -m ppo_torchrl.report <run dir | sweep dir>`.

A run dir gets <run dir>/report.png.

Panels: raw training return (mean of the episodes finished in each iteration, and mean of the last
100 finished episodes, which lags while episodes grow longer) and deterministic eval return (a marker
and its std per eval) against frames, then the PPO debugging quantities: entropy, approx KL, clip
fraction, value loss, explained variance and policy std.

A sweep (multirun) dir gets sweep_report.png (train return against frames, mean and 95% CI band
over seeds, one curve per group of runs sharing their overrides minus `seed`) and
sweep_report.md / .csv (final return mean +- std, seeds, frames, SPS). Failed or partial runs are
left out with a line saying which.

Every figure is written as a 256-colour PNG (`write_png`): a plot's anti-aliased lines and fills need no more, and the
file is ~40% of matplotlib's RGBA one (results/ keeps its plots within a 40 MiB tree).
"""

from __future__ import annotations

import csv
import io
import lzma
from pathlib import Path
from typing import Dict, List

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.locks import read, releasing
from ppo_torchrl.records import has_record, open_record
from ppo_torchrl.run.rundir import atomic_write_bytes, check_replaceable, is_run, record, unwritable

PANELS = [
    ("train/entropy", "policy entropy"),
    ("train/approx_kl", "approx KL"),
    ("train/clipfrac", "clip fraction"),
    ("loss/critic", "value loss"),
    ("train/explained_variance", "explained variance"),
    ("policy/scale_mean", "policy std (mean)"),
]


RUN_COLUMNS = ("frames", "train/episode_return", "train/return_last100", "eval/return_mean", "eval/return_std")


def read_metrics(path: Path, required=("frames",)) -> Dict[str, List[float]]:
    """Columns of metrics.csv as float lists; empty cells become NaN; a column of text alone (a logger's tag, a path)
    is left out, not called damage. A file that is not the app's table (not text, no header, a `required` column
    missing, a column of numbers with text in it, a row cut short) is one ConfigError line."""
    damaged = (f"{path} is damaged (a row that is not numbers); restore it, or delete the damaged rows, and run "
               "the report again")
    try:
        with open_record(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except (UnicodeDecodeError, csv.Error, lzma.LZMAError, EOFError):
        raise ConfigError(f"{path} is not a metrics table (not CSV text); restore it from the run, or report another "
                          "run") from None
    if not rows:
        raise ConfigError(f"{path} has no rows yet: the run has not finished an iteration")
    if any(None in r or None in r.values() for r in rows):  # a row longer or shorter than the header: cut or mixed
        raise ConfigError(damaged)
    columns = {}
    for key in rows[0]:
        cells = [r[key] for r in rows]
        numbers = [number(c) for c in cells]
        filled = [n for c, n in zip(cells, numbers) if c != ""]
        if filled and all(n is None for n in filled) and key not in required:  # a text column (a tag): not plotted
            continue
        if any(n is None and c != "" for c, n in zip(cells, numbers)):  # numbers and text in one column: damage
            raise ConfigError(damaged)
        columns[key] = [float("nan") if n is None else n for n in numbers]
    missing = [key for key in required if key not in columns]
    if missing:
        raise ConfigError(f"{path} has no column {missing[0]}: it is not a metrics.csv this app wrote; restore it "
                          "from the run, or report another run")
    return columns


def number(cell: str):
    """A cell as a float, or None when it is empty or not a number."""
    try:
        return float(cell) if cell != "" else None
    except ValueError:
        return None


def last100_label(m: Dict[str, List[float]]) -> str:
    """The last-100 curve's label, with how many frames its 100 episodes span at the end: while
    episodes grow longer (few finish per iteration) the window reaches back far and the curve lags."""
    import numpy as np

    label = "train: mean of the last 100 finished episodes"
    episodes = np.nan_to_num(np.asarray(m.get("train/episodes", [])))
    if not episodes.size:
        return label
    back = np.cumsum(episodes[::-1])  # episodes finished in the last 1, 2, ... iterations
    if back[-1] < 100:
        return f"{label} (all {int(back[-1])} so far)"
    first = len(episodes) - 1 - int(np.searchsorted(back, 100))  # the oldest iteration in the window
    span = m["frames"][-1] - (m["frames"][first - 1] if first > 0 else 0)
    return f"{label} (at the end they span the last {span:,.0f} frames, so it lags)"


def episode_kinds(run_dir: Path) -> tuple:
    """What the train and eval curves' episodes are, where they differ in kind (a step env whose training draws
    the step's height, on a curriculum or from a range, while its eval has one fixed step: their returns are not
    comparable): (train words, eval words) for the legend, ("", "") otherwise or without a readable config.yaml."""
    try:
        from ppo_torchrl.config_data import read_config

        terrain = read_config(Path(run_dir) / "config.yaml").env.get("terrain")
        if terrain is None or terrain.get("step_height") is not None or terrain.get("step_height_range") is None:
            return "", ""
        low, high = (float(h) * 100 for h in terrain.step_height_range)
        fixed = terrain.get("eval_step_height")
    except Exception:  # noqa: BLE001 - no config.yaml, or a damaged one: the plain labels
        return "", ""
    drawn = f"the curriculum's steps, {low:g}-{high:g} cm" if terrain.get("curriculum") else f"steps of {low:g}-{high:g} cm"
    return (f"\n  (on {drawn}; episodes end early at a fall)",
            f" (one fixed step of {float(fixed) * 100:g} cm)" if fixed is not None else " (the model file's step)")


def run_figure(run_dir: Path):
    """The run's figure: returns against frames on top, the PPO diagnostics below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    metrics_path = Path(run_dir) / "metrics.csv"
    if not has_record(metrics_path):
        raise ConfigError(f"{run_dir} is not a ppo_torchrl run dir (no metrics.csv)")
    m = read_metrics(metrics_path, RUN_COLUMNS)
    frames = np.asarray(m["frames"])
    fig = plt.figure(figsize=(14, 9), constrained_layout=True)
    grid = fig.add_gridspec(3, 3)
    ax = fig.add_subplot(grid[0, :])
    train_kind, eval_kind = episode_kinds(run_dir)  # a curriculum's training episodes are not the eval's
    ax.plot(frames, m["train/episode_return"], alpha=0.35,
            label="train: mean of the episodes finished in each iteration" + train_kind)
    ax.plot(frames, m["train/return_last100"], label=last100_label(m) + train_kind)
    evals = ~np.isnan(np.asarray(m["eval/return_mean"]))
    if evals.any():  # markers, not a line: evals are a few points, and one alone must show
        mean, std = np.asarray(m["eval/return_mean"])[evals], np.asarray(m["eval/return_std"])[evals]
        ax.errorbar(frames[evals], mean, yerr=std, fmt="o", markersize=6, capsize=4,
                    label="eval: deterministic, mean +- std over its episodes" + eval_kind)
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

        try:
            s = json.loads(summary.read_text())
            title = f"{s['env']}  seed {s['seed']}  {s.get('loss', '')}/{s.get('policy', '')}  {int(s['frames']):,} frames"
        except (OSError, ValueError, TypeError, KeyError, AttributeError):  # a damaged summary: the dir's name
            pass
    fig.suptitle(title)
    return fig


def write_png(fig, path: Path, dpi: int, owner: Path | None = None) -> None:
    """fig as a 256-colour PNG at path (atomic; listed in owner's manifest when given). Median cut, no dither: a
    plot's colours are a few flat ones and their anti-aliased blends, which 256 keep to the eye."""
    from PIL import Image

    rgba = io.BytesIO()
    fig.savefig(rgba, format="png", dpi=dpi)
    rgba.seek(0)
    image = Image.open(rgba).convert("RGB").quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    atomic_write_bytes(path, lambda f: image.save(f, format="png", optimize=True), owner=owner)


def plot_run(run_dir: Path) -> Path:
    """<run dir>/report.png."""
    import matplotlib.pyplot as plt

    fig = run_figure(run_dir)
    out = Path(run_dir) / "report.png"
    write_png(fig, out, 90, run_dir)
    plt.close(fig)
    return out


# two-sided 95% Student-t quantiles by degrees of freedom (n seeds - 1); 1.96 beyond the table
T95 = {1: 12.71, 2: 4.30, 3: 3.18, 4: 2.78, 5: 2.57, 6: 2.45, 7: 2.36, 8: 2.31, 9: 2.26, 10: 2.23}


def sweep_runs(sweep_dir: Path):
    """(finished runs grouped by their overrides minus seed (a sorted tuple), lines about the runs left out)."""
    import json

    groups: Dict[tuple, list] = {}
    skipped = []
    for job in sorted(p for p in Path(sweep_dir).iterdir() if p.is_dir() and not p.name.startswith(".")):
        summary, overrides = job / "summary.json", job / ".hydra" / "overrides.yaml"
        if not summary.exists():
            skipped.append(f"skipped {job.name}: no summary.json (failed before its first iteration)")
            continue
        try:
            s = json.loads(summary.read_text())
            status = s.get("status")
        except (OSError, ValueError, AttributeError):
            skipped.append(f"skipped {job.name}: its summary.json cannot be read")
            continue
        if status != "finished":
            skipped.append(f"skipped {job.name}: status {s.get('status')} at {s.get('frames')} frames")
            continue
        from ppo_torchrl.config_data import read_yaml

        try:  # the overrides as text, only compared (an interpolation in one stays its text)
            args = read_yaml(overrides, as_text=True) if overrides.exists() else []
        except Exception:  # noqa: BLE001 - a damaged file: not grouped as any other job
            skipped.append(f"skipped {job.name}: its .hydra/overrides.yaml cannot be read")
            continue
        key = tuple(sorted(a for a in args if not a.split("=")[0].lstrip("+~") == "seed"))
        groups.setdefault(key, []).append((job, s))
    return groups, skipped


def plot_sweep(sweep_dir: Path) -> List[Path]:
    """Learning curves (mean and 95% CI over seeds) and a table per group of a multirun dir."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    groups, skipped = sweep_runs(sweep_dir)
    for line in skipped:
        print(line)
    if not groups:
        raise ConfigError(f"{sweep_dir}: no finished runs to report")
    fig, ax = plt.subplots(figsize=(10, 6), constrained_layout=True)
    rows, shown = [], []
    common = set.intersection(*(set(key) for key in groups))  # the legend shows what varies, the title the rest
    for key, runs in sorted(groups.items()):
        varying = " ".join(a for a in key if a not in common) or ("all runs" if len(groups) == 1 else "(defaults)")
        curves = [read_metrics(job / "metrics.csv") for job, _ in runs]
        grid = np.asarray(max((c["frames"] for c in curves), key=len))
        ys = np.stack([np.interp(grid, c["frames"], np.nan_to_num(np.asarray(c["train/return_last100"]), nan=0.0))
                       for c in curves])
        mean = ys.mean(0)
        n = len(runs)
        half = T95.get(n - 1, 1.96) * ys.std(0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros_like(mean)
        ax.plot(grid, mean, label=f"{varying} (n={n})")
        ax.fill_between(grid, mean - half, mean + half, alpha=0.2)
        final = np.asarray([s["train_return_last100"] for _, s in runs], float)
        evals = np.asarray([s["eval_return_mean"] if s["eval_return_mean"] is not None else np.nan for _, s in runs])
        shown.append(varying)  # the table's group: what sets it apart (what every run shares heads the table)
        rows.append({
            "group": " ".join(key) or "(defaults)",
            "seeds": " ".join(str(s["seed"]) for _, s in sorted(runs, key=lambda r: r[1]["seed"])),
            "n": n, "frames": int(np.min([s["frames"] for _, s in runs])),
            # +- is the sample std over seeds (ddof=1), 0 for a single run
            "train_return_mean": final.mean(), "train_return_std": final.std(ddof=1) if n > 1 else 0.0,
            "eval_return_mean": np.nanmean(evals), "eval_return_std": np.nanstd(evals, ddof=1) if n > 1 else 0.0,
            "sps": float(np.mean([s["sps"] for _, s in runs])),
        })
    import textwrap

    envs = sorted({str(s.get("env")) for runs in groups.values() for _, s in runs})
    title = f"{', '.join(envs)}: train return, mean and 95% CI over seeds"
    if common:
        title += "\n" + textwrap.fill("every run: " + " ".join(sorted(common)), 110)
    ax.set(xlabel="frames", ylabel="train return (last 100 episodes, raw)", title=title)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    png = Path(sweep_dir) / "sweep_report.png"
    write_png(fig, png, 90, sweep_dir)
    plt.close(fig)

    csv_path = Path(sweep_dir) / "sweep_report.csv"
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_bytes(csv_path, lambda f: f.write(table.getvalue().encode()), owner=sweep_dir)
    md = ["| group | seeds | frames | train return (last 100), mean +- sample std | eval return | SPS |",
          "|---|---|---|---|---|---|"]
    md += [f"| {group} | {r['seeds']} | {r['frames']:,} | {r['train_return_mean']:.1f} +- {r['train_return_std']:.1f} "
           f"| {r['eval_return_mean']:.1f} +- {r['eval_return_std']:.1f} | {r['sps']:.0f} |"
           for group, r in zip(shown, rows)]
    if common:
        md = [f"Every run: `{' '.join(sorted(common))}`", ""] + md
    md_path = Path(sweep_dir) / "sweep_report.md"
    text = "\n".join(md) + "\n" + "".join(f"\n{line}" for line in skipped) + ("\n" if skipped else "")
    atomic_write_bytes(md_path, lambda f: f.write(text.encode()), owner=sweep_dir)
    print("\n".join(md))
    return [png, md_path, csv_path]


@releasing  # the shared lock it takes (locks.read) goes when it ends
def main(argv: List[str]) -> List[Path]:
    """A run dir gets report.png; a multirun (sweep) dir gets sweep_report.{png,md,csv}."""
    usage = "python -m ppo_torchrl.report <run dir or sweep dir | latest | latest/<env>>"
    if "--help" in argv or "-h" in argv:
        from ppo_torchrl.cli import print_help

        print_help(usage, {"<run dir or sweep dir>": ("a run dir gets report.png, a sweep (multirun) dir "
                                                       "sweep_report.png, .md and .csv; latest (or latest/<env>, "
                                                       "e.g. latest/Hopper-v4) is the newest run under outputs/",
                                                       None)},
                   "Plots a run's returns and PPO diagnostics against frames, or a sweep's return curves (mean and\n"
                   "95% CI over seeds) and final returns per group of runs that differ only in seed.")
    if len(argv) != 1:
        raise ConfigError(f"usage: {usage}")
    from ppo_torchrl.cli import resolve_run

    target = resolve_run(argv[0].removeprefix("run="))  # [run=]latest[/<env>]: the newest run dir under outputs/
    if not target.is_dir():
        raise ConfigError(f"{target} is not a directory")
    read(target)  # a shared lock: no overwrite or run starts there while this reads it (locks.py)
    why = unwritable(target)
    if why:
        raise ConfigError(f"cannot write the report into {target}: {why}; copy the dir somewhere writable and run it there")
    if has_record(target / "metrics.csv"):
        check_replaceable(target, [target / "report.png"])  # a report.png the app did not write is left alone
        outputs = [plot_run(target)]
    elif (target / "multirun.yaml").is_file() or any(target.glob("*/.hydra")) or (target / "trial.json").is_file():
        check_replaceable(target, [target / f"sweep_report.{ext}" for ext in ("png", "csv", "md")])
        outputs = plot_sweep(target)  # a trial_seeds run is a sweep of its seed<k>/ runs
    else:
        raise ConfigError(f"{target} is neither a run dir (metrics.csv) nor a sweep dir (multirun.yaml) nor a "
                          "trial_seeds run (trial.json)")
    for out in outputs:
        print(f"wrote {out}")
    if is_run(target):
        record(target, outputs)
    return outputs


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
