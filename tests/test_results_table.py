"""benchmarks/collect_results.py's table over a dir of recorded rows: mean +- sample std, every seed, a peer's row."""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import collect_results  # noqa: E402


def _row(dest: Path, name: str, seed: int, train: float, evaluated: float, best=None) -> None:
    d = dest / f"{name}_seed{seed}"
    d.mkdir(parents=True)
    (d / "summary.json").write_text(json.dumps({
        "seed": seed, "frames": 1_001_472, "train_return_last100": train, "eval_return_mean": evaluated,
        "best_eval_return": best, "sps": 1000.0, "wall_s": 300.0}))


def test_the_table_gives_the_sample_std_over_seeds_and_no_spread_for_a_single_seed(tmp_path):
    for seed, train in ((26, 3000.0), (27, 3200.0), (28, 3400.0)):
        _row(tmp_path, "Hopper-v4", seed, train, train + 100, best=train + 200)
    _row(tmp_path, "sb3-ppo", 26, 2900.0, 3100.0)
    lines = collect_results.table(collect_results.recorded_runs(tmp_path)).splitlines()
    app = next(line for line in lines if line.startswith("| Hopper-v4 "))
    peer = next(line for line in lines if line.startswith("| sb3-ppo "))
    assert "| 3200 +- 200 | 3000, 3200, 3400 | 3300 +- 200 | 3400 +- 200 |" in app  # ddof=1: std of 3000/3200/3400
    assert "| 2900 (one seed) | 2900 | 3100 (one seed) | - |" in peer  # not "+- 0", and no periodic evals
