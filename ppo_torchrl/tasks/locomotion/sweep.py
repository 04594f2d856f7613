"""A legged task's height sweep (evaluate's heights=): the same evaluation at each fixed step height, in metres or,
for env=legged, in leg lengths (0.25l); one row per height (success, the line alone, terminations by reason, the gait
figures per foot) and one per episode, with the success-rate curve.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Optional

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.tasks.locomotion.figures import EPISODE_FOOT_KEYS, GAIT_KEYS, ended_line

SWEEP_FILES = ("height_sweep.csv", "height_sweep.png", "height_sweep_episodes.csv", "height_sweep.json")


MAX_STEP_M, MAX_STEP_LEGS = 2.0, 4.0  # a step no robot here can meet, let alone climb: a typo (heights=1e9)


def parse_heights(text: str) -> list[tuple]:
    """heights=0,0.05,0.1 (m) or, for env=legged, in leg lengths: 0,0.2l,0.25l,0.3l. [(value, in leg lengths)]."""
    example = "e.g. 0,0.05,0.1,0.15,0.2 (m) or, for env=legged, 0,0.2l,0.25l,0.3l (leg lengths)"
    try:
        heights = [(float(h.strip()[:-1]), True) if h.strip().endswith("l") else (float(h), False)
                   for h in text.split(",") if h.strip()]
    except ValueError:
        raise ConfigError(f"heights={text}: expected step heights separated by commas, {example}") from None
    if not heights or any(not (h >= 0 and math.isfinite(h)) for h, _ in heights):
        raise ConfigError(f"heights={text}: expected step heights >= 0 separated by commas, {example}")
    tall = next((h for h, legs in heights if h > (MAX_STEP_LEGS if legs else MAX_STEP_M)), None)
    if tall is not None:
        raise ConfigError(f"heights={text}: a step of {tall:g} is taller than any robot here can meet (at most "
                          f"{MAX_STEP_M:g} m, or {MAX_STEP_LEGS:g}l in leg lengths); {example}")
    return heights


def heights_in_metres(heights: list[tuple], env_cfg, text: str = "") -> list[float]:
    """parse_heights' values in m: a height in leg lengths times the robot's (read from its model). A robot's
    heights all in m and below 1 m (0.25 meant 0.25l?) get a note on stderr that says how to write leg lengths."""
    if not any(legs for _, legs in heights):
        if env_cfg.get("legged") is not None and any(h > 0 for h, _ in heights) and not any(h >= 1 for h, _ in heights):
            top = max(h for h, _ in heights)
            print(f"note: heights={text} are in m (the highest a {top * 100:g} cm step); in this robot's leg lengths "
                  f"write an l: heights={','.join(f'{h:g}l' if h else '0' for h, _ in heights)}",
                  file=sys.stderr, flush=True)
        return [h for h, _ in heights]
    if env_cfg.get("legged") is None:
        raise ConfigError("heights in leg lengths (0.25l) need a run of env=legged, whose robot has one; give m here")
    from ppo_torchrl.envs.make import resolve_model_file
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.robots.recipe import in_metres

    leg = read_robot(resolve_model_file(env_cfg.xml_file), env_cfg.legged.keyframe).leg_length
    return [in_metres(h, leg) if legs else h for h, legs in heights]


def sweep_row(height: float, episodes: int, result: dict) -> dict:
    """One height's row of height_sweep.csv: success (beyond the line and not terminated), the line alone,
    the share of episodes terminated and by each reason, the gait figures (each foot's a column per foot)."""
    row = {"step_height_m": height, "episodes": episodes, "success_rate": result["success_rate"],
           "forward_velocity_mean": result["forward_velocity_mean"], "return_mean": result["return_mean"],
           "crossed_at_end_rate": result["crossed_at_end_rate"], "terminated_share": result["terminated_share"],
           **{f"terminated: {why}": share for why, share in result["termination_shares"].items()}}
    for key in GAIT_KEYS:
        value = result.get(key)
        if key == "feet":
            continue
        if isinstance(value, list):
            row.update({f"{key} {foot}": v for foot, v in zip(result["feet"], value)})
        else:
            row[key] = value
    return row


def height_sweep(cfg, ac, obs_stats, heights: list[float], episodes: int, seed: int, out_dir: Path, title: str,
                 owner: Optional[Path] = None, evaluate=None) -> list:
    """Evaluate at each fixed step height; write height_sweep.csv (a row per height), the success-rate curve
    height_sweep.png, height_sweep_episodes.csv (a row per episode: crossed, terminated and why, length and
    EPISODE_FOOT_KEYS per foot) and height_sweep.json (each height's eval result, eval.json's figures).
    owner: the run dir whose manifest lists them (rundir.atomic_write_bytes); evaluate: evaluate.evaluate_policy."""
    import csv
    import io

    from ppo_torchrl.run.rundir import atomic_write_bytes, atomic_write_json

    rows, results, per_episode = [], [], []
    for height in heights:
        cfg.env.terrain.step_height = height
        result = evaluate(cfg, ac, obs_stats, episodes, seed=seed, progress=True)
        if "success_margin" not in result:
            raise ConfigError("heights= needs a step env (a model with a body named 'step'); to put a flat-ground run "
                              "on the step add env.xml_file=quadruped_step.xml")
        rows.append(sweep_row(height, episodes, result))
        results.append({"step_height_m": height, **result})
        for outcome in result["outcomes"]:
            per_episode.append({"step_height_m": height,
                                **{k: v for k, v in outcome.items() if k not in EPISODE_FOOT_KEYS},
                                **{f"{key} {foot}": v for key in EPISODE_FOOT_KEYS
                                   for foot, v in zip(result["feet"], outcome.get(key, []))}})
        feet = ", ".join(f"{foot} {share:.2f}" for foot, share in zip(result["feet"], result["foot_contact_share"]))
        print(f"step {height * 100:g} cm: {result['success_rate']:.0%} of {episodes} episodes cross and are not "
              f"terminated ({result['crossed_at_end_rate']:.0%} beyond the line at the end; {ended_line(result)}); "
              f"forward velocity {result['forward_velocity_mean']:.2f} m/s; share of time on the ground: {feet}",
              flush=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, table in ((SWEEP_FILES[0], rows), (SWEEP_FILES[2], per_episode)):
        columns = list(dict.fromkeys(k for row in table for k in row))  # a reason met at one height only: 0 elsewhere
        text = io.StringIO(newline="")
        writer = csv.DictWriter(text, fieldnames=columns, restval=0.0 if name == SWEEP_FILES[0] else "")
        writer.writeheader()
        writer.writerows(table)
        atomic_write_bytes(out_dir / name, lambda f: f.write(text.getvalue().encode()), owner)
    atomic_write_json(out_dir / SWEEP_FILES[3], {"title": title, "episodes": episodes, "seed": seed,
                                                 "heights": results}, owner)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ppo_torchrl.report import write_png

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    x = [r["step_height_m"] * 100 for r in rows]
    ax.plot(x, [r["success_rate"] * 100 for r in rows], "o-", label="cross and not terminated (success)")
    ax.plot(x, [r["crossed_at_end_rate"] * 100 for r in rows], "s--", color="0.6", label="beyond the line at the end")
    ax.set(xlabel="step height (cm)", ylabel=f"episodes (%, of {episodes})", ylim=(-3, 103))
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(title, fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    write_png(fig, out_dir / SWEEP_FILES[1], 120, owner)
    plt.close(fig)
    print(f"per episode: {out_dir / SWEEP_FILES[2]}; every figure: {out_dir / SWEEP_FILES[3]}")
    return rows
