"""What an evaluation of a MuJoCo Playground task (env=playground, envs_playground.py) reports beyond returns and
lengths: each reward term's episode sum and the mean command (the env's `episode_metrics()` per episode), their means
over the eval (result["episode_metrics"]), the line evaluate prints, and what a training run logs of them (no eval
columns of metrics.csv: the training batches log the same terms as reward/<term>; summary.json keeps the means)."""

from __future__ import annotations

import numpy as np


def figures(cfg, episodes: dict, result: dict) -> None:
    rows = episodes.get("metrics") or []
    keys = dict.fromkeys(k for m in rows for k in m)
    result["episode_metrics"] = {k: float(np.mean([m[k] for m in rows if k in m])) for k in keys}
    for outcome, m in zip(result["outcomes"], rows):
        outcome.update(m)
    result["task_keys"] = ["episode_metrics"]
    result["columns"] = {}


def motion_line(result: dict) -> str:
    lines = [f"{result['terminated_share']:.0%} end terminated"] if result.get("terminated_share") else []
    figures = result.get("episode_metrics") or {}
    if figures:
        lines.append("per episode (mean): " + ", ".join(f"{k} {v:.3g}" for k, v in figures.items()))
    return "".join(f"\n  {line}" for line in lines)
