"""Parity of the collectors: copy the runs of one or more sweeps (`collector.backend=fast,torchrl`, and
`collector.workers=2`) into results/ and write a side-by-side table (per seed, and mean +- sample std per
collector), with Welch's t-test of each collector against the first (fast, one process) where scipy is
installed.

    python -m ppo_torchrl -m env=InvertedPendulum-v4 collector.backend=fast,torchrl seed=1,2,3 \\
        collector.total_frames=61440 logger=none hydra/launcher=joblib hydra.launcher.n_jobs=2 \\
        hydra.sweep.dir=outputs/multirun/parity_ip
    python benchmarks/parity.py outputs/multirun/parity_ip [more sweep dirs] results/parity/InvertedPendulum-v4
"""

import sys
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from collect_results import copy_finished_runs  # noqa: E402

METRICS = [("train_return_last100", "train return (last 100)"), ("eval_return_mean", "eval return (final, 10 ep.)"),
           ("sps", "frames/s")]


def collector_name(summary: dict, config: dict) -> str:
    c = config["collector"]
    backend = c["backend"] if c["backend"] != "auto" else ("torchrl" if config["env"]["transforms"].get("extra") else "fast")
    return backend + (f"_workers{c['workers']}" if c.get("workers", 1) > 1 else "")


def command_of(sweep: Path) -> str:
    hydra = yaml.safe_load((sweep / "multirun.yaml").read_text())["hydra"]
    return " ".join(["python -m ppo_torchrl -m", *hydra["overrides"]["task"],
                     *(o for o in hydra["overrides"]["hydra"] if not o.startswith("hydra.mode"))])


def main(sweeps: list, dest: Path) -> None:
    runs = {}
    for sweep in sweeps:
        for name, rows in copy_finished_runs(sweep, dest, collector_name).items():
            runs.setdefault(name, []).extend(rows)
    env = next(iter(runs.values()))[0]["env"]
    frames = next(iter(runs.values()))[0]["frames"]
    lines = [f"# Collector parity: {env}, {frames:,} frames", "", "Runs:", "",
             *(f"- `{command_of(sweep)}`" for sweep in sweeps), "",
             f"Table: `python benchmarks/parity.py {' '.join(map(str, sweeps))} {dest}`", "",
             "| backend | seeds | " + " | ".join(f"{title} per seed | mean +- sample std" for _, title in METRICS) + " |",
             "|---|---|" + "---|---|" * len(METRICS)]
    order = sorted(runs, key=lambda k: (k != "fast", k))
    for backend in order:
        rows = runs[backend]
        rows.sort(key=lambda r: r["seed"])
        cells = []
        for key, _ in METRICS:
            values = np.array([r[key] for r in rows], float)
            std = values.std(ddof=1) if len(values) > 1 else float("nan")
            cells += [", ".join(f"{v:.0f}" for v in values), f"{values.mean():.0f} +- {std:.0f}"]
        lines.append(f"| {backend} | {' '.join(str(r['seed']) for r in rows)} | " + " | ".join(cells) + " |")
    try:
        from scipy.stats import ttest_ind
    except ImportError:
        ttest_ind = None
    if ttest_ind is not None and len(order) > 1:
        lines.append("")
        for other in order[1:]:
            for key, title in METRICS[:2]:
                x, y = [r[key] for r in runs[order[0]]], [r[key] for r in runs[other]]
                p = ttest_ind(x, y, equal_var=False).pvalue if np.std(x) + np.std(y) > 0 else 1.0
                lines.append(f"- {title}, {order[0]} against {other}: Welch's t-test p = {p:.2f}")
    (dest / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main([Path(a) for a in sys.argv[1:-1]], Path(sys.argv[-1]))
