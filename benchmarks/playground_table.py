"""Issue 74's report as markdown tables: per row (task x training seed) the task's own episode reward, the tracking
set at the last checkpoint and at the one nearest 20M frames, frames, wall time and frames/s; per task the reward over
seeds (mean +- sample std, every seed's figure) beside what Playground publishes; per task each reward term's episode
sum; then each of issue 74's goals read as results/playground/tuning_2026-12-03/PLAN.md ("The report") registers them.

    python benchmarks/playground_table.py <report dir> [--out table.md]

The report dir holds one row dir per task and seed, `<task>_seed<s>`, each with `summary.json`, `eval/eval.json`
(`evaluate checkpoint=last episodes=10 seed=2000`), `eval/tracking.json[.xz]` (`tracking=true episodes=5`) and, for a
40M row, `eval_20M/tracking.json[.xz]` or `eval_20M/tracking.md`. A row without its episode reward is listed as
waiting and counts in no mean.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from cli_args import ConfigError, Parser, out_file
from cli_args import run as run_main
from joystick_table import clock, read_json
from levers_table import mean_std

ROW = re.compile(r"^(?P<task>.+)_seed(?P<seed>\d+)$")
# What Playground states for each task (docs/playground.md, "Playground's own training settings"): its training
# steps and hardware; no final episode reward is published in numbers for any of them.
PUBLISHED = {"Go1JoystickFlatTerrain-v1": "200M steps, 8,192 envs, one A100",
             "Go1JoystickRoughTerrain-v1": "200M steps, 8,192 envs, one A100",
             "SpotFlatTerrainJoystick-v1": "100M steps, 8,192 envs, one A100",
             "BarkourJoystick-v1": "100M steps, 8,192 envs, one A100"}
TRACKING_GOAL, FALLS_GOAL = 0.05, 0.01  # issue 73's tracking goals (its units), its falls goal
FRAMES_GOAL = 20_000_000 * 1.001  # issue 74's budget; a run of total_frames=20000000 ends on its batch, 20,000,768


def nominal(tracking) -> dict:
    return None if tracking is None else tracking["worlds"]["nominal"]


def rows(report: Path) -> tuple:
    """({(task, seed): row figures} of rows with an episode reward, [names of rows still waiting])."""
    done, waiting = {}, []
    for row in sorted(p for p in report.iterdir() if p.is_dir() and ROW.match(p.name)):
        m = ROW.match(row.name)
        ev = read_json(row / "eval" / "eval.json")
        summary = read_json(row / "summary.json") or {}
        if ev is None:
            waiting.append((summary.get("env", m["task"]), int(m["seed"]), summary.get("frames")))
            continue
        done[(m["task"], int(m["seed"]))] = {
            "env": ev.get("env") or summary.get("env"), "reward": ev["return_mean"], "reward_std": ev["return_std"],
            "terms": ev.get("episode_metrics", {}), "last": nominal(read_json(row / "eval" / "tracking.json")),
            "at20": nominal(read_json(row / "eval_20M" / "tracking.json")), "frames": summary.get("frames"),
            "wall_s": summary.get("wall_s"), "sps": summary.get("sps")}
    return done, waiting


def best_stride(track) -> str:
    """The translating command (forward, backward, sideways) tracked best: its v_xy error of its commanded speed."""
    if track is None:
        return "-"
    moving = [c for c in track["commands"] if abs(c["yaw"]) < 1e-9 and (abs(c["vx"]) + abs(c["vy"])) > 0]
    if not moving:
        return "-"
    best = min(moving, key=lambda c: c["v_xy_error"] / (c["vx"] ** 2 + c["vy"] ** 2) ** 0.5)
    return f"{best['command']} {best['v_xy_error']:.3f} of {(best['vx'] ** 2 + best['vy'] ** 2) ** 0.5:.2f}"


def track_cell(track) -> str:
    if track is None:
        return "-"
    o = track["overall"]
    return f"{o['v_xy_error']:.3f} / {o['yaw_rate_error']:.3f} / {o['falls']:.0%}"


def table(report: Path) -> str:
    done, waiting = rows(report)
    if not done and not waiting:
        raise ConfigError(f"{report}: no <task>_seed<s> dir")
    out = ["| task | seed | frames | episode reward (10 episodes) | last: v_xy / yaw / falls | last: best stride | "
           "20M: v_xy / yaw / falls | 20M: best stride | wall (h:mm) | frames/s |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for (task, seed), r in sorted(done.items()):
        frames = f"{r['frames']:,}" if isinstance(r["frames"], int) else "-"
        sps = f"{r['sps']:,.0f}" if isinstance(r["sps"], (int, float)) else "-"
        out.append(f"| {r['env']} | {seed} | {frames} | {r['reward']:.1f} +- {r['reward_std']:.1f} | "
                   f"{track_cell(r['last'])} | {best_stride(r['last'])} | {track_cell(r['at20'])} | "
                   f"{best_stride(r['at20'])} | {clock(r['wall_s'])} | {sps} |")
    for task, seed, frames in waiting:
        at = f"training, {frames:,} frames" if isinstance(frames, int) else "waiting"
        out.append(f"| {task} | {seed} | {at} (no episode reward yet) | | | | | | | |")
    tasks = sorted({r["env"] for r in done.values()})
    out += ["", "| task | seeds | episode reward, mean +- sample std | per seed | Playground's published final reward "
            "| Playground's budget |", "|---|---|---|---|---|---|"]
    for env in tasks:
        mine = sorted((s, r["reward"]) for (t, s), r in done.items() if r["env"] == env)
        m, sd = mean_std([v for _, v in mine])
        spread = f"{m:.1f} +- {sd:.1f}" if len(mine) > 1 else f"{m:.1f} (one seed)"
        per = ", ".join(f"{s}: {v:.1f}" for s, v in mine)
        out.append(f"| {env} | {len(mine)} | {spread} | {per} | none in numbers (docs/playground.md) | "
                   f"{PUBLISHED.get(env, '-')} |")
    if tasks:
        names = sorted({k for r in done.values() for k in r["terms"] if k.startswith("reward/")})
        out += ["", "Each reward term's episode sum (mean over a task's seeds of its 10 episodes' mean):", "",
                "| term | " + " | ".join(tasks) + " |", "|---|" + "---|" * len(tasks)]
        for name in names:
            cells = []
            for env in tasks:
                values = [r["terms"][name] for r in done.values() if r["env"] == env and name in r["terms"]]
                cells.append(f"{mean_std(values)[0]:.1f}" if values else "-")
            out.append(f"| {name.removeprefix('reward/')} | " + " | ".join(cells) + " |")
    out += ["", goals(done)]
    return "\n".join(out) + "\n"


def goals(done: dict) -> str:
    """Issue 74's goals as the report registers them."""
    if not done:
        return "goals: no row yet"
    over = sorted(f"{r['env']} seed {s}" for (t, s), r in done.items()
                  if isinstance(r["frames"], int) and r["frames"] > FRAMES_GOAL)
    go1 = [(s, r["last"]) for (t, s), r in sorted(done.items())
           if r["env"] == "Go1JoystickFlatTerrain-v1" and r["last"] is not None]
    met = [s for s, t in go1 if t["overall"]["v_xy_error"] <= TRACKING_GOAL and
           t["overall"]["yaw_rate_error"] <= TRACKING_GOAL and t["overall"]["falls"] <= FALLS_GOAL]
    parts = ["reward >= Playground's published final reward: cannot be read (none is published in numbers)",
             f"<= 20M frames: missed by {len(over)} of {len(done)} rows" if over else
             f"<= 20M frames: met by all {len(done)} rows",
             f"Go1 flat within issue 73's tracking goals (v_xy and yaw <= {TRACKING_GOAL}, falls <= "
             f"{FALLS_GOAL:.0%}) at the last checkpoint: {len(met)} of {len(go1)} rows"]
    return "goals: " + "; ".join(parts)


def main(argv=None) -> int:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path)
    parser.add_argument("--out", type=out_file, default=None)
    args = parser.parse_args(argv)
    if not args.report.is_dir():
        raise ConfigError(f"{args.report}: no such directory")
    text = table(args.report)
    print(text, end="")
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
