"""Parity of the two collector backends: copy a `collector.backend=fast,torchrl` sweep's runs into
results/ and write a side-by-side table (per seed, and mean +- sample std per backend), with
Welch's t-test per metric where scipy is installed.

    python -m ppo_torchrl -m env=InvertedPendulum-v4 collector.backend=fast,torchrl seed=1,2,3 \\
        collector.total_frames=61440 logger=none hydra/launcher=joblib hydra.launcher.n_jobs=2 \\
        hydra.sweep.dir=outputs/multirun/parity_ip
    python benchmarks/parity.py outputs/multirun/parity_ip results/parity/InvertedPendulum-v4
"""

import sys
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from collect_results import copy_finished_runs  # noqa: E402

METRICS = [("train_return_last100", "train return (last 100)"), ("eval_return_mean", "eval return (final, 10 ep.)"),
           ("sps", "frames/s")]


def main(sweep: Path, dest: Path) -> None:
    runs = copy_finished_runs(sweep, dest, lambda summary, config: config["collector"]["backend"])
    env = next(iter(runs.values()))[0]["env"]
    frames = next(iter(runs.values()))[0]["frames"]
    hydra = yaml.safe_load((sweep / "multirun.yaml").read_text())["hydra"]
    command = " ".join(["python -m ppo_torchrl -m", *hydra["overrides"]["task"],
                        *(o for o in hydra["overrides"]["hydra"] if not o.startswith("hydra.mode"))])
    lines = [f"# Backend parity: {env}, {frames:,} frames", "", f"Runs: `{command}`", "",
             f"Table: `python benchmarks/parity.py {sweep} {dest}`", "",
             "| backend | seeds | " + " | ".join(f"{title} per seed | mean +- sample std" for _, title in METRICS) + " |",
             "|---|---|" + "---|---|" * len(METRICS)]
    for backend, rows in sorted(runs.items()):
        rows.sort(key=lambda r: r["seed"])
        cells = []
        for key, _ in METRICS:
            values = np.array([r[key] for r in rows], float)
            std = values.std(ddof=1) if len(values) > 1 else float("nan")
            cells += [", ".join(f"{v:.0f}" for v in values), f"{values.mean():.0f} +- {std:.0f}"]
        lines.append(f"| {backend} | {' '.join(str(r['seed']) for r in rows)} | " + " | ".join(cells) + " |")
    if len(runs) == 2:
        try:
            from scipy.stats import ttest_ind
        except ImportError:
            ttest_ind = None
        if ttest_ind is not None:
            a, b = (runs[k] for k in sorted(runs))
            lines.append("")
            for key, title in METRICS[:2]:
                x, y = [r[key] for r in a], [r[key] for r in b]
                p = ttest_ind(x, y, equal_var=False).pvalue if np.std(x) + np.std(y) > 0 else 1.0
                lines.append(f"- {title}: Welch's t-test p = {p:.2f}")
    (dest / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
